"""Block gate ``G_block`` (paper appendix "Complete Cooperative Unified Score", paragraph "Hard
gates": blocking or timeout; "blocking or timeout also fails a hard gate" under "Recovery").

Fails on any of:

* a standstill (``speed < 0.1 m/s``, counted only while the route is unfinished) lasting 400
  consecutive ticks (20 s) -- failure time: the tick at which it reached 20 s;
* an unfinished route at the end (``progress < route_length - 2 m``: timeout) -- failure time:
  the last folded tick;
* a controller fault (NaN/inf waypoints, or a plan over ``MAX_PLAN_SPEED``) on any tick --
  failure time: the first fault.

Soft: ``sigmoid((399.5 ticks - longest standstill) * DT / T) * sigmoid((progress - (length -
2 m)) / T) * (1 - fault)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import DT
from lantern_jax.core.times import NEVER, happened, time_or_nan
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.accumulate import first_time, run
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.components.progress import is_completed
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class BlockState:
    """Standstill and controller-fault record of one execution (scalars)."""

    still_run: Array  # () int32, consecutive ticks below 0.1 m/s with the route unfinished
    max_still_run: Array  # () int32, longest such run
    t_stall: Array  # () float32, s, tick at which a standstill reached 20 s (NEVER)
    fault: Array  # () bool, controller fault on some tick
    t_fault: Array  # () float32, s, first controller fault (NEVER)


def init(settings: ScoringSettings) -> BlockState:
    """Moving, no fault. (no shape depends on ``settings``)"""
    del settings
    i0, never = jnp.asarray(0, jnp.int32), jnp.asarray(NEVER, jnp.float32)
    return BlockState(
        still_run=i0, max_still_run=i0, t_stall=never, fault=jnp.asarray(False), t_fault=never
    )


def update(
    state: BlockState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> BlockState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``controller_fault``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    unfinished = ~is_completed(tick.progress, tick.route_length, settings)
    still_run = run(state.still_run, (tick.speed < settings.still_speed_mps) & unfinished)
    stall_now = still_run >= settings.block_still
    fault = jnp.asarray(sample.controller_fault, bool)
    return BlockState(
        still_run=still_run,
        max_still_run=jnp.maximum(state.max_still_run, still_run),
        t_stall=first_time(happened(state.t_stall), stall_now, tick.t, state.t_stall),
        fault=state.fault | fault,
        t_fault=first_time(state.fault, fault, tick.t, state.t_fault),
    )


def stalled(state: BlockState, settings: ScoringSettings) -> Array:
    """() bool: a standstill of >= 20 s with the route unfinished."""
    return state.max_still_run >= settings.block_still


def max_still_s(state: BlockState) -> Array:
    """() float32, s: longest standstill with the route unfinished."""
    return state.max_still_run.astype(jnp.float32) * DT


def failure_times(state: BlockState, ctx: Context, settings: ScoringSettings) -> tuple[Array, ...]:
    """Failure time(s) for the first Route A gate failure.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(t_stall, t_fault, t_timeout)``: () float32, s each (``NEVER`` = that cause
        did not fail); the timeout fails at the last folded tick.
    """
    completed = is_completed(ctx.progress_m, ctx.route_length_m, settings)
    return state.t_stall, state.t_fault, jnp.where(completed, NEVER, ctx.t_last)


def hard(state: BlockState, ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, no 20 s standstill, route completed, no controller
        fault; () bool (always True).
    """
    completed = is_completed(ctx.progress_m, ctx.route_length_m, settings)
    return ~stalled(state, settings) & completed & ~state.fault, jnp.asarray(True)


def soft(
    state: BlockState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, s (standstill margin) and m (completion margin).

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    max_still = state.max_still_run.astype(jnp.float32)
    still_margin = (settings.block_still - thresholds.COUNT_HALF - max_still) * DT
    completion_margin = ctx.progress_m - (ctx.route_length_m - settings.completion_tol_m)
    no_fault = 1.0 - state.fault.astype(jnp.float32)
    value = soft_gate(still_margin, temperature) * soft_gate(completion_margin, temperature)
    return value * no_fault, jnp.asarray(True)


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {
    "controller_fault": ("A", "controller_fault"),
    "t_fault_s": ("A", "t_fault_s"),
    "B_controller_fault": ("B", "controller_fault"),
    "B_t_fault_s": ("B", "t_fault_s"),
}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_block", "controller_fault", "t_fault_s", "stalled", "max_still_s")


def outputs(state: BlockState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {
        "gate_block": hard(state, ctx, settings)[0],
        "controller_fault": state.fault,
        "t_fault_s": time_or_nan(state.t_fault),
        "stalled": stalled(state, settings),
        "max_still_s": max_still_s(state),
    }
