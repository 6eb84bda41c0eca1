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

import dataclasses
import warnings

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import happened, time_or_nan
from lantern_jax.scoring import user_metrics
from lantern_jax.scoring.components import (
    COMPONENTS,
    HAZARD_COMPONENTS,
    ROUTE_A_GATES,
    progress,
    recovery,
)
from lantern_jax.scoring.telemetry import Telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings

Array = jax.Array


@struct.dataclass
class ExecutionMetrics:
    """Hard per-execution outputs (scalars per execution; a leading batch axis under ``vmap``).

    Each field comes from the shared context (:data:`CONTEXT_FIELDS`) or from exactly one
    component of :data:`~lantern_jax.scoring.components.COMPONENTS`, whose ``outputs`` gives
    it (:data:`FIELD_OWNERS`); a new component's outputs are declared here and in its module's
    ``OUTPUTS``, and importing this module fails when the two disagree."""

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


#: The fields :func:`finalize` reads from the shared context (and the user metrics); every other
#: field is one component's output (its module's ``OUTPUTS``), exactly once.
CONTEXT_FIELDS = ("is_route_a", "coincident_onset", "progress", "progress_m", "route_length_m",
                  "completed", "t_ref_s", "t_event_s", "t_warn_off_s", "t_clear_s", "v_pre_mps",
                  "event_exposed", "timed_out", "t_first_failure_s", "metrics")  # fmt: skip


def _field_owners() -> dict[str, str]:
    """Each field of :class:`ExecutionMetrics` -> ``"context"`` or the component giving it;
    raises if a field has no owner or two."""
    owners: dict[str, list[str]] = {f: ["context"] for f in CONTEXT_FIELDS}
    for c in COMPONENTS:
        for f in c.module.OUTPUTS:
            owners.setdefault(f, []).append(c.field)
    declared = [f.name for f in dataclasses.fields(ExecutionMetrics)]
    twice = {f: o for f, o in owners.items() if len(o) > 1}
    if twice or set(owners) != set(declared):
        raise AssertionError(f"ExecutionMetrics fields {sorted(set(declared) - set(owners))} have "
                             f"no owner, {sorted(set(owners) - set(declared))} are not fields, "
                             f"{twice} have two")  # fmt: skip
    return {f: o[0] for f, o in owners.items()}


#: ExecutionMetrics field -> ``"context"`` or the :data:`COMPONENTS` field whose ``outputs``
#: gives it (checked when this module is imported).
FIELD_OWNERS = _field_owners()

#: The route-level table's columns read from the shared context's fields: column -> (route,
#: ExecutionMetrics field), as a component module's ``COLUMNS``.
CONTEXT_COLUMNS: dict[str, tuple[str, str]] = {
    "A_progress": ("A", "progress"),
    "B_progress": ("B", "progress"),
    "t_ref_s": ("A", "t_ref_s"),
    "t_event_s": ("A", "t_event_s"),
    "t_warn_off_s": ("A", "t_warn_off_s"),
    "t_clear_s": ("A", "t_clear_s"),
    "coincident_onset": ("A", "coincident_onset"),
    "t_first_failure_s": ("A", "t_first_failure_s"),
    "event_exposed": ("A", "event_exposed"),
}


def _route_columns() -> dict[str, tuple[str, str]]:
    """Every route-table column read from the per-execution metrics -> (route, field): the
    context's and each component's ``COLUMNS``; raises if a column has two owners or reads a
    field its owner does not give."""
    columns, owner = dict(CONTEXT_COLUMNS), dict.fromkeys(CONTEXT_COLUMNS, "context")
    for c in COMPONENTS:
        for name, (route, field) in c.module.COLUMNS.items():
            if name in columns:
                raise AssertionError(f"route-table column {name!r}: {owner[name]} and {c.field}")
            columns[name], owner[name] = (route, field), c.field
    for name, (route, field) in columns.items():
        if route not in ("A", "B") or FIELD_OWNERS.get(field) != owner[name]:
            raise AssertionError(f"route-table column {name!r} of {owner[name]} reads {route}."
                                 f"{field}, which {owner[name]} does not give")  # fmt: skip
    return columns


#: Route-table column -> (route ``"A"`` or ``"B"``, the ExecutionMetrics field it holds), from
#: the context and the component table (checked when this module is imported).
ROUTE_COLUMNS = _route_columns()


def first_failure_time(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> Array:
    """() float32, s: time stamp of the first Route A gate failure (``NEVER`` if none)."""
    times = []
    for name, gate in ROUTE_A_GATES.items():
        times += gate.failure_times(getattr(tel, name), tel.context, settings)
    return jnp.min(jnp.stack(times), axis=0)


def release_time(tel: Telemetry) -> Array:
    """() float32, s: ``max(t_warn_off, t_clear)`` once both happened, else ``NEVER``.

    Deprecated (nothing reads it; kept for one release): the recovery component computes it,
    :func:`lantern_jax.scoring.components.recovery.release_time`, and ``finalize`` gives it as
    ``ExecutionMetrics.t_release_s``."""
    warnings.warn("scoring.metrics.release_time is deprecated: read ExecutionMetrics.t_release_s "
                  "or call scoring.components.recovery.release_time",
                  DeprecationWarning, stacklevel=2)  # fmt: skip
    return recovery.release_time(tel.context.t_warn_off, tel.context.t_clear)


def availability(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> dict[str, Array]:
    """Valid-hazard-telemetry masks (see the module docstring) as () bool arrays.

    Deprecated (nothing reads it; kept for one release): ``finalize`` gives the same masks as
    ``ExecutionMetrics.<term>_available``."""
    warnings.warn("scoring.metrics.availability is deprecated: read the *_available fields of "
                  "finalize's ExecutionMetrics", DeprecationWarning, stacklevel=2)  # fmt: skip
    t_fail = first_failure_time(tel, settings)
    return {
        name: unit.valid(getattr(tel, name), tel.context, t_fail)
        for name, unit in HAZARD_COMPONENTS.items()
    }


def finalize(tel: Telemetry, settings: ScoringSettings = DEFAULT_SCORING) -> ExecutionMetrics:
    """Per-execution hard outputs from the final accumulators (jittable).

    Args:
        tel: final accumulators of one execution.
        settings: the scoring settings the accumulators were folded with.
    """
    ctx = tel.context
    t_fail = first_failure_time(tel, settings)
    completed = progress.is_completed(ctx.progress_m, ctx.route_length_m, settings)
    fields = {
        "is_route_a": ctx.is_route_a,
        "coincident_onset": ctx.coincident_onset,
        "progress": progress.hard(ctx, settings)[0],
        "progress_m": ctx.progress_m,
        "route_length_m": ctx.route_length_m,
        "completed": completed,
        "t_ref_s": time_or_nan(ctx.t_warn_point),
        "t_event_s": time_or_nan(ctx.t_event),
        "t_warn_off_s": time_or_nan(ctx.t_warn_off),
        "t_clear_s": time_or_nan(ctx.t_clear),
        "v_pre_mps": jnp.where(ctx.v_pre_set, ctx.v_pre, jnp.nan),
        "event_exposed": happened(ctx.t_event),
        "timed_out": ~completed,
        "t_first_failure_s": time_or_nan(t_fail),
        "metrics": user_metrics.values(settings.metrics, tel.metrics, ctx, settings),
    }
    for c in COMPONENTS:
        fields.update(c.module.outputs(getattr(tel, c.field), ctx, t_fail, settings))
    return ExecutionMetrics(**fields)
