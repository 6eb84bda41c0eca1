"""The three reference policies of the result tables: ``expert``, ``ego`` and ``coop``.

* ``expert`` — the planner over every present actor, hidden ones included (privileged upper
  reference, in the spirit of PDM-Lite).
* ``ego`` — the same planner restricted to what the front camera sees now; ignores warnings.
* ``coop`` — ``ego`` plus warning handling: while a warning is active, the warned hazard becomes
  a virtual constraint at its grounded position, chosen by what the warning text says:

  - "... is about to enter the ego lane" / "... is blocking the ego lane" (pedestrian, static
    object): a stopped obstacle in the lane at the grounded distance ahead;
  - "... will cut into the ego lane soon" (vehicle): a leader in the lane at the grounded
    distance, moving with the nearest seen actor's velocity when one matches the position;
  - "... will cross the ego ... path. Yield before turning ...": a yield stop before the turn
    entry of the route (or right away when the ego is already turning).

  The semantics come from the text bank (:mod:`lantern_jax.scenarios.warnings`), so a text the
  policy does not understand (an unseen paraphrase or a non-actionable message) has no effect.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import BIG, LWW, OR, PE, RTY, RWW, VC
from lantern_jax.policies.base import Policy, register_policy
from lantern_jax.policies.observation import Observation
from lantern_jax.policies.planner import (
    Constraints,
    PlannerParams,
    default_planner_params,
    merge,
    plan,
    project_on_route,
    stop_constraint,
    turn_entry_arc,
)

# Response semantics of a warning text.
SEM_NONE = -1  # not understood / not actionable
SEM_LANE_OBSTACLE = 0  # a stopped obstacle in the ego lane at the grounded position
SEM_CUT_IN = 1  # a vehicle entering the ego lane at the grounded position
SEM_YIELD_TURN = 2  # yield before the turn

_FAMILY_SEMANTICS = {
    PE: SEM_LANE_OBSTACLE,
    OR: SEM_LANE_OBSTACLE,
    VC: SEM_CUT_IN,
    LWW: SEM_YIELD_TURN,
    RWW: SEM_YIELD_TURN,
    RTY: SEM_YIELD_TURN,
}


def text_semantics(understood_kinds: tuple[str, ...] = ("canonical",)) -> np.ndarray:
    """(num_texts,) int32 response semantics per text-bank id for the ``coop`` policy.

    Args:
        understood_kinds: text kinds whose wording the policy was built for; other texts (e.g.
            held-out paraphrases, non-actionable messages) map to ``SEM_NONE``.
    """
    from lantern_jax.scenarios.warnings import TEXT_BANK

    out = np.full((len(TEXT_BANK),), SEM_NONE, np.int32)
    for entry in TEXT_BANK:
        if entry.kind in understood_kinds:
            out[entry.text_id] = _FAMILY_SEMANTICS[entry.family]
    return out


def warning_constraints(
    p: PlannerParams, obs: Observation, semantics: jax.Array, seen: jax.Array
) -> Constraints:
    """Virtual constraints from the active warning (all inactive when there is none).

    Args:
        p: planner parameters.
        obs: observation.
        semantics: (num_texts,) int32 table from :func:`text_semantics`.
        seen: (A,) bool, actors the policy sees (used to match a cut-in vehicle's velocity).
    """
    tid = jnp.clip(obs.warning_text_id, 0, semantics.shape[0] - 1)
    sem = jnp.where(obs.warning_active & (obs.warning_text_id >= 0), semantics[tid], SEM_NONE)
    arc, _ = project_on_route(obs.route, obs.warning_pos)
    ahead = arc > 0.0

    obstacle = stop_constraint(p, arc - 1.0, (sem == SEM_LANE_OBSTACLE) & ahead)

    # Cut-in: a leader at the grounded position, with a matched seen actor's speed.
    d = jnp.linalg.norm(obs.actor_xy - obs.warning_pos[None, :], axis=-1)
    d = jnp.where(seen, d, BIG)
    j = jnp.argmin(d)
    matched = d[j] < 3.0
    v_match = jnp.where(matched, jnp.maximum(obs.actor_vel[j, 0], 0.0), 0.0)
    cut_gap = jnp.where((sem == SEM_CUT_IN) & ahead, jnp.maximum(arc - 2.0 * 2.45, 0.0), BIG)
    cut = Constraints(gap=cut_gap[None], speed=v_match[None], s0=jnp.full((1,), 2.0))

    entry = turn_entry_arc(obs.route)
    yield_arc = jnp.where(entry < BIG * 0.5, jnp.maximum(entry - p.yield_setback, 0.0), BIG)
    yld = stop_constraint(p, yield_arc, (sem == SEM_YIELD_TURN) & (yield_arc < BIG * 0.5))
    return merge(obstacle, cut, yld)


def _init(key: jax.Array) -> PlannerParams:
    del key
    return default_planner_params()


def _expert_act(params: PlannerParams, obs: Observation) -> jax.Array:
    return plan(params, obs, obs.present)[0]


def _ego_act(params: PlannerParams, obs: Observation) -> jax.Array:
    return plan(params, obs, obs.visible)[0]


def make_coop_act(understood_kinds: tuple[str, ...] = ("canonical",)):
    """Build the ``coop`` act function for the given understood text kinds."""
    table = jnp.asarray(text_semantics(understood_kinds))

    def act(params: PlannerParams, obs: Observation) -> jax.Array:
        extra = warning_constraints(params, obs, table, obs.visible)
        return plan(params, obs, obs.visible, extra)[0]

    return act


def expert_policy() -> Policy:
    """Privileged planner over all present actors (upper reference)."""
    return Policy(
        "expert", _init, _expert_act, "privileged PDM-Lite-style planner", privileged=True
    )


def ego_policy() -> Policy:
    """The planner restricted to the front camera; ignores warnings."""
    return Policy("ego", _init, _ego_act, "front-camera planner, ignores warnings")


def coop_policy() -> Policy:
    """``ego`` plus cooperative-warning handling."""
    return Policy(
        "coop", _init, make_coop_act(), "front-camera planner + warnings", uses_warning=True
    )


register_policy("expert", expert_policy)
register_policy("ego", ego_policy)
register_policy("coop", coop_policy)
