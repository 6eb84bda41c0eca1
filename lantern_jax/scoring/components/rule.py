"""Rule gate ``G_rule`` (paper appendix "Complete Cooperative Unified Score", paragraph "Hard
gates": traffic-rule violation).

Fails on any red-light violation; the failure time is the first one.  The soft gate equals the
hard one (a violation is an event, with no margin to relax).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import NEVER
from lantern_jax.scoring.components.accumulate import first_time
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class RuleState:
    """Rule record of one execution (scalars)."""

    red_light: Array  # () bool, a red-light violation on some tick
    t_violation: Array  # () float32, s, first red-light violation (NEVER)


def init(settings: ScoringSettings) -> RuleState:
    """No violation yet. (no shape depends on ``settings``)"""
    del settings
    return RuleState(red_light=jnp.asarray(False), t_violation=jnp.asarray(NEVER, jnp.float32))


def update(
    state: RuleState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> RuleState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``red_light_violation``).
        tick: shared per-tick context.
        settings: thresholds; temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    red = jnp.asarray(sample.red_light_violation, bool)
    return RuleState(
        red_light=state.red_light | red,
        t_violation=first_time(state.red_light, red, tick.t, state.t_violation),
    )


def failure_times(state: RuleState, ctx: Context, settings: ScoringSettings) -> tuple[Array, ...]:
    """Failure time(s) for the first Route A gate failure.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(t_violation,)``: () float32, s (``NEVER`` = no violation).
    """
    return (state.t_violation,)


def hard(state: RuleState, ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, no red-light violation; () bool (always True).
    """
    return ~state.red_light, jnp.asarray(True)


def soft(
    state: RuleState, ctx: Context, temperature: Array, settings: ScoringSettings
) -> tuple[Array, Array]:
    """The gate as a float (not relaxed).

    Args:
        state: final record.
        ctx: final shared context.
        temperature: unused.

    Returns:
        ``(passed, valid)``: () float32 in {0, 1}; () bool (always True).
    """
    return 1.0 - state.red_light.astype(jnp.float32), jnp.asarray(True)


#: Its columns of the route-level table besides its gate's pass flag (none; see
#: :data:`lantern_jax.core.constants.GATE_COLUMNS`): column -> (route, field).
COLUMNS: dict[str, tuple[str, str]] = {}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("gate_rule",)


def outputs(state: RuleState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {"gate_rule": hard(state, ctx, settings)[0]}
