"""Time-to-collision component ``S_TTC`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Time-to-collision")::

    v_close = -r . (v_hazard - v_ego) / |r|        TTC = d_box / v_close
    S_TTC = clip(TTC_min / 3 s)                     no closing trend -> 1, overlap -> 0

Only the controlled hazard counts, over ``[t_ref, t_clear]``.  A tick of that window with the
hazard present is a sample if the boxes overlap (TTC 0) or ``v_close > 0.05 m/s``; the hard state
is a running minimum plus an "any sample" flag.  The soft state is a weighted log-sum-exp soft
minimum in which every window tick counts with weight ``sigmoid((v_close - 0.05) / T)`` (1 for an
overlap) instead of the hard inclusion test.

Available (valid) when ``t_ref`` happened no later than the first Route A gate failure.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import BIG
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.context import Context, Tick, opened_by, value_or_nan
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import LSE_EMPTY, lse_add, smooth_clip01, softmin_decode
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class TTCState:
    """Accumulators of the TTC window (scalars)."""

    min_s: Array  # () float32, s, hard minimum TTC (BIG before any sample)
    any_sample: Array  # () bool, at least one TTC sample (closing or overlapping)
    lse: Array  # () float32, soft-min accumulator log sum w exp(-TTC / T)


def init(settings: ScoringSettings) -> TTCState:
    """No sample yet. (no shape depends on ``settings``)"""
    del settings
    return TTCState(
        min_s=jnp.asarray(BIG, jnp.float32),
        any_sample=jnp.asarray(False),
        lse=jnp.asarray(LSE_EMPTY, jnp.float32),
    )


def closing_speed(rel: Array, rel_vel: Array) -> Array:
    """() float32, m/s: ``-r . v_rel / |r|`` (0 when the centres coincide).

    Args:
        rel: (2,) float32, m, hazard centre minus ego centre.
        rel_vel: (2,) float32, m/s, hazard velocity minus ego velocity.
    """
    rr = jnp.sum(rel * rel)
    r_ok = rr > thresholds.COINCIDENT_SQ_M2
    r_norm = jnp.sqrt(jnp.where(r_ok, rr, 1.0))
    return jnp.where(r_ok, -jnp.sum(rel * rel_vel) / r_norm, 0.0)


def update(state: TTCState, sample: TickSample, tick: Tick, settings: ScoringSettings) -> TTCState:
    """Fold one tick.

    Args:
        state: accumulators before the tick.
        sample: the tick's measurement (``hazard_rel``, ``hazard_rel_vel``).
        tick: shared per-tick context.
        settings: thresholds; temperature in s (soft minimum) and m/s (sample weights).

    Returns:
        The accumulators after the tick.
    """
    f32 = jnp.float32
    temperature = settings.temperature
    v_close = closing_speed(
        jnp.asarray(sample.hazard_rel, f32), jnp.asarray(sample.hazard_rel_vel, f32)
    )
    d_box = tick.hazard_dist
    overlap = d_box <= 0.0
    closing = v_close > settings.closing_min_mps
    in_window = tick.post_ref & tick.before_clear & tick.present
    ttc = jnp.where(overlap, 0.0, d_box / jnp.where(closing, v_close, 1.0))
    sampled = in_window & (overlap | closing)
    ttc_soft = jnp.where(overlap, 0.0, d_box / jnp.maximum(v_close, settings.closing_min_mps))
    log_w = jnp.where(
        overlap, 0.0, jax.nn.log_sigmoid((v_close - settings.closing_min_mps) / temperature)
    )
    return TTCState(
        min_s=jnp.where(sampled, jnp.minimum(state.min_s, ttc), state.min_s),
        any_sample=state.any_sample | sampled,
        lse=jnp.where(in_window, lse_add(state.lse, ttc_soft, temperature, log_w), state.lse),
    )


def valid(state: TTCState, ctx: Context, t_fail: Array) -> Array:
    """() bool: the TTC window opened (``t_ref``) no later than ``t_fail``.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
    """
    return opened_by(ctx.t_warn_point, t_fail)


def hard(state: TTCState, ctx: Context, t_fail: Array) -> tuple[Array, Array]:
    """Hard minimum TTC.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).

    Returns:
        ``(ttc_min, valid)``: () float32, s (``inf`` = no closing trend); () bool.
    """
    return jnp.where(state.any_sample, state.min_s, jnp.inf), valid(state, ctx, t_fail)


def score(ttc_min_s: Any, settings: ScoringSettings) -> Array:
    """``S_TTC = clip(TTC_min / 3 s)``, elementwise.

    Args:
        ttc_min_s: (...) float32, s; ``inf`` = no closing trend (scores 1), ``NaN`` = unavailable.
        settings: the normalisation (``ttc_norm_s``).

    Returns:
        (...) float32 in [0, 1]; ``NaN`` where unavailable.
    """
    x = jnp.asarray(ttc_min_s, jnp.float32)
    return jnp.where(jnp.isnan(x), jnp.nan, jnp.clip(x / settings.ttc_norm_s, 0.0, 1.0))


def soft(
    state: TTCState, ctx: Context, t_fail: Array, temperature: Array, settings: ScoringSettings,
    d_safe: Any = None,
) -> tuple[Array, Array]:  # fmt: skip
    """Smooth ``S_TTC``: the soft minimum, decoded with the accumulator temperature
    ``ctx.temperature`` and capped at 3 s, through a smooth clip.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
        temperature: () float32, temperature of the smooth clip.
        settings: the normalisation (``ttc_norm_s``).
        d_safe: () float32, m, the scene's clearance normaliser (read by clearance only; every
            hazard term takes it: one signature per role).

    Returns:
        ``(s_ttc, valid)``: () float32 in [0, 1]; () bool (the hard availability).
    """
    ttc = softmin_decode(state.lse, ctx.temperature, cap=settings.ttc_norm_s)
    return smooth_clip01(ttc / settings.ttc_norm_s, temperature), valid(state, ctx, t_fail)


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {"ttc_min_s": ("A", "ttc_min_s")}

#: The name of its score among the pair components and in the route-level table.
SCORE = "S_ttc"


def score_of(metrics: Any, d_safe: Any, settings: ScoringSettings) -> Array:
    """``S_ttc`` of Route A executions, elementwise:
    :func:`score` of their metrics' ``ttc_min_s`` (the hazard role's ``score_of``,
    :mod:`lantern_jax.scoring.components`)."""
    return score(metrics.ttc_min_s, settings)


#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("ttc_min_s", "ttc_available")


def outputs(state: TTCState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    ttc_min_s, ok = hard(state, ctx, t_fail)
    return {"ttc_min_s": value_or_nan(ttc_min_s, ok), "ttc_available": ok}
