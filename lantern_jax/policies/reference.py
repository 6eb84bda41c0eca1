"""The camera-based reference policies of the result tables, ``ego`` and ``coop`` (the
privileged ``expert`` is :mod:`lantern_jax.policies.expert`), and ``expert-v1``.

* ``ego`` — the planner restricted to what the front camera sees now; ignores warnings.
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
* ``expert-v1`` — the same planner over every present actor, hidden ones included, with
  constant-velocity forecasts: the first privileged reference, which validated (filtered) the
  ``lantern-v2`` suite and, so that its pairs of the five families whose scenes did not change
  stay exactly those of ``lantern-v2``, ``lantern-v3``.  It is kept so that the suite
  regenerates exactly from its seed; it reacts to a waiting hazard only once it moves (see
  :mod:`lantern_jax.policies.expert`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.constants import BIG
from lantern_jax.observation import Observation
from lantern_jax.policies.base import Policy
from lantern_jax.policies.planner import (
    Constraints,
    PlannerConfig,
    default_planner_config,
    merge,
    plan,
    project_on_route,
    stop_constraint,
    turn_entry_arc,
)
from lantern_jax.scenarios.families import (
    RESPONSE_CUT_IN,
    RESPONSE_LANE_OBSTACLE,
    RESPONSE_YIELD_TURN,
    family,
)
from lantern_jax.scenarios.warnings import TEXT_BANK

# Response semantics of a warning text, as integer codes for the jitted policy.
SEM_NONE = -1  # not understood / not actionable
SEM_LANE_OBSTACLE = 0  # a stopped obstacle in the ego lane at the grounded position
SEM_CUT_IN = 1  # a vehicle entering the ego lane at the grounded position
SEM_YIELD_TURN = 2  # yield before the turn

_RESPONSE_CODES = {
    RESPONSE_LANE_OBSTACLE: SEM_LANE_OBSTACLE,
    RESPONSE_CUT_IN: SEM_CUT_IN,
    RESPONSE_YIELD_TURN: SEM_YIELD_TURN,
}


def text_semantics(understood_kinds: tuple[str, ...] = ("canonical",)) -> np.ndarray:
    """(num_texts,) int32 response semantics per text-bank id for the ``coop`` policy.

    Args:
        understood_kinds: text kinds whose wording the policy was built for; other texts (e.g.
            held-out paraphrases, non-actionable messages) and texts of no family map to
            ``SEM_NONE``.
    """
    out = np.full((len(TEXT_BANK),), SEM_NONE, np.int32)
    for entry in TEXT_BANK:
        if entry.kind in understood_kinds and entry.family >= 0:
            out[entry.text_id] = _RESPONSE_CODES[family(entry.family).response]
    return out


def warning_constraints(
    p: PlannerConfig, obs: Observation, semantics: jax.Array, seen: jax.Array
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
    rel = obs.actor_xy - obs.warning_pos[None, :]
    d = jnp.where(seen, jnp.sum(rel * rel, axis=-1), BIG)  # squared distance (no sqrt)
    j = jnp.argmin(d)
    matched = d[j] < 9.0  # within 3 m
    v_match = jnp.where(matched, jnp.maximum(obs.actor_vel[j, 0], 0.0), 0.0)
    cut_gap = jnp.where((sem == SEM_CUT_IN) & ahead, jnp.maximum(arc - 2.0 * 2.45, 0.0), BIG)
    cut = Constraints(gap=cut_gap[None], speed=v_match[None], s0=jnp.full((1,), 2.0))

    entry = turn_entry_arc(obs.route)
    yield_arc = jnp.where(entry < BIG * 0.5, jnp.maximum(entry - p.yield_setback, 0.0), BIG)
    yld = stop_constraint(p, yield_arc, (sem == SEM_YIELD_TURN) & (yield_arc < BIG * 0.5))
    return merge(obstacle, cut, yld)


@struct.dataclass
class ReferenceParams:
    """Parameters of the reference policies: one act function, behaviour chosen by data.

    Because ``ego``, ``coop`` and ``expert-v1`` share :func:`reference_act` and differ only in
    these (traced) flags, evaluating them reuses one compiled rollout.
    """

    planner: PlannerConfig
    privileged: jax.Array  # () bool, plan over every present actor (else: camera-visible only)
    use_warning: jax.Array  # () bool, turn active warnings into virtual constraints


_CANONICAL_SEMANTICS = None


def _semantics_table() -> jax.Array:
    global _CANONICAL_SEMANTICS
    if _CANONICAL_SEMANTICS is None:
        _CANONICAL_SEMANTICS = np.asarray(text_semantics(("canonical",)))
    return jnp.asarray(_CANONICAL_SEMANTICS)


def reference_act(params: ReferenceParams, obs: Observation) -> jax.Array:
    """The shared act function of the reference policies.

    Args:
        params: :class:`ReferenceParams`.
        obs: one scenario's observation.

    Returns:
        (10, 2) float32 waypoints, ego frame (x forward, y right), 0.25 s apart.
    """
    seen = jnp.where(params.privileged, obs.present, obs.visible)
    extra = warning_constraints(params.planner, obs, _semantics_table(), seen)
    extra = extra.replace(gap=jnp.where(params.use_warning, extra.gap, BIG))
    return plan(params.planner, obs, seen, extra)[0]


def _make_init(privileged: bool, use_warning: bool):
    def init(key: jax.Array) -> ReferenceParams:
        del key
        return ReferenceParams(
            planner=default_planner_config(),
            privileged=jnp.asarray(privileged),
            use_warning=jnp.asarray(use_warning),
        )

    return init


def legacy_expert_policy() -> Policy:
    """``expert-v1``: the planner over all present actors (the ``lantern-v3`` suite validator).

    It reads ``obs.present`` (in every observation), not the privileged forecast, so it runs in
    an ordinary rollout.
    """
    return Policy(
        "expert-v1",
        _make_init(True, False),
        reference_act,
        "the lantern-v3 suite validator: the ego planner over every present actor with "
        "constant-velocity forecasts (kept so lantern-v3 regenerates exactly)",
    )


def ego_policy() -> Policy:
    """The planner restricted to the front camera; ignores warnings."""
    return Policy(
        "ego",
        _make_init(False, False),
        reference_act,
        "the same planner restricted to the front camera; ignores warnings",
    )


def coop_policy() -> Policy:
    """``ego`` plus cooperative-warning handling."""
    return Policy(
        "coop",
        _make_init(False, True),
        reference_act,
        "front-camera planner + cooperative warnings as virtual constraints",
        uses_warning=True,
    )
