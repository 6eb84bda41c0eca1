"""Progress component ``P`` (paper appendix "Complete Cooperative Unified Score", paragraph
"Scoring unit": ``P = RC / 100`` with ``RC`` the route completion)::

    P = clip(progress / (route_length - 2 m))

Reaching the route's end zone (``route_length - 2 m``) counts as complete (the leaderboard's
> 99 % rule).  Stateless: it reads the furthest route arc and the route length that the shared
:class:`~lantern_jax.scoring.components.context.Context` keeps from the latest tick.  Always
valid.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.scoring.components.context import Context
from lantern_jax.scoring.smooth import smooth_clip01
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


def is_completed(progress_m: Array, route_length_m: Array, settings: ScoringSettings) -> Array:
    """Whether the ego reached the route's end zone.

    Args:
        progress_m: (...) float32, m, furthest route arc reached.
        route_length_m: (...) float32, m.
        settings: the end zone (``completion_tol_m``).

    Returns:
        (...) bool: ``progress_m >= route_length_m - 2 m``.
    """
    return reached_end_zone(progress_m, route_length_m, settings.completion_tol_m)


def reached_end_zone(progress_m: Array, route_length_m: Array, end_zone_m: Array) -> Array:
    """:func:`is_completed` with the end zone given as a value rather than read from the
    settings (for a term judged where the settings are not at hand: the recovery's windows cut
    short by the route's end, :func:`lantern_jax.scoring.components.recovery.cut_windows`).

    Args:
        progress_m: (...) float32, m, furthest route arc reached.
        route_length_m: (...) float32, m.
        end_zone_m: (...) float32, m, the end zone's length (``completion_tol_m``).

    Returns:
        (...) bool: ``progress_m >= route_length_m - end_zone_m``.
    """
    return progress_m >= route_length_m - end_zone_m


def hard(ctx: Context, settings: ScoringSettings) -> tuple[Array, Array]:
    """Hard route completion.

    Args:
        ctx: final shared context (progress and route length).

    Returns:
        ``(p, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    span = settings.completion_length(ctx.route_length_m)
    frac = jnp.where(span > 0, ctx.progress_m / jnp.where(span > 0, span, 1.0), 0.0)
    return jnp.clip(frac, 0.0, 1.0), jnp.asarray(True)


def soft(ctx: Context, temperature: Array, settings: ScoringSettings) -> tuple[Array, Array]:
    """Smooth route completion: the ratio through a smooth clip.

    Args:
        ctx: final shared context (progress and route length).
        temperature: () float32, temperature of the smooth clip.

    Returns:
        ``(p, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    span = settings.completion_length(ctx.route_length_m)
    safe_len = jnp.where(span > 0, span, 1.0)
    p = jnp.where(span > 0, smooth_clip01(ctx.progress_m / safe_len, temperature), 0.0)
    return p, jnp.asarray(True)
