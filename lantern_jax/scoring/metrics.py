"""Per-execution outputs (hard) from the final :class:`~lantern_jax.scoring.telemetry.Telemetry`.

Paper appendix "Complete Cooperative Unified Score".  One execution per call; ``vmap`` outside.

Missing-value rules
-------------------
* Protocol and first-crossing times are ``NaN`` when they never happened.
* Valid hazard telemetry: let ``t_fail`` be the time stamp of the first Route A gate failure
  (collision, route deviation >= 30 m, lane debounce reached, red-light violation, 20 s
  standstill, controller fault; an unfinished route fails at the last folded tick; no failure =
  never; the gates' ``failure_times``).  A component is *available* only if its window opened
  no later than ``t_fail`` (each component's ``valid``):

  ===============  ===================================================================
  TTC              ``t_ref`` happened and ``t_ref <= t_fail``
  clearance        ``t_event`` happened, ``t_event <= t_fail``, and the window held at
                   least one sample (hazard present or a collision)
  anticipation     ``t_ref`` and ``t_event`` happened and ``t_ref <= t_fail``
  recovery         ``t_release`` happened and ``t_release <= t_fail``
  ===============  ===================================================================

  Unavailable components are ``NaN`` (never imputed): ``ttc_min_s``, ``clearance_min_m``,
  ``t_react_s`` and ``recovery_latency_s``.
* Available but without a sample: ``ttc_min_s = inf`` when no tick had a closing trend (scores 1),
  ``t_react_s = NaN`` when no sustained response occurred (scores 0), ``recovery_latency_s = NaN``
  when the ego never recovered (scores 0).  The ``*_available`` flags tell these apart.
* Coincident onset (Right-Turn Yield): ``t_react_s`` is the start of the window ending at the
  event tick when that window already met the response criterion, otherwise the first sustained
  response at/after ``t_ref`` (which is >= ``t_event`` and scores 0).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import happened, time_or_nan
from lantern_jax.scoring import user_metrics
from lantern_jax.scoring.components import (
    HAZARD_COMPONENTS,
    ROUTE_A_GATES,
    anticipation,
    block,
    clearance,
    collision,
    efficiency,
    false_brake,
    lane,
    progress,
    recovery,
    route_deviation,
    rule,
    ttc,
)
from lantern_jax.scoring.telemetry import Telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings

Array = jax.Array


@struct.dataclass
class ExecutionMetrics:
    """Hard per-execution outputs (scalars per execution; a leading batch axis under ``vmap``)."""

    is_route_a: Array  # () bool
    coincident_onset: Array  # () bool
    progress: Array  # () float32, route completion, clip(progress / (length - 2 m), 0, 1)
    progress_m: Array  # () float32, m
    route_length_m: Array  # () float32, m
    completed: Array  # () bool, progress >= route_length - 2 m at the end
    ttc_min_s: Array  # () float32, s, NaN unavailable, inf no closing trend
    clearance_min_m: Array  # () float32, m, NaN unavailable
    t_ref_s: Array  # () float32, s (warning point), NaN never
    t_event_s: Array  # () float32, s, NaN never
    t_warn_off_s: Array  # () float32, s, NaN never
    t_clear_s: Array  # () float32, s, NaN never
    t_release_s: Array  # () float32, s, max(t_warn_off, t_clear), NaN never
    t_react_s: Array  # () float32, s, NaN unavailable or no response
    t_recover_s: Array  # () float32, s, NaN unavailable or no recovery
    recovery_latency_s: Array  # () float32, s, t_recover - t_release, NaN unavailable/no recovery
    v_pre_mps: Array  # () float32, m/s, ego speed before warning onset (last tick before t_ref;
    #                   NaN when t_ref never happened)
    event_exposed: Array  # () bool, the physical event began (t_event recorded): Event Exposure
    response_at_event: Array  # () bool, the window ending at the event tick met the criterion
    ttc_available: Array  # () bool
    clearance_available: Array  # () bool
    anticipation_available: Array  # () bool
    recovery_available: Array  # () bool
    gate_collision: Array  # () bool, passed (no collision)
    gate_route_deviation: Array  # () bool, passed (distance to route always < 30 m)
    gate_lane: Array  # () bool, passed (< 1 s in total outside the driving lanes)
    gate_rule: Array  # () bool, passed (no red-light violation)
    gate_block: Array  # () bool, passed (no 20 s standstill, route completed, no controller fault)
    gate_false_brake: Array  # () bool, passed (no unjustified 1 s stop touching the matched
    #                          stretch of route; see scoring.components.false_brake)
    controller_fault: Array  # () bool, the policy's plan was unusable (NaN/inf, or over
    #                          MAX_PLAN_SPEED) on some tick
    t_fault_s: Array  # float32, s, first controller fault (NaN none)
    stalled: Array  # () bool, standstill of >= 20 s with the route unfinished
    timed_out: Array  # () bool, route not completed at the end of the execution
    t_first_failure_s: Array  # () float32, s, first Route A gate failure (NaN none)
    max_route_dist_m: Array  # () float32, m
    outside_lanes_s: Array  # () float32, s, total time outside the driving lanes
    max_still_s: Array  # () float32, s, longest standstill with the route unfinished
    false_brake_max_stop_s: Array  # () float32, s, longest unjustified stop touching the matched
    #                                stretch of route (Route B false brake)
    t_complete_s: Array  # () float32, s, first tick in the route's end zone (NaN: not completed)
    slow_unjustified_s: Array  # () float32, s, below half the reference speed with nothing
    #                            justifying it (efficiency diagnostic, not part of the CUS)
    metrics: tuple = ()  # () float32 each, the values of ``settings.metrics`` (user metrics)


def first_failure_time(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> Array:
    """() float32, s: time stamp of the first Route A gate failure (``NEVER`` if none)."""
    times = []
    for name, gate in ROUTE_A_GATES.items():
        times += gate.failure_times(getattr(tel, name), tel.context, settings)
    return jnp.min(jnp.stack(times), axis=0)


def release_time(tel: Telemetry) -> Array:
    """() float32, s: ``max(t_warn_off, t_clear)`` once both happened, else ``NEVER``."""
    return recovery.release_time(tel.context.t_warn_off, tel.context.t_clear)


def availability(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> dict[str, Array]:
    """Valid-hazard-telemetry masks (see the module docstring) as () bool arrays."""
    t_fail = first_failure_time(tel, settings)
    return {
        name: unit.valid(getattr(tel, name), tel.context, t_fail)
        for name, unit in HAZARD_COMPONENTS.items()
    }


def _or_nan(value_valid: tuple[Array, Array]) -> Array:
    """A hard ``(value, valid)`` pair as one value, ``NaN`` where unavailable."""
    value, valid = value_valid
    return jnp.where(valid, value, jnp.nan)


def finalize(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> ExecutionMetrics:
    """Per-execution hard outputs from the final accumulators (jittable).

    Args:
        tel: final accumulators of one execution.
        settings: the scoring settings the accumulators were folded with.
    """
    ctx = tel.context
    t_fail = first_failure_time(tel, settings)
    avail = availability(tel, settings)
    completed = progress.is_completed(ctx.progress_m, ctx.route_length_m, settings)
    s = settings
    return ExecutionMetrics(
        is_route_a=ctx.is_route_a,
        coincident_onset=ctx.coincident_onset,
        progress=progress.hard(ctx, s)[0],
        progress_m=ctx.progress_m,
        route_length_m=ctx.route_length_m,
        completed=completed,
        ttc_min_s=_or_nan(ttc.hard(tel.ttc, ctx, t_fail)),
        clearance_min_m=_or_nan(clearance.hard(tel.clearance, ctx, t_fail)),
        t_ref_s=time_or_nan(ctx.t_warn_point),
        t_event_s=time_or_nan(ctx.t_event),
        t_warn_off_s=time_or_nan(ctx.t_warn_off),
        t_clear_s=time_or_nan(ctx.t_clear),
        t_release_s=time_or_nan(release_time(tel)),
        t_react_s=_or_nan(anticipation.hard(tel.anticipation, ctx, t_fail)),
        t_recover_s=_or_nan(recovery.recovered_at(tel.recovery, ctx, t_fail)),
        recovery_latency_s=_or_nan(recovery.hard(tel.recovery, ctx, t_fail)),
        v_pre_mps=jnp.where(ctx.v_pre_set, ctx.v_pre, jnp.nan),
        event_exposed=happened(ctx.t_event),
        response_at_event=tel.anticipation.response_at_event,
        ttc_available=avail["ttc"],
        clearance_available=avail["clearance"],
        anticipation_available=avail["anticipation"],
        recovery_available=avail["recovery"],
        gate_collision=collision.hard(tel.collision, ctx, s)[0],
        gate_route_deviation=route_deviation.hard(tel.route_deviation, ctx, s)[0],
        gate_lane=lane.hard(tel.lane, ctx, s)[0],
        gate_rule=rule.hard(tel.rule, ctx, s)[0],
        gate_block=block.hard(tel.block, ctx, s)[0],
        gate_false_brake=false_brake.hard(tel.false_brake, ctx, s)[0],
        controller_fault=tel.block.fault,
        t_fault_s=time_or_nan(tel.block.t_fault),
        stalled=block.stalled(tel.block, s),
        timed_out=~completed,
        t_first_failure_s=time_or_nan(t_fail),
        max_route_dist_m=tel.route_deviation.max_dist,
        outside_lanes_s=lane.outside_s(tel.lane),
        max_still_s=block.max_still_s(tel.block),
        false_brake_max_stop_s=false_brake.max_stop_s(tel.false_brake),
        t_complete_s=time_or_nan(tel.efficiency.t_complete),
        slow_unjustified_s=efficiency.slow_s(tel.efficiency),
        metrics=user_metrics.values(s.metrics, tel.metrics, ctx, s),
    )
