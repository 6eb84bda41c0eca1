"""Anticipation component ``S_ant`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Anticipation")::

    S_ant = clip((t_event - t_react) / (t_event - t_ref))
            no response, or a response at/after the event -> 0
            coincident warning/event onset (Right-Turn Yield): 1 iff a response was already
            present at the event, else 0

Sustained response (hard): every tick at/after ``t_ref`` gets a flag
``accel <= -0.5 m/s^2 or speed <= v_pre - 1 m/s``; ``t_react`` is the start of the first 10-tick
(0.5 s) window, all of whose ticks lie at/after ``t_ref``, with >= 8 flags set (any time, also
after the event; the score clips it).

Coincident onset (no pre-warning interval): at the first tick with ``t >= t_event`` the last 10
ticks (ending at that tick, regardless of ``t_ref``) are examined with flags
``accel <= -0.5 or speed <= v_start - 1``, ``v_start`` the speed on the window's first tick;
``response_at_event`` records whether >= 8 are set (False with fewer than 10 ticks so far) and
``t_response_start`` the window's start.  This check runs on every execution; it is used where
``coincident_onset`` is set.

Soft (a soft first crossing): soft flags
``1 - (1 - sigmoid((-0.5 - a) / T)) (1 - sigmoid((v_pre - 1 - v) / T))``; each complete window
``k`` passes with probability ``sigma_k = sigmoid((sum of soft flags - 7.5) / T)``, and
``p_k = sigma_k prod_{j<k} (1 - sigma_j)`` is the probability that it is the first passing one.
The state holds ``sum p_k`` and ``sum p_k t_k``; the score uses the expected ``t_react`` given a
response, times the probability of a response.

Available (valid) when ``t_ref`` happened no later than the first Route A gate failure and
``t_event`` happened.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import NEVER, happened, time_or_nan
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.accumulate import count, expected_time, first_time, push
from lantern_jax.scoring.components.context import (
    Context,
    Tick,
    opened_by,
    ring_length,
    value_or_nan,
)
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import smooth_clip01
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class AnticipationState:
    """Accumulators of the response criteria (scalars unless a shape is given)."""

    n_post_ref: Array  # () int32, ticks with t >= t_ref
    flags: Array  # (W,) bool, response flags of the last ticks (False before t_ref); W the
    #               reaction window in ticks (ScoringSettings.react_window)
    t_react: Array  # () float32, s, start of the first sustained-response window (NEVER)
    event_checked: Array  # () bool, the window ending at the event tick was examined
    response_at_event: Array  # () bool, that window met the criterion
    t_response_start: Array  # () float32, s, start of that window (NEVER if not met)
    soft_flags: Array  # (W,) float32, soft response flags of the last ticks, in [0, 1]
    surv: Array  # () float32, soft probability that no window has passed yet
    p: Array  # () float32, soft probability that some window passed, sum_k p_k
    pt: Array  # () float32, s, sum_k p_k t_k
    soft_response_at_event: Array  # () float32, soft response_at_event, in [0, 1]


def init(settings: ScoringSettings) -> AnticipationState:
    """No tick yet."""
    f = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    W = settings.react_window  # noqa: N806
    return AnticipationState(
        n_post_ref=jnp.asarray(0, jnp.int32), flags=jnp.zeros(W, bool), t_react=f(NEVER),
        event_checked=jnp.asarray(False), response_at_event=jnp.asarray(False),
        t_response_start=f(NEVER), soft_flags=jnp.zeros(W, jnp.float32),
        surv=f(1.0), p=f(0.0), pt=f(0.0), soft_response_at_event=f(0.0),
    )  # fmt: skip


def _soft_flag(accel: Array, speed: Array, v_ref: Array, settings: ScoringSettings) -> Array:
    """Soft response flag ``accel <= -0.5 m/s^2 or speed <= v_ref - 1 m/s``.

    Args:
        accel: (...) float32, m/s^2.
        speed: (...) float32, m/s.
        v_ref: () float32, m/s, reference speed.
        settings: thresholds and temperature.

    Returns:
        (...) float32 in [0, 1].
    """
    temp = settings.temperature
    return 1.0 - (1.0 - jax.nn.sigmoid((settings.react_accel_mps2 - accel) / temp)) * (
        1.0 - jax.nn.sigmoid((v_ref - settings.react_speed_drop_mps - speed) / temp)
    )


def _window_pass(full: Array, soft_flags: Array, settings: ScoringSettings) -> Array:
    """Soft ``at least react_min_count flags set`` of one window.

    Args:
        full: () bool, the window is complete.
        soft_flags: (W,) float32, soft flags of the window.
        settings: thresholds and temperature (in flags).

    Returns:
        () float32 in [0, 1]; 0 for an incomplete window.
    """
    margin = jnp.sum(soft_flags) - (settings.react_min_count - thresholds.COUNT_HALF)
    return jnp.where(full, jax.nn.sigmoid(margin / settings.temperature), 0.0)


def _sustained(state: AnticipationState, tick: Tick, settings: ScoringSettings) -> dict[str, Array]:
    """First sustained response at/after ``t_ref`` (hard and soft first crossing)."""
    W = settings.react_window  # noqa: N806
    accel, speed, post_ref = tick.accel, tick.speed, tick.post_ref
    flag = post_ref & (
        (accel <= settings.react_accel_mps2) | (speed <= tick.v_pre - settings.react_speed_drop_mps)
    )
    flags = push(state.flags, flag)
    n_post_ref = count(state.n_post_ref, post_ref)
    full = n_post_ref >= W
    window_start = tick.time_ring[ring_length(settings) - W]
    ok = full & (jnp.sum(flags) >= settings.react_min_count)
    soft_flag = jnp.where(post_ref, _soft_flag(accel, speed, tick.v_pre, settings), 0.0)
    soft_flags = push(state.soft_flags, soft_flag)
    sigma = _window_pass(full, soft_flags, settings)
    p_k = state.surv * sigma
    return dict(
        n_post_ref=n_post_ref,
        flags=flags,
        t_react=first_time(happened(state.t_react), ok, window_start, state.t_react),
        soft_flags=soft_flags,
        surv=state.surv * (1.0 - sigma),
        p=state.p + p_k,
        pt=state.pt + p_k * window_start,
    )


def _at_event(state: AnticipationState, tick: Tick, settings: ScoringSettings) -> dict[str, Array]:
    """Response already present in the window ending at the first tick with ``t >= t_event``."""
    W = settings.react_window  # noqa: N806
    now = tick.post_event & ~state.event_checked
    full = tick.n_ticks >= W
    v_start = tick.speed_ring[0]
    flags = (tick.accel_ring <= settings.react_accel_mps2) | (
        tick.speed_ring <= v_start - settings.react_speed_drop_mps
    )
    present = full & (jnp.sum(flags) >= settings.react_min_count)
    soft_present = _window_pass(
        full, _soft_flag(tick.accel_ring, tick.speed_ring, v_start, settings), settings
    )
    start = tick.time_ring[ring_length(settings) - W]
    return dict(
        event_checked=state.event_checked | tick.post_event,
        response_at_event=jnp.where(now, present, state.response_at_event),
        t_response_start=jnp.where(now & present, start, state.t_response_start),
        soft_response_at_event=jnp.where(now, soft_present, state.soft_response_at_event),
    )


def update(
    state: AnticipationState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> AnticipationState:
    """Fold one tick.

    Args:
        state: accumulators before the tick.
        sample: the tick's measurement (unused: speed and acceleration come with ``tick``).
        tick: shared per-tick context.
        settings: thresholds; temperature in m/s^2 and m/s (soft flags), flags (window tests).

    Returns:
        The accumulators after the tick.
    """
    return AnticipationState(
        **_sustained(state, tick, settings), **_at_event(state, tick, settings)
    )


def valid(state: AnticipationState, ctx: Context, t_fail: Array) -> Array:
    """() bool: ``t_ref`` happened no later than ``t_fail`` and ``t_event`` happened.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
    """
    return opened_by(ctx.t_warn_point, t_fail) & happened(ctx.t_event)


def hard(state: AnticipationState, ctx: Context, t_fail: Array) -> tuple[Array, Array]:
    """Hard reaction time.

    With coincident onset, ``t_react`` is the start of the window ending at the event tick when
    that window met the criterion, otherwise the first sustained response at/after ``t_ref``
    (which is >= ``t_event`` and scores 0).

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).

    Returns:
        ``(t_react, valid)``: () float32, s (``NaN`` = no sustained response); () bool.
    """
    at_event = ctx.coincident_onset & state.response_at_event
    t_react = jnp.where(at_event, state.t_response_start, state.t_react)
    return time_or_nan(t_react), valid(state, ctx, t_fail)


def score(
    t_ref: Any, t_event: Any, t_react: Any, available: Any = True, coincident: Any = None
) -> Array:
    """``S_ant = clip((t_event - t_react) / (t_event - t_ref))``, elementwise.

    Args:
        t_ref: (...) float32, s; ``NaN`` makes the component unavailable.
        t_event: (...) float32, s; ``NaN`` makes the component unavailable.
        t_react: (...) float32, s; ``NaN`` or ``inf`` = no sustained response (scores 0).
        available: (...) bool, ``False`` -> ``NaN``.
        coincident: (...) bool, coincident warning/event onset; ``None`` means
            ``t_event <= t_ref``.  Coincident onset scores 1 iff ``t_react < t_event`` (a
            response was already present at the event), else 0.

    Returns:
        (...) float32 in [0, 1]; ``NaN`` where unavailable.
    """
    f32 = jnp.float32
    t_ref, t_event, t_react = (jnp.asarray(x, f32) for x in (t_ref, t_event, t_react))
    span = t_event - t_ref
    coinc = (span <= 0.0) if coincident is None else jnp.asarray(coincident, bool)
    responded = jnp.isfinite(t_react)
    safe_span = jnp.where(span > 0.0, span, 1.0)
    regular = jnp.clip((t_event - t_react) / safe_span, 0.0, 1.0)
    value = jnp.where(coinc, (t_react < t_event).astype(f32), regular)
    value = jnp.where(responded, value, 0.0)
    ok = jnp.asarray(available, bool) & ~jnp.isnan(t_ref) & ~jnp.isnan(t_event)
    return jnp.where(ok, value, jnp.nan)


def soft(
    state: AnticipationState, ctx: Context, t_fail: Array, temperature: Array,
    settings: ScoringSettings, d_safe: Any = None,
) -> tuple[Array, Array]:  # fmt: skip
    """Smooth ``S_ant``: ``P(response) * clip((t_event - E[t_react | response]) /
    (t_event - t_ref))`` with a smooth clip; with coincident onset the soft
    ``response_at_event``.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
        temperature: () float32, temperature of the smooth clip.
        settings: the response thresholds.
        d_safe: () float32, m, the scene's clearance normaliser (read by clearance only; every
            hazard term takes it: one signature per role).

    Returns:
        ``(s_ant, valid)``: () float32 in [0, 1]; () bool (the hard availability).
    """
    ok = valid(state, ctx, t_fail)
    has, e_react = expected_time(state.p, state.pt)
    span = ctx.t_event - ctx.t_warn_point
    safe_span = jnp.where(ok & (span > 0), span, 1.0)
    clipped = smooth_clip01((ctx.t_event - e_react) / safe_span, temperature)
    regular = jnp.where(has, state.p * clipped, 0.0)
    return jnp.where(ctx.coincident_onset, state.soft_response_at_event, regular), ok


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {"t_react_s": ("A", "t_react_s")}

#: The name of its score among the pair components and in the route-level table.
SCORE = "S_ant"


def score_of(metrics: Any, d_safe: Any, settings: ScoringSettings) -> Array:
    """``S_ant`` of Route A executions, elementwise:
    :func:`score` of their metrics' protocol times, ``t_react_s`` and flags
    (the hazard role's ``score_of``,
    :mod:`lantern_jax.scoring.components`)."""
    return score(metrics.t_ref_s, metrics.t_event_s, metrics.t_react_s,
                 metrics.anticipation_available, metrics.coincident_onset)  # fmt: skip


#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("t_react_s", "anticipation_available", "response_at_event")


def outputs(state: AnticipationState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    t_react, ok = hard(state, ctx, t_fail)
    return {
        "t_react_s": value_or_nan(t_react, ok),
        "anticipation_available": ok,
        "response_at_event": state.response_at_event,
    }
