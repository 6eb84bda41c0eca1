"""Clearance component ``S_clear`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Clearance")::

    S_clear = clip(d_min / d_safe)        d_safe = 2 m (PE, OR), 3 m otherwise

``d_min`` is the minimum ego-hazard box-surface distance over ``[t_event, t_clear]`` while the
hazard is present; a collision tick inside the window is a sample of 0 ("collision sets
d_min = 0").  The soft state is an unweighted log-sum-exp soft minimum of the same samples.

Available (valid) when ``t_event`` happened no later than the first Route A gate failure and the
window held at least one sample (hazard present or a collision).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import BIG
from lantern_jax.scoring.components.context import Context, Tick, opened_by, value_or_nan
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import LSE_EMPTY, lse_add, smooth_clip01, softmin_decode
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class ClearanceState:
    """Accumulators of the clearance window (scalars)."""

    min_m: Array  # () float32, m, hard minimum box distance (BIG before any sample)
    any_sample: Array  # () bool, at least one sample (hazard present or collision)
    lse: Array  # () float32, soft-min accumulator log sum exp(-d / T)


def init(settings: ScoringSettings) -> ClearanceState:
    """No sample yet. (no shape depends on ``settings``)"""
    del settings
    return ClearanceState(
        min_m=jnp.asarray(BIG, jnp.float32),
        any_sample=jnp.asarray(False),
        lse=jnp.asarray(LSE_EMPTY, jnp.float32),
    )


def update(
    state: ClearanceState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> ClearanceState:
    """Fold one tick.

    Args:
        state: accumulators before the tick.
        sample: the tick's measurement (unused: the distances come with ``tick``).
        tick: shared per-tick context.
        settings: thresholds; temperature: () float32, m, of the soft minimum.

    Returns:
        The accumulators after the tick.
    """
    temperature = settings.temperature
    in_window = tick.post_event & tick.before_clear
    sampled = in_window & (tick.present | tick.collision)
    d = jnp.where(tick.collision, 0.0, tick.hazard_dist)
    return ClearanceState(
        min_m=jnp.where(sampled, jnp.minimum(state.min_m, d), state.min_m),
        any_sample=state.any_sample | sampled,
        lse=jnp.where(sampled, lse_add(state.lse, d, temperature), state.lse),
    )


def valid(state: ClearanceState, ctx: Context, t_fail: Array) -> Array:
    """() bool: the window opened (``t_event``) no later than ``t_fail`` and held a sample.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
    """
    return opened_by(ctx.t_event, t_fail) & state.any_sample


def hard(state: ClearanceState, ctx: Context, t_fail: Array) -> tuple[Array, Array]:
    """Hard minimum clearance.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).

    Returns:
        ``(d_min, valid)``: () float32, m; () bool.
    """
    return state.min_m, valid(state, ctx, t_fail)


def score(clearance_min_m: Any, d_safe: Any) -> Array:
    """``S_clear = clip(d_min / d_safe)``, elementwise.

    Args:
        clearance_min_m: (...) float32, m; ``NaN`` = unavailable.
        d_safe: (...) float32, m, the family's normaliser.

    Returns:
        (...) float32 in [0, 1]; ``NaN`` where unavailable.
    """
    x = jnp.asarray(clearance_min_m, jnp.float32)
    d_safe = jnp.asarray(d_safe, jnp.float32)
    return jnp.where(jnp.isnan(x), jnp.nan, jnp.clip(x / d_safe, 0.0, 1.0))


def soft(
    state: ClearanceState, ctx: Context, t_fail: Array, temperature: Array,
    settings: ScoringSettings, d_safe: Array,
) -> tuple[Array, Array]:  # fmt: skip
    """Smooth ``S_clear``: the soft minimum, decoded with the accumulator temperature
    ``ctx.temperature`` and capped at ``d_safe``, through a smooth clip.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
        temperature: () float32, temperature of the smooth clip.
        settings: unused (one signature per role).
        d_safe: () float32, m, the scene's clearance normaliser.

    Returns:
        ``(s_clear, valid)``: () float32 in [0, 1]; () bool (the hard availability).
    """
    d_min = softmin_decode(state.lse, ctx.temperature, cap=d_safe)
    return smooth_clip01(d_min / d_safe, temperature), valid(state, ctx, t_fail)


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {"clearance_min_m": ("A", "clearance_min_m")}

#: The name of its score among the pair components and in the route-level table.
SCORE = "S_clear"


def score_of(metrics: Any, d_safe: Any, settings: ScoringSettings) -> Array:
    """``S_clear`` of Route A executions, elementwise:
    :func:`score` of their metrics' ``clearance_min_m`` over ``d_safe``
    (the hazard role's ``score_of``,
    :mod:`lantern_jax.scoring.components`)."""
    return score(metrics.clearance_min_m, d_safe)


#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("clearance_min_m", "clearance_available")


def outputs(state: ClearanceState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    clearance_min_m, ok = hard(state, ctx, t_fail)
    return {"clearance_min_m": value_or_nan(clearance_min_m, ok), "clearance_available": ok}
