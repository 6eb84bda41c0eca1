"""The camera-based reference policies of the result tables, ``ego`` and ``coop`` (the
privileged ``expert`` is :mod:`lantern_jax.policies.expert`), and ``expert-v1``.

* ``ego`` — the planner over what the front camera sees now; it has no warning sensor.
* ``coop`` — ``ego`` plus the warning sensor: it reads the delivered text with a **keyword rule**
  over its tokens (:func:`text_response`) and turns what the text asks for into a virtual
  constraint:

  ==============================  =====================================================
  the text contains (any case)    response
  ==============================  =====================================================
  "yield"                         a yield stop before the turn entry of the route (or
                                  right away when the ego is already turning); no
                                  position needed
  "cut into"                      a leader in the lane at the stated position, moving
                                  with the nearest seen actor's velocity when one is
                                  within 3 m of it
  "ego lane"                      a stopped obstacle in the lane at the stated position
  ==============================  =====================================================

  The first row that matches decides.  The position is the text's two numbers (its value
  channel); a text that writes none gets no position response, and a position behind the ego
  is ignored.  The keywords are the canonical templates' own words (their six sentences each
  match the row their family's scenario calls for); any other wording reaches the same rule,
  so a paraphrase or a non-actionable message is answered by what its words match — for
  better or worse (``lantern-jax wording`` and the language diagnostic measure it).
* ``expert-v1`` — the same planner over every actor that exists (ground truth, the
  ``"privileged"`` sensor), hidden ones included, with constant-velocity forecasts: the first
  privileged reference, which validated (filtered) the ``lantern-v2`` suite and, so that its
  pairs of the five families whose scenes did not change stay exactly those of ``lantern-v2``,
  ``lantern-v3``.  It is kept so that the suite regenerates exactly from its seed; it reacts to
  a waiting hazard only once it moves (see :mod:`lantern_jax.policies.expert`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.core.constants import BIG
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
from lantern_jax.types import language
from lantern_jax.types.observation import (
    FRONT_CAMERA,
    PRIVILEGED,
    WARNING,
    Observation,
    stated_position,
)

# What a warning text asks ``coop`` for, as integer codes for the jitted policy.
SEM_NONE = -1  # nothing the rule understands
SEM_LANE_OBSTACLE = 0  # a stopped obstacle in the ego lane at the stated position
SEM_CUT_IN = 1  # a vehicle entering the ego lane at the stated position
SEM_YIELD_TURN = 2  # yield before the turn

#: The keyword rule, in the order it is tried: (response, keywords).  A keyword matches when its
#: token ids occur in the text (each spelling tokenised on its own, lower and capitalised).
KEYWORD_RULE: tuple[tuple[int, tuple[str, ...]], ...] = (
    (SEM_YIELD_TURN, ("yield",)),
    (SEM_CUT_IN, ("cut into",)),
    (SEM_LANE_OBSTACLE, ("ego lane",)),
)


@functools.cache
def keyword_tables() -> tuple[np.ndarray, np.ndarray]:
    """The rule's keywords as token-id rows (outside ``jit``, once).

    Returns:
        ids: (K, M) int32, every spelling's token ids, padded with -1.
        response: (K,) int32, the response code of each row (:data:`KEYWORD_RULE` order).
    """
    tok = language.load_tokenizer()
    rows, codes = [], []
    for code, words in KEYWORD_RULE:
        for word in words:
            for spelling in dict.fromkeys((word, word[:1].upper() + word[1:])):
                rows.append(tok.encode(spelling, add_special_tokens=False).ids)
                codes.append(code)
    width = max(map(len, rows))
    ids = np.full((len(rows), width), -1, np.int32)
    for i, r in enumerate(rows):
        ids[i, : len(r)] = r
    return ids, np.asarray(codes, np.int32)


def text_response(tokens: jax.Array) -> jax.Array:
    """() int32: the response code the keyword rule gives a text (``SEM_NONE``: no keyword).

    Every keyword row is compared with every window of the text at once: (K, M, L) equalities
    of the shifted token rows, no gather (the policy runs this every tick)."""
    ids, codes = keyword_tables()
    k = jnp.asarray(ids)[:, :, None]  # (K, M, 1)
    match = (language.shifted_rows(tokens, ids.shape[1])[None] == k) | (k < 0)  # (K, M, L)
    hits = jnp.any(jnp.all(match, axis=1), axis=1)  # (K,)
    first = jnp.argmax(hits)
    return jnp.where(jnp.any(hits), jnp.asarray(codes)[first], SEM_NONE)


def warning_constraints(p: PlannerConfig, obs: Observation, seen: jax.Array) -> Constraints:
    """Virtual constraints from the delivered text (all inactive when there is none).

    Args:
        p: planner parameters.
        obs: observation (its warning tokens; all padding without the warning sensor).
        seen: (A,) bool, actors the policy sees (used to match a cut-in vehicle's velocity).
    """
    sem = text_response(obs.warning_tokens)
    pos, has_pos = stated_position(obs)
    arc, _ = project_on_route(obs.route, pos)
    ahead = has_pos & (arc > 0.0)

    obstacle = stop_constraint(p, arc - 1.0, (sem == SEM_LANE_OBSTACLE) & ahead)

    # Cut-in: a leader at the stated position, with a matched seen actor's speed.
    rel = obs.actor_xy - pos[None, :]
    d = jnp.where(seen, jnp.sum(rel * rel, axis=-1), BIG)  # squared distance (no sqrt)
    j = jnp.argmin(d)
    matched = d[j] < p.match_radius**2
    v_match = jnp.where(matched, jnp.maximum(obs.actor_vel[j, 0], 0.0), 0.0)
    cut_gap = jnp.where((sem == SEM_CUT_IN) & ahead, jnp.maximum(arc - p.cut_in_setback, 0.0), BIG)
    cut = Constraints(gap=cut_gap[None], speed=v_match[None], s0=jnp.full((1,), p.cut_in_s0))

    entry = turn_entry_arc(obs.route, p.turn_threshold)
    yield_arc = jnp.where(entry < BIG * 0.5, jnp.maximum(entry - p.yield_setback, 0.0), BIG)
    yld = stop_constraint(p, yield_arc, (sem == SEM_YIELD_TURN) & (yield_arc < BIG * 0.5))
    return merge(obstacle, cut, yld)


@struct.dataclass
class ReferenceParams:
    """Parameters of the reference policies (the planner's; one act function for all three,
    their sensors make the difference)."""

    planner: PlannerConfig


def reference_act(params: ReferenceParams, obs: Observation) -> jax.Array:
    """The shared act function of the reference policies.

    It plans over the actors its sensors give it: the cameras' (``obs.visible``), or every
    actor that exists when it has the privileged sensor (``expert-v1``); and it answers the
    warning text with the keyword rule when it has the warning sensor (``coop``; without it
    the text is always empty and the rule gives nothing).

    Args:
        params: :class:`ReferenceParams`.
        obs: one scenario's observation.

    Returns:
        (10, 2) float32 waypoints, ego frame (x forward, y right), 0.25 s apart.
    """
    if obs.privileged is not None:
        truth = obs.privileged
        obs = obs.replace(
            actor_xy=truth.actor_xy, actor_vel=truth.actor_vel, actor_dir=truth.actor_dir,
            actor_extent=truth.actor_extent, actor_kind=truth.actor_kind, visible=truth.present,
        )  # fmt: skip
    extra = warning_constraints(params.planner, obs, obs.visible)
    return plan(params.planner, obs, obs.visible, extra)[0]


def reference_params(key: jax.Array) -> ReferenceParams:
    """The reference policies' parameters (the default planner; ``key`` is unused)."""
    del key
    return ReferenceParams(planner=default_planner_config())


def legacy_expert_policy() -> Policy:
    """``expert-v1``: the planner over every actor that exists (the ``lantern-v3`` suite
    validator)."""
    return Policy(
        "expert-v1",
        reference_params,
        reference_act,
        "the lantern-v3 suite validator: the ego planner over every present actor with "
        "constant-velocity forecasts (kept so lantern-v3 regenerates exactly)",
        sensors=(FRONT_CAMERA, PRIVILEGED),
    )


def ego_policy() -> Policy:
    """The planner restricted to the front camera; no warning sensor."""
    return Policy(
        "ego",
        reference_params,
        reference_act,
        "the same planner restricted to the front camera; no warning sensor",
    )


def coop_policy() -> Policy:
    """``ego`` plus the warning sensor, read by the keyword rule."""
    return Policy(
        "coop",
        reference_params,
        reference_act,
        "front-camera planner + the warning text read by a keyword rule (yield / cut into / "
        "ego lane) as virtual constraints",
        sensors=(FRONT_CAMERA, WARNING),
    )
