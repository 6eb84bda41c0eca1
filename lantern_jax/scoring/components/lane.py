"""Lane gate ``G_lane`` (paper appendix "Complete Cooperative Unified Score", paragraph "Hard
gates": the ``outside_route_lanes`` infraction).

Hard: fails when the total time outside the driving lanes reaches 1 s (20 ticks) -- a debounce
over the whole execution, not necessarily contiguous; the failure time is the tick at which the
total reached 1 s.  Soft: ``sigmoid((19.5 ticks - ticks outside) * DT / T)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import DT
from lantern_jax.core.times import NEVER, happened
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.accumulate import count, first_time
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class LaneState:
    """Lane record of one execution (scalars)."""

    n_outside: Array  # () int32, ticks outside the driving lanes (total)
    t_fail: Array  # () float32, s, tick at which the total reached 1 s (NEVER)


def init(settings: ScoringSettings) -> LaneState:
    """Inside the lanes. (no shape depends on ``settings``)"""
    del settings
    return LaneState(n_outside=jnp.asarray(0, jnp.int32), t_fail=jnp.asarray(NEVER, jnp.float32))


def update(
    state: LaneState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> LaneState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``outside_lanes``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    n_outside = count(state.n_outside, jnp.asarray(sample.outside_lanes, bool))
    failed = n_outside >= settings.lane_debounce
    return LaneState(
        n_outside=n_outside,
        t_fail=first_time(happened(state.t_fail), failed, tick.t, state.t_fail),
    )


def outside_s(state: LaneState) -> Array:
    """() float32, s: total time outside the driving lanes."""
    return state.n_outside.astype(jnp.float32) * DT


def failure_times(state: LaneState, ctx: Context, settings: ScoringSettings) -> tuple[Array, ...]:
    """Failure time(s) for the first Route A gate failure.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(t_fail,)``: () float32, s (``NEVER`` = the gate passed).
    """
    return (state.t_fail,)


def hard(state: LaneState, ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, < 1 s in total outside the lanes; () bool (always True).
    """
    return state.n_outside < settings.lane_debounce, jnp.asarray(True)


def soft(
    state: LaneState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, s, of the sigmoid of the margin.

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    margin = (
        settings.lane_debounce - thresholds.COUNT_HALF - state.n_outside.astype(jnp.float32)
    ) * DT
    return soft_gate(margin, temperature), jnp.asarray(True)


#: Its columns of the route-level table besides its gate's pass flag (none; see
#: :data:`lantern_jax.core.constants.GATE_COLUMNS`): column -> (route, field).
COLUMNS: dict[str, tuple[str, str]] = {}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_lane", "outside_lanes_s")


def outputs(state: LaneState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {"gate_lane": hard(state, ctx, settings)[0], "outside_lanes_s": outside_s(state)}
