"""Closed-loop visits and expert relabelling (the data side of DAgger).

The learner drives a batch of training scenes in the simulator; every ``every`` ticks the
visited state is kept with the observation the learner had there (the dataset's observation,
:data:`~lantern_jax.apps.dataset.record.FRONT_SENSORS`, or for a learner with the six-camera rig
the observation under :data:`~lantern_jax.apps.dataset.record.RIG_SENSORS`, the dataset's
``rig.*`` and ``surround.*`` columns), and the privileged expert relabels it: it
drives on from that very state (ego, actors, protocol, telemetry) for the label horizon, and
the label is its positions 0.25 ... 2.5 s later in the ego frame of the visited state — exactly
what :func:`lantern_jax.apps.dataset.frames.future_waypoints` computes from an expert recording. A
visit is valid when the execution is live there and for the whole horizon (the dataset's rule,
:func:`~lantern_jax.apps.dataset.frames.frame_indices`), and flags whether the horizon crosses
warning onset or termination (the dataset's ``horizon_crossing``).

With ``beta > 0`` the expert drives a segment (``segment`` visits long, one by default)
instead of the learner with probability ``beta`` (each segment and execution drawn on its own):
the DAgger mixture.  Every visit also carries its execution's first collision time, so that
host code can keep the visits just before a failure (``closed_loop``'s ``failure_window_s``).

Everything here is jitted and batched (``vmap`` over scenes); host code reads the result.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.apps.dataset.record import FRAME_TICKS, FRONT_SENSORS, RIG_SENSORS, data_settings
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.core.times import happened
from lantern_jax.policies.base import Policy
from lantern_jax.sim.engine import Program, check_texts
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import start_state
from lantern_jax.sim.settings import Settings
from lantern_jax.sim.state import State
from lantern_jax.sim.step import policy_waypoints, step, transition
from lantern_jax.types.observation import Observation
from lantern_jax.types.world import Scenario

Array = jax.Array


@struct.dataclass
class Visits:
    """Visited states of one execution (leading axis: visit; a batch adds one in front)."""

    obs: Observation  # the learner's observation at the visit (FRONT_SENSORS; RIG_SENSORS
    #                   for a learner with the six-camera rig)
    waypoints: Array  # (V, 10, 2) float32, m, ego frame: the expert's plan from the visit
    valid: Array  # (V,) bool, live at the visit and for the whole 2.5-s horizon
    t: Array  # (V,) float32, s, simulation time of the visit
    crosses_onset: Array  # (V,) bool, warning onset happens within the horizon
    crosses_termination: Array  # (V,) bool, warning termination happens within the horizon
    t_collision: Array  # (V,) float32, s, the execution's first collision (NEVER: none), per visit


def ego_frame_offsets(xy0: Array, yaw0: Array, xy: Array) -> Array:
    """(K, 2) float32, m: world positions ``xy`` (K, 2) in the ego frame of pose
    ``(xy0 (2,), yaw0 ())`` (x forward, y right), as
    :func:`~lantern_jax.apps.dataset.frames.future_waypoints` writes them."""
    rel = xy - xy0
    c, s = jnp.cos(yaw0), jnp.sin(yaw0)
    return jnp.stack([rel[:, 0] * c + rel[:, 1] * s, rel[:, 0] * s - rel[:, 1] * c], axis=-1)


def expert_label(
    scenario: Scenario, state: State, expert: Policy, expert_params: Any, settings: Settings
) -> tuple[Array, Array, Array, Array]:
    """The expert's label of one visited state: it drives on from ``state`` for 10 frames.

    Returns:
        waypoints: (10, 2) float32, m, ego frame of ``state``.
        live: () bool, the execution is live at ``state`` and at all ten future frames.
        crosses_onset, crosses_termination: () bool, the warning starts / ends within them.
    """
    start = state.replace(policy_carry=expert.initial_carry(expert_params))

    def tick(s, _):
        return step(expert, expert_params, scenario, s, settings)[0], None

    def frame(s, _):
        s = jax.lax.scan(tick, s, None, length=FRAME_TICKS)[0]
        return s, (s.ego.xy, ~s.done)

    final, (xy, live) = jax.lax.scan(frame, start, None, length=NUM_WAYPOINTS)
    wps = ego_frame_offsets(state.ego.xy, state.ego.yaw, xy).astype(jnp.float32)
    p0, p1 = state.protocol, final.protocol
    onset = happened(p1.t_warn_on) & ~happened(p0.t_warn_on)
    termination = happened(p1.t_warn_off) & ~happened(p0.t_warn_off)
    return wps, ~state.done & jnp.all(live), onset, termination


def _mixed_tick(learner, lp, expert, ep, scenario, settings, s: State, use_expert: Array):
    """One tick driven by the expert where ``use_expert`` (() bool), else by the learner (both
    stateless: the carry is kept as it is)."""
    w_l, _ = policy_waypoints(learner, lp, scenario, s, settings)
    w_e, _ = policy_waypoints(expert, ep, scenario, s, settings)
    return transition(scenario, s, jnp.where(use_expert, w_e, w_l), settings)[0]


def visit_and_relabel(
    scenario: Scenario, learner: Policy, learner_params: Any, expert: Policy, expert_params: Any,
    key: Array, beta: Array, phase: Array, *, num_visits: int, every: int, settings: Settings,
    segment: int = 1,
) -> Visits:  # fmt: skip
    """Roll one execution with the learner (the expert w.p. ``beta`` per segment of
    ``segment`` visits), keeping a visit every ``every`` ticks from tick ``phase`` until it
    ends or ``num_visits`` are kept; each visit is relabelled by :func:`expert_label`. Visits
    after the end are invalid. ``phase`` (() int32, ticks) is an argument, not part of the
    compiled program."""
    if learner.stateful or expert.stateful:
        raise ValueError("visit_and_relabel: stateful policies are not supported")

    def tick(st: State, use_expert: Array) -> State:
        return _mixed_tick(learner, learner_params, expert, expert_params, scenario, settings,
                           st, use_expert)  # fmt: skip

    def run(s: State, use_expert: Array) -> State:
        return jax.lax.scan(lambda st, _: (tick(st, use_expert), None), s, None, length=every)[0]

    sensors = RIG_SENSORS if learner.surround else FRONT_SENSORS
    state0 = start_state(scenario, learner, learner_params, settings)
    state0 = jax.lax.fori_loop(0, phase, lambda _, st: tick(st, jnp.asarray(False)), state0)

    def visit(s: State) -> Visits:
        wps, live, on, off = expert_label(scenario, s, expert, expert_params, settings)
        obs = observe(scenario, s, sensors, settings.bank)
        return Visits(obs, wps, live, s.t, on, off, s.telemetry.collision.t_collision)

    shapes = jax.eval_shape(visit, state0)
    empty = jax.tree.map(lambda x: jnp.zeros((num_visits, *x.shape), x.dtype), shapes)

    def body(carry):
        i, s, buf = carry
        buf = jax.tree.map(lambda b, x: b.at[i].set(x), buf, visit(s))
        use_expert = jax.random.bernoulli(jax.random.fold_in(key, i // segment), beta)
        return i + 1, run(s, use_expert), buf

    def cond(carry):
        i, s, _ = carry
        return (i < num_visits) & ~s.done

    _, final, buf = jax.lax.while_loop(cond, body, (jnp.asarray(0), state0, empty))
    # the loop stops at the end or after num_visits visits: a collision later is not seen
    t_coll = jnp.broadcast_to(final.telemetry.collision.t_collision, buf.t_collision.shape)
    return buf.replace(t_collision=t_coll)


@functools.partial(
    jax.jit, static_argnames=("learner", "expert", "num_visits", "every", "settings", "segment")
)
def _batch(scenarios, lp, ep, keys, beta, phase, *, learner, expert, num_visits, every,
           settings, segment):  # fmt: skip
    def one(sc, k):
        return visit_and_relabel(sc, learner.driver, lp, expert.driver, ep, k, beta, phase,
                                 num_visits=num_visits, every=every, settings=settings,
                                 segment=segment)  # fmt: skip

    return jax.vmap(one)(scenarios, keys)


def relabel_batch(
    scenarios: Scenario, learner: Policy, learner_params: Any, expert: Policy, expert_params: Any,
    key: Array, beta: float = 0.0, num_visits: int = 40, every: int = 40, phase: int = 0,
    settings: Settings | None = None, segment: int = 1,
) -> Visits:  # fmt: skip
    """:func:`visit_and_relabel` of a batch of scenarios (leading axis ``B``); one compiled
    program per (learner program, expert program, visit layout).

    Args:
        scenarios: the batch (``tree_stack`` of scenarios).
        learner, learner_params: the policy that drives (its parameters are an argument: a new
            round's weights reuse the compiled program).
        expert, expert_params: the relabelling policy (``expert``).
        key: PRNG key of the beta draws.
        beta: probability that the expert drives a segment.
        num_visits, every, phase: visits kept, ticks between visits, ticks before the first.
        segment: visits per segment of the beta mixture (a segment is ``segment * every``
            ticks).
        settings: default :func:`~lantern_jax.apps.dataset.record.data_settings`.

    Returns:
        :class:`Visits` with leading axes ``(B, num_visits)``.
    """
    settings = data_settings() if settings is None else settings
    check_texts(settings, scenarios)
    keys = jax.random.split(key, scenarios.config.family.shape[0])
    return _batch(scenarios, learner_params, expert_params, keys, jnp.float32(beta),
                  jnp.int32(phase), learner=Program(learner), expert=Program(expert),
                  num_visits=num_visits, every=every, settings=settings,
                  segment=segment)  # fmt: skip
