"""Per-execution outputs (hard) from the final :class:`~lantern_jax.scoring.telemetry.Telemetry`.

Paper appendix "Complete Cooperative Unified Score".  One execution per call; ``vmap`` outside.

Missing-value rules
-------------------
* Protocol and first-crossing times are ``NaN`` when they never happened.
* Valid hazard telemetry: let ``t_fail`` be the time stamp of the first Route A gate failure
  (collision, route deviation >= 30 m, lane debounce reached, red-light violation, 20 s
  standstill, controller fault; an unfinished route fails at the last folded tick; no failure =
  never).  A component is *available* only if its window opened no later than ``t_fail``:

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

from lantern_jax.constants import DT, INF_TIME
from lantern_jax.scoring import thresholds as th
from lantern_jax.scoring.telemetry import Telemetry

Array = jax.Array


@struct.dataclass
class ExecutionMetrics:
    """Hard per-execution outputs (scalars per execution; a leading batch axis under ``vmap``)."""

    is_route_a: Array  # bool
    coincident_onset: Array  # bool
    progress: Array  # float32, route completion, clip(progress / (length - 2 m), 0, 1)
    progress_m: Array  # float32, m
    route_length_m: Array  # float32, m
    completed: Array  # bool, progress >= route_length - 2 m at the end
    ttc_min_s: Array  # float32, s, NaN unavailable, inf no closing trend
    clearance_min_m: Array  # float32, m, NaN unavailable
    t_ref_s: Array  # float32, s (warning point), NaN never
    t_event_s: Array  # float32, s, NaN never
    t_warn_off_s: Array  # float32, s, NaN never
    t_clear_s: Array  # float32, s, NaN never
    t_release_s: Array  # float32, s, max(t_warn_off, t_clear), NaN never
    t_react_s: Array  # float32, s, NaN unavailable or no response
    t_recover_s: Array  # float32, s, NaN unavailable or no recovery
    recovery_latency_s: Array  # float32, s, t_recover - t_release, NaN unavailable/no recovery
    v_pre_mps: Array  # float32, m/s, ego speed at the first tick with t >= t_ref (NaN never)
    response_at_event: Array  # bool, the window ending at the event tick met the criterion
    ttc_available: Array  # bool
    clearance_available: Array  # bool
    anticipation_available: Array  # bool
    recovery_available: Array  # bool
    gate_collision: Array  # bool, passed (no collision)
    gate_route_deviation: Array  # bool, passed (distance to route always < 30 m)
    gate_lane: Array  # bool, passed (< 1 s in total outside the driving lanes)
    gate_rule: Array  # bool, passed (no red-light violation)
    gate_block: Array  # bool, passed (no 20 s standstill, route completed, no controller fault)
    gate_false_brake: Array  # bool, passed (no unjustified 1 s stop in [t_ref, t_event])
    controller_fault: Array  # bool, the policy produced NaN/inf waypoints on some tick
    stalled: Array  # bool, standstill of >= 20 s with the route unfinished
    timed_out: Array  # bool, route not completed at the end of the execution
    t_first_failure_s: Array  # float32, s, first Route A gate failure (NaN none)
    max_route_dist_m: Array  # float32, m
    outside_lanes_s: Array  # float32, s, total time outside the driving lanes
    max_still_s: Array  # float32, s, longest standstill with the route unfinished
    false_brake_max_stop_s: Array  # float32, s, longest unjustified stop in [t_ref, t_event]


def _happened(t: Array) -> Array:
    return t < th.HAPPENED_BELOW


def _time_or_nan(t: Array) -> Array:
    return jnp.where(_happened(t), t, jnp.nan)


def first_failure_time(tel: Telemetry) -> Array:
    """() float32, s: time stamp of the first Route A gate failure (``INF_TIME`` if none)."""
    completed = tel.progress_m >= tel.route_length_m - th.COMPLETION_TOL_M
    t_unfinished = jnp.where(completed, INF_TIME, tel.t_last)
    times = jnp.stack(
        [
            tel.t_collision,
            tel.t_route_dev,
            tel.t_lane_fail,
            tel.t_rule,
            tel.t_stall,
            tel.t_fault,
            t_unfinished,
        ]
    )
    return jnp.min(times, axis=0)


def release_time(tel: Telemetry) -> Array:
    """() float32, s: ``max(t_warn_off, t_clear)`` once both happened, else ``INF_TIME``."""
    both = _happened(tel.t_warn_off) & _happened(tel.t_clear)
    return jnp.where(both, jnp.maximum(tel.t_warn_off, tel.t_clear), INF_TIME)


def availability(tel: Telemetry) -> dict[str, Array]:
    """Valid-hazard-telemetry masks (see the module docstring) as () bool arrays."""
    t_fail = first_failure_time(tel)
    t_rel = release_time(tel)
    ref_ok = _happened(tel.t_warn_point) & (tel.t_warn_point <= t_fail)
    return {
        "ttc": ref_ok,
        "clearance": _happened(tel.t_event) & (tel.t_event <= t_fail) & tel.clear_any,
        "anticipation": ref_ok & _happened(tel.t_event),
        "recovery": _happened(t_rel) & (t_rel <= t_fail),
    }


def finalize(tel: Telemetry) -> ExecutionMetrics:
    """Per-execution hard outputs from the final accumulators (jittable)."""
    nan = jnp.nan
    avail = availability(tel)
    t_fail = first_failure_time(tel)
    t_rel = release_time(tel)
    length = tel.route_length_m
    span = th.completion_length(length)
    frac = jnp.where(span > 0, tel.progress_m / jnp.where(span > 0, span, 1.0), 0.0)
    completed = tel.progress_m >= length - th.COMPLETION_TOL_M

    ttc = jnp.where(tel.ttc_any, tel.ttc_min, jnp.inf)
    t_react = jnp.where(
        tel.coincident_onset & tel.response_at_event, tel.t_response_start, tel.t_react
    )
    t_react = jnp.where(avail["anticipation"], _time_or_nan(t_react), nan)
    recovered = avail["recovery"] & _happened(tel.t_recover)
    t_recover = jnp.where(recovered, tel.t_recover, nan)

    stalled = tel.max_still_run >= th.BLOCK_STILL
    return ExecutionMetrics(
        is_route_a=tel.is_route_a,
        coincident_onset=tel.coincident_onset,
        progress=jnp.clip(frac, 0.0, 1.0),
        progress_m=tel.progress_m,
        route_length_m=length,
        completed=completed,
        ttc_min_s=jnp.where(avail["ttc"], ttc, nan),
        clearance_min_m=jnp.where(avail["clearance"], tel.clear_min, nan),
        t_ref_s=_time_or_nan(tel.t_warn_point),
        t_event_s=_time_or_nan(tel.t_event),
        t_warn_off_s=_time_or_nan(tel.t_warn_off),
        t_clear_s=_time_or_nan(tel.t_clear),
        t_release_s=_time_or_nan(t_rel),
        t_react_s=t_react,
        t_recover_s=t_recover,
        recovery_latency_s=jnp.where(recovered, tel.t_recover - t_rel, nan),
        v_pre_mps=jnp.where(tel.v_pre_set, tel.v_pre, nan),
        response_at_event=tel.response_at_event,
        ttc_available=avail["ttc"],
        clearance_available=avail["clearance"],
        anticipation_available=avail["anticipation"],
        recovery_available=avail["recovery"],
        gate_collision=~tel.collided,
        gate_route_deviation=~_happened(tel.t_route_dev),
        gate_lane=tel.n_outside < th.LANE_DEBOUNCE,
        gate_rule=~tel.red_light,
        gate_block=~stalled & completed & ~tel.fault,
        gate_false_brake=tel.fb_max_run < th.FALSE_BRAKE,
        controller_fault=tel.fault,
        stalled=stalled,
        timed_out=~completed,
        t_first_failure_s=_time_or_nan(t_fail),
        max_route_dist_m=tel.max_route_dist,
        outside_lanes_s=tel.n_outside.astype(jnp.float32) * DT,
        max_still_s=tel.max_still_run.astype(jnp.float32) * DT,
        false_brake_max_stop_s=tel.fb_max_run.astype(jnp.float32) * DT,
    )
