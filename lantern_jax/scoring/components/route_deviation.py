"""Route-deviation gate ``G_road`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Hard gates": severe route departure).

Hard: fails on any tick with ``dist_to_route >= 30 m``; the failure time is the first such tick.
Soft: ``sigmoid((30 m - max dist_to_route) / T)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import NEVER, happened
from lantern_jax.scoring.components.accumulate import first_time
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class RouteDeviationState:
    """Route-distance record of one execution (scalars)."""

    max_dist: Array  # () float32, m, largest distance of the ego centre from the route
    t_deviation: Array  # () float32, s, first tick with dist_to_route >= 30 m (NEVER)


def init(settings: ScoringSettings) -> RouteDeviationState:
    """On the route. (no shape depends on ``settings``)"""
    del settings
    return RouteDeviationState(
        max_dist=jnp.asarray(0.0, jnp.float32), t_deviation=jnp.asarray(NEVER, jnp.float32)
    )


def update(
    state: RouteDeviationState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> RouteDeviationState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``dist_to_route``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    dist = jnp.asarray(sample.dist_to_route, jnp.float32)
    deviated = dist >= settings.route_deviation_m
    return RouteDeviationState(
        max_dist=jnp.maximum(state.max_dist, dist),
        t_deviation=first_time(happened(state.t_deviation), deviated, tick.t, state.t_deviation),
    )


def failure_times(
    state: RouteDeviationState, ctx: Context, settings: ScoringSettings
) -> tuple[Array, ...]:
    """Failure time(s) for the first Route A gate failure.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(t_deviation,)``: () float32, s (``NEVER`` = no deviation).
    """
    return (state.t_deviation,)


def hard(
    state: RouteDeviationState, ctx: Context, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, distance to the route always < 30 m; () bool (always True).
    """
    return ~happened(state.t_deviation), jnp.asarray(True)


def soft(
    state: RouteDeviationState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, m, of the sigmoid of the margin.

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    return soft_gate(settings.route_deviation_m - state.max_dist, temperature), jnp.asarray(True)


#: Its columns of the route-level table besides its gate's pass flag (none; see
#: :data:`lantern_jax.core.constants.GATE_COLUMNS`): column -> (route, field).
COLUMNS: dict[str, tuple[str, str]] = {}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_route_deviation", "max_route_dist_m")


def outputs(state: RouteDeviationState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {
        "gate_route_deviation": hard(state, ctx, settings)[0],
        "max_route_dist_m": state.max_dist,
    }
