"""Route B false-brake gate ``G_FB`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Hard gates", Route B).

**The matched stretch** is a stretch of route, not of time: the arc lengths of Route A's
warning-to-event approach, ``[s_warn, s_event]`` (Route A and its Route B share the route
exactly, so these are the same places on Route B).  With coincident warning and event points
(Right-Turn Yield) it is ``[s_warn - 10 m, s_conflict]``.  Route B never closes it early: no
forced event, no time limit.  The ego is in it while its route progress lies in it
(:func:`matched_window`, evaluated per tick in :func:`lantern_jax.scoring.measure.measure`).

**A false brake** is a stop (``speed <= 0.1 m/s``, not justified by a light, stop sign, lead
vehicle, obstacle, conflict or the route end; a warning is no justification — see
:func:`lantern_jax.scoring.measure.justified_stop`) of at least 20 consecutive ticks (1 s) that
touches the matched stretch; the whole stop counts, including the part before the ego crept
into the stretch (a stop that began before the stretch and lasts into it).  Any such stop fails
the gate.  Soft: ``sigmoid((19.5 ticks - longest such stop) * DT / T)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import DT
from lantern_jax.core.times import NEVER, happened
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.accumulate import first_time, run
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


def matched_window(
    s_warn: Array, s_event: Array, s_conflict: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """The matched stretch of route ``[lo, hi]`` (m of route arc).

    Args:
        s_warn: () float32, m, warning point.
        s_event: () float32, m, geometric event point.
        s_conflict: () float32, m, conflict point.
        settings: the coincident-onset lead (``false_brake_coincident_lead_m``).

    Returns:
        ``(lo, hi)``: ``(s_warn, s_event)``, or ``(s_warn - 10 m, s_conflict)`` when the event
        point does not lie beyond the warning point (coincident onset).
    """
    coincident = s_event <= s_warn
    lo = jnp.where(coincident, s_warn - settings.false_brake_coincident_lead_m, s_warn)
    hi = jnp.where(coincident, s_conflict, s_event)
    return lo, hi


@struct.dataclass
class FalseBrakeState:
    """Unjustified-stop record of one execution (scalars)."""

    run: Array  # () int32, consecutive unjustified stopped ticks (anywhere on the route)
    touched: Array  # () bool, the current such stop has been inside the matched stretch
    max_run: Array  # () int32, longest such stop that touched the matched stretch, ticks
    t_fail: Array  # () float32, s, tick at which such a stop reached 1 s (NEVER)


def init(settings: ScoringSettings) -> FalseBrakeState:
    """No stop yet. (no shape depends on ``settings``)"""
    del settings
    i0 = jnp.asarray(0, jnp.int32)
    return FalseBrakeState(
        run=i0, touched=jnp.asarray(False), max_run=i0, t_fail=jnp.asarray(NEVER, jnp.float32)
    )


def update(
    state: FalseBrakeState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> FalseBrakeState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``justified_stop``, ``fb_window``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    stopped = tick.speed <= settings.false_brake_speed_mps
    stop = stopped & ~jnp.asarray(sample.justified_stop, bool)
    n_run = run(state.run, stop)
    in_window = jnp.asarray(sample.fb_window, bool)
    touched = stop & (in_window | ((state.run > 0) & state.touched))
    counted = jnp.where(touched, n_run, 0)
    failed = counted >= settings.false_brake
    return FalseBrakeState(
        run=n_run,
        touched=touched,
        max_run=jnp.maximum(state.max_run, counted),
        t_fail=first_time(happened(state.t_fail), failed, tick.t, state.t_fail),
    )


def max_stop_s(state: FalseBrakeState) -> Array:
    """() float32, s: longest unjustified stop that touched the matched stretch."""
    return state.max_run.astype(jnp.float32) * DT


def hard(state: FalseBrakeState, ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, no unjustified stop of 1 s touching the matched stretch;
        () bool (always True).
    """
    return state.max_run < settings.false_brake, jnp.asarray(True)


def soft(
    state: FalseBrakeState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, s, of the sigmoid of the margin.

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    margin = (settings.false_brake - thresholds.COUNT_HALF - state.max_run.astype(jnp.float32)) * DT
    return soft_gate(margin, temperature), jnp.asarray(True)


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {"B_false_brake_stop_s": ("B", "false_brake_max_stop_s")}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_false_brake", "false_brake_max_stop_s")


def outputs(state: FalseBrakeState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {
        "gate_false_brake": hard(state, ctx, settings)[0],
        "false_brake_max_stop_s": max_stop_s(state),
    }
