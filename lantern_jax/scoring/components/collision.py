"""Collision gate ``G_coll`` (paper appendix "Complete Cooperative Unified Score", paragraph
"Hard gates": the gates fail upon any collision).

Hard: fails on any tick with ``sample.collision`` (an overlap with any present actor at ego speed
>= 0.1 m/s).  Soft: ``(1 - collided) * sigmoid(margin / T)`` with the signed margin
``min over hazard ticks of max(box distance, 0.1 m/s - speed)`` (closest approach to the
controlled hazard; a slow touch is no collision).  The failure time is the first collision tick.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import BIG
from lantern_jax.core.times import NEVER
from lantern_jax.scoring.components.accumulate import first_time
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class CollisionState:
    """Collision record of one execution (scalars)."""

    collided: Array  # () bool, a collision on some tick
    t_collision: Array  # () float32, s, first collision (NEVER)
    margin: Array  # () float32, m (mixed with m/s), min over hazard ticks of
    #                max(box dist, 0.1 - speed); BIG before any hazard tick


def init(settings: ScoringSettings) -> CollisionState:
    """No collision yet. (no shape depends on ``settings``)"""
    del settings
    return CollisionState(
        collided=jnp.asarray(False),
        t_collision=jnp.asarray(NEVER, jnp.float32),
        margin=jnp.asarray(BIG, jnp.float32),
    )


def update(
    state: CollisionState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> CollisionState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (unused: collision, hazard distance and speed come
            with ``tick``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    slow_touch = settings.collision_min_speed_mps - tick.speed
    margin = jnp.where(tick.present, jnp.maximum(tick.hazard_dist, slow_touch), BIG)
    return CollisionState(
        collided=state.collided | tick.collision,
        t_collision=first_time(state.collided, tick.collision, tick.t, state.t_collision),
        margin=jnp.minimum(state.margin, margin),
    )


def failure_times(
    state: CollisionState, ctx: Context, settings: ScoringSettings
) -> tuple[Array, ...]:
    """Failure time(s) for the first Route A gate failure.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(t_collision,)``: () float32, s (``NEVER`` = no collision).
    """
    return (state.t_collision,)


def hard(state: CollisionState, ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, no collision; () bool (always True).
    """
    return ~state.collided, jnp.asarray(True)


def soft(
    state: CollisionState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, m, of the sigmoid of the margin.

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    no_collision = 1.0 - state.collided.astype(jnp.float32)
    return no_collision * soft_gate(state.margin, temperature), jnp.asarray(True)


#: Its columns of the route-level table besides its gate's pass flag (none; see
#: :data:`lantern_jax.core.constants.GATE_COLUMNS`): column -> (route, field).
COLUMNS: dict[str, tuple[str, str]] = {}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_collision",)


def outputs(state: CollisionState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {"gate_collision": hard(state, ctx, settings)[0]}
