"""Rollouts that also watch the actors a stress test controls: distances, stops, road, speed.

The benchmark's telemetry measures the ego against the hazard only.  A stress test drives other
actors too (adversarial tracks) and must judge their plausibility
(:mod:`lantern_jax.apps.stress.plausibility`), so its rollouts fold a :class:`Watch` next to the
simulator's state, tick by tick, for ``W`` **watched** slots (static indices: the hazard and
every slot with a track; ``tracked`` marks the latter):

* the collision margin ``max(box distance, 0.1 m/s - ego speed)`` and the box distance to the
  ego, as hard minima and log-sum-exp soft minima over the ticks the actor is present;
* the distance of the nearest watched actor present, integrated over the ticks any is
  present, and that time (their ratio is the mean distance KING's objective uses,
  :mod:`lantern_jax.apps.stress.king`);
* for tracked actors after their track has started: the longest stop in the ego's path (hard
  run length) and its soft count, the time off the road (hard and soft), the highest speed;
* every ``traj_every`` ticks, the watched actors' positions (the near-duplicate rule compares
  them; NaN while absent).

:func:`soft_rollout` is one execution over a fixed horizon (``lax.scan``, rematerialised for the
backward pass), :func:`soft_rollout_batch` a batch of them in one scan; :func:`hard_batch` runs
a batch until every execution has ended (the evaluation's chunked ``while_loop`` with early
exit) and returns the hard per-execution metrics beside the watch.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.core.constants import BIG, DT, EGO_HALF_LENGTH, KIND_PEDESTRIAN
from lantern_jax.core.times import happened
from lantern_jax.dynamics.adversary import track_start
from lantern_jax.dynamics.scripted import trigger_time
from lantern_jax.maths import geometry, polyline
from lantern_jax.scoring.measure import EGO_EXTENT
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.smooth import LSE_EMPTY, lse_add
from lantern_jax.scoring.thresholds import ScoringSettings
from lantern_jax.sim.rollout import start_state, with_carry
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.state import State, init_state
from lantern_jax.sim.step import Driver, step
from lantern_jax.types.world import Scenario, present

Array = jax.Array

TRAJ_EVERY = 5  # ticks (0.25 s) between recorded positions of the watched actors


@struct.dataclass
class Watch:
    """Accumulators of one execution about its W watched actors (see the module docstring)."""

    margin: Array  # (W,) float32, m, hard min collision margin (BIG before any sample)
    margin_lse: Array  # (W,) float32, soft-min accumulator of the same
    dist: Array  # (W,) float32, m, hard min box distance to the ego
    dist_lse: Array  # (W,) float32, soft-min accumulator of the same
    near_sum: Array  # () float32, m s, box distance of the nearest watched actor present,
    #                  integrated over the ticks any is present
    near_seen: Array  # () float32, s, time any watched actor was present
    stop_run: Array  # (W,) float32, s, current stop in the ego's path (tracked actors)
    stop_max: Array  # (W,) float32, s, longest such stop
    stop_soft: Array  # (W,) float32, s, soft time stopped in the ego's path
    off_road: Array  # (W,) float32, s, time off the road (tracked actors)
    off_road_soft: Array  # (W,) float32, s, soft time off the road
    max_speed: Array  # (W,) float32, m/s, highest speed after the track's start
    traj: Array  # (K, W, 2) float32, m, positions every TRAJ_EVERY ticks (NaN absent)


def init_watch(num: int, records: int) -> Watch:
    """Empty accumulators for ``num`` watched actors and ``records`` recorded positions."""
    big = jnp.full((num,), BIG, jnp.float32)
    empty = jnp.full((num,), LSE_EMPTY, jnp.float32)
    zero = jnp.zeros((num,), jnp.float32)
    traj = jnp.full((records, num, 2), jnp.nan, jnp.float32)
    none = jnp.zeros((), jnp.float32)
    return Watch(margin=big, margin_lse=empty, dist=big, dist_lse=empty, near_sum=none,
                 near_seen=none, stop_run=zero, stop_max=zero, stop_soft=zero, off_road=zero,
                 off_road_soft=zero, max_speed=zero, traj=traj)  # fmt: skip


def _off_road(scenario: Scenario, slots: Array, xy: Array, lane_margin: Array) -> Array:
    """(W,) float32, m: how far each watched actor is beyond its road (<= 0 on it): a walker
    beyond :data:`~lantern_jax.apps.stress.plausibility.WALKER_CORRIDOR_M` of its own path, a
    vehicle beyond every lane's half width + ``lane_margin`` (the scoring's lane margin)."""
    script, lanes = scenario.actors, scenario.lanes
    walker = script.kind[slots] == KIND_PEDESTRIAN
    own, _ = jax.vmap(polyline.nearest_segment)(script.path[slots], script.path_valid[slots], xy)

    def lane_excess(p):
        d, _ = jax.vmap(polyline.nearest_segment, in_axes=(0, 0, None))(
            lanes.center, lanes.point_valid, p
        )
        excess = d - (0.5 * lanes.width + lane_margin)
        return jnp.min(jnp.where(lanes.valid, excess, BIG))

    return jnp.where(walker, own - rules.WALKER_CORRIDOR_M, jax.vmap(lane_excess)(xy))


def update_watch(
    w: Watch,
    scenario: Scenario,
    new: State,
    live: Array,
    slots: Array,
    tracked: Array,
    scoring: ScoringSettings,
) -> Watch:
    """Fold one tick (the state ``new`` at its end) into the accumulators of ONE execution.

    Args:
        w: accumulators before the tick.
        scenario: the execution's scenario.
        new: the state after the tick.
        live: () bool, the execution had not ended before the tick (else nothing changes).
        slots: (W,) int32, the watched slots.
        tracked: (W,) bool, which of them have tracks.
        scoring: the scoring settings (the soft minima's temperature, m and s; the collision
            speed; the lane margin).
    """
    temperature = scoring.temperature
    script, actors, ego = scenario.actors, new.actors, new.ego
    idx = jnp.asarray(slots, jnp.int32)
    xy, yaw, ext = actors.xy[idx], actors.yaw[idx], script.extent[idx]
    here = live & present(script, actors)[idx]
    d = geometry.distance_to_boxes(
        ego.xy, ego.yaw, jnp.asarray(EGO_EXTENT, jnp.float32), xy, yaw, ext
    )
    m = jnp.maximum(d, scoring.collision_min_speed_mps - ego.speed)

    # tracked actors after the start of their track
    t_event = new.protocol.t_event
    tau = trigger_time(
        script.trigger[idx], script.trigger_delay[idx], t_event, script.trigger_deadline[idx]
    )
    start = track_start(script.trigger[idx], tau, t_event)
    began = happened(start) & (new.t >= jnp.where(happened(start), start, 0.0))
    on = here & jnp.asarray(tracked) & began
    route = scenario.route
    arc, _, _, dist_r = jax.vmap(polyline.project, in_axes=(None, None, None, 0))(
        route.xy, route.s, route.valid, xy
    )
    lateral = dist_r - ext[:, 1]
    ahead = arc - (new.percept.route_arc - EGO_HALF_LENGTH)
    speed = jnp.abs(actors.speed[idx])
    stopped = on & (lateral < rules.IN_PATH_M) & (ahead > 0.0) & (speed < rules.STOP_SPEED_MPS)
    run = jnp.where(stopped, w.stop_run + DT, jnp.where(live, 0.0, w.stop_run))
    in_path_soft = jax.nn.sigmoid((rules.IN_PATH_M - lateral) / rules.SOFT_DIST_M)
    ahead_soft = jax.nn.sigmoid(ahead / rules.SOFT_DIST_M)
    slow_soft = jax.nn.sigmoid((rules.STOP_SPEED_MPS - speed) / rules.SOFT_SPEED_MPS)
    soft_stop = in_path_soft * ahead_soft * slow_soft
    excess = _off_road(scenario, idx, xy, scoring.lane_margin_m)
    seen = jnp.any(here)  # some watched actor is present at this tick

    traj = w.traj
    if traj.shape[0] > 0:
        k = jnp.minimum(new.tick // TRAJ_EVERY, traj.shape[0] - 1)
        row = jnp.where(here[:, None], xy, jnp.nan)
        write = live & (new.tick % TRAJ_EVERY == 0)
        traj = traj.at[k].set(jnp.where(write, row, traj[k]))
    return Watch(
        margin=jnp.where(here, jnp.minimum(w.margin, m), w.margin),
        margin_lse=jnp.where(here, lse_add(w.margin_lse, m, temperature), w.margin_lse),
        dist=jnp.where(here, jnp.minimum(w.dist, d), w.dist),
        dist_lse=jnp.where(here, lse_add(w.dist_lse, d, temperature), w.dist_lse),
        near_sum=w.near_sum + jnp.where(seen, DT * jnp.min(jnp.where(here, d, BIG)), 0.0),
        near_seen=w.near_seen + jnp.where(seen, DT, 0.0),
        stop_run=run,
        stop_max=jnp.maximum(w.stop_max, run),
        stop_soft=w.stop_soft + jnp.where(on, DT * soft_stop, 0.0),
        off_road=w.off_road + jnp.where(on & (excess > 0.0), DT, 0.0),
        off_road_soft=w.off_road_soft
        + jnp.where(on, DT * jax.nn.sigmoid(excess / rules.SOFT_DIST_M), 0.0),
        max_speed=jnp.where(on, jnp.maximum(w.max_speed, speed), w.max_speed),
        traj=traj,
    )


def _tick(policy: Driver, params: Any, scenario: Scenario, slots, tracked, settings: Settings):
    """``(state, watch) -> (state, watch)``: one tick of ONE execution with its watch."""

    def body(carry: tuple[State, Watch], _) -> tuple[tuple[State, Watch], None]:
        state, w = carry
        new, _ = step(policy, params, scenario, state, settings)
        watch = update_watch(w, scenario, new, ~state.done, slots, tracked, settings.scoring)
        return (new, watch), None

    return body


def soft_rollout(
    scenario: Scenario,
    policy: Driver,
    params: Any,
    horizon: int,
    settings: Settings,
    slots: Array,
    tracked: Array,
) -> tuple[State, Watch]:
    """One execution over ``horizon`` ticks with its watch of the slots ``slots`` (W,) int32
    (``tracked`` (W,) bool: those with tracks); differentiable end to end, each tick recomputed
    in the backward pass, so memory grows with the carry only; ``settings`` carry the soft
    temperature (``settings.scoring.temperature``)."""
    body = jax.checkpoint(_tick(policy, params, scenario, slots, tracked, settings))
    init = (start_state(scenario, policy, params, settings), init_watch(slots.shape[0], 0))
    return jax.lax.scan(body, init, None, length=horizon)[0]


def soft_rollout_batch(
    scenarios: Scenario,
    policy: Driver,
    params: Any,
    horizon: int,
    settings: Settings,
    slots: Array,
    tracked: Array,
) -> tuple[State, Watch]:
    """:func:`soft_rollout` of N executions (the leading axis of every leaf of ``scenarios``,
    ``slots`` (N, W) and ``tracked`` (N, W)), as one scan whose tick is the one-execution tick
    vmapped over the batch.

    The batch is vmapped inside the scan, not the scan under ``vmap``: batching a scan whose
    carry varies over the batch only in part makes JAX re-batch the whole tick until it knows
    which parts do, forwards and again in the backward pass.  For the stress surrogate (a
    batch of candidates of one scene, ``benchmarks/bench_soft_compile.py``) this form traced
    in 13 s instead of 35 s and compiled in 40 s instead of 48 s.  Where the whole carry
    varies over the batch (every pair of a suite: the fragility radii) ``vmap`` of
    :func:`soft_rollout` compiled faster (23 s against 30 s) and is kept there.  Each
    execution's ticks are the same either way; a differentiated output of execution ``i``
    depends on the inputs of execution ``i`` only, so the gradient of a sum over the batch is
    every execution's own gradient.
    """

    def one_tick(scenario, watched, marks, carry: tuple[State, Watch]) -> tuple[State, Watch]:
        return _tick(policy, params, scenario, watched, marks, settings)(carry, None)[0]

    def tick(carry: tuple[State, Watch], _) -> tuple[tuple[State, Watch], None]:
        return jax.vmap(one_tick)(scenarios, slots, tracked, carry), None

    def start(scenario: Scenario) -> tuple[State, Watch]:
        return start_state(scenario, policy, params, settings), init_watch(slots.shape[1], 0)

    init = jax.vmap(start)(scenarios)
    return jax.lax.scan(jax.checkpoint(tick), init, None, length=horizon)[0]


def hard_batch(
    scenarios: Scenario,
    policy: Driver,
    params: Any,
    max_ticks: int,
    slots: Array,
    tracked: Array,
    settings: Settings = DEFAULT_SETTINGS,
    chunk: int = 40,
) -> tuple[Any, Watch]:
    """Roll a batch (leading axis on every leaf) until every execution has ended.

    Returns:
        ``(metrics, watch)``: the batch's hard :class:`~lantern_jax.scoring.metrics.
        ExecutionMetrics` and its :class:`Watch` (positions every :data:`TRAJ_EVERY` ticks).
    """
    n_chunks = -(-max_ticks // chunk)
    records = -(-max_ticks // TRAJ_EVERY) + 1

    def run_chunk(scenario, carry):
        body = _tick(policy, params, scenario, slots, tracked, settings)
        return jax.lax.scan(body, carry, None, length=chunk)[0]

    batched = jax.vmap(run_chunk)
    n = scenarios.config.is_route_a.shape[0]
    starts = jax.vmap(lambda sc: init_state(sc, (), settings.scoring))(scenarios)
    states = with_carry(starts, policy, params)
    w0 = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (n, *x.shape)), init_watch(slots.shape[0], records)
    )

    def cond(loop):
        return (loop[0] < n_chunks) & ~jnp.all(loop[1][0].done)

    def body(loop):
        i, carry = loop
        return i + 1, batched(scenarios, carry)

    _, (final, w) = jax.lax.while_loop(cond, body, (jnp.asarray(0, jnp.int32), (states, w0)))
    return jax.vmap(lambda tel: finalize(tel, settings.scoring))(final.telemetry), w
