"""Recovery component ``S_rec`` (paper appendix "Complete Cooperative Unified Score", paragraph
"Recovery")::

    RL = t_recover - t_release         S_rec = clip(1 - RL / 8 s)        no recovery -> 0

``t_release = max(t_warn_off, t_clear)`` once both happened.  With the threshold
``v_thr = max(2 m/s, 0.5 v_pre)``, ``t_recover`` is the start of the first 20-tick (1 s) window
whose ticks all lie at/after ``t_release`` with speed above ``v_thr`` and whose progress gain
(last tick minus first tick of the window) is >= 0.5 m.

**A window cut short by the route's end.**  The execution ends on the tick the ego reaches the
route's end zone (:func:`~lantern_jax.scoring.components.progress.is_completed`).  When that
happens less than a window after ``t_release`` no full window fits, and an ego that held its
speed from the release to the end would score "no recovery" (``S_rec = 0``) where one that
reached the end a tick later scores ``RL = 0`` (``S_rec = 1``): a cliff of a tenth of a second
in route completion, seen in Right-Turn Yield, where the release can come when the crossing car
passes behind an ego that went first.  The paper's appendix does not say what a route that
ends before the window fits scores (it asks for 29 m of route after the conflict, so that the
window fits after a yield).  Here, on the tick the route is completed, the windows that end
there are counted too, shorter than 20 ticks: the earliest whose ticks all lie at/after
``t_release`` with speed above ``v_thr`` and whose progress gain is >= 0.5 m (the same two
tests; only the duration is cut by the route's end) gives ``t_recover`` when no full window
passed before.  A full window keeps precedence, and an ego below ``v_thr`` at the end, or that
gained less than 0.5 m since the release, still has no recovery.  The cut windows are judged
once, when the execution has ended (:func:`cut_windows`, called by :func:`hard` and
:func:`soft`), on its last tick, the one that completed the route: nothing is added to a tick
of the rollout.

Soft (a soft first crossing): window ``k`` passes with probability ``sigma_k``, the product of
``sigmoid((v - v_thr) / T)`` over its ticks times ``sigmoid((gain - 0.5) / T)``;
``p_k = sigma_k prod_{j<k} (1 - sigma_j)``; the windows cut short by the route's end follow the
full windows in that order, earliest start first.  The state holds
``sum p_k`` and ``sum p_k t_k``; the score uses the expected ``t_recover`` given a recovery,
times the probability of a recovery.

Available (valid) when ``t_release`` happened no later than the first Route A gate failure.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import NEVER, happened, time_or_nan
from lantern_jax.scoring.components.accumulate import expected_time, first_time, push, run
from lantern_jax.scoring.components.context import (
    Context,
    Tick,
    opened_by,
    ring_length,
    value_or_nan,
)
from lantern_jax.scoring.components.progress import reached_end_zone
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import smooth_clip01
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class RecoveryState:
    """Accumulators of the recovery criterion (scalars unless a shape is given)."""

    run: Array  # () int32, consecutive ticks after release with speed above the threshold
    t_recover: Array  # () float32, s, start of the first recovery window (NEVER)
    log_ok: Array  # (ring_length,) float32, log sigmoid((v - v_thr) / T) of the last ticks
    surv: Array  # () float32, soft probability that no window has passed yet
    p: Array  # () float32, soft probability that some window passed, sum_k p_k
    pt: Array  # () float32, s, sum_k p_k t_k
    # the settings the windows cut short by the route's end are judged with at the end (the
    # hazard role's :func:`hard` takes no settings; :func:`soft` and :func:`outputs` judge the
    # windows with the same values)
    window: Array  # () int32, ticks of a full window (``recover_window``)
    min_gain: Array  # () float32, m, progress a window needs (``recover_min_progress_m``)
    end_zone: Array  # () float32, m, the route's end zone (``completion_tol_m``)


def init(settings: ScoringSettings) -> RecoveryState:
    """No tick yet."""
    f = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    ring = ring_length(settings)
    return RecoveryState(
        run=jnp.asarray(0, jnp.int32), t_recover=f(NEVER), log_ok=jnp.zeros(ring, jnp.float32),
        surv=f(1.0), p=f(0.0), pt=f(0.0),
        window=jnp.asarray(settings.recover_window, jnp.int32),
        min_gain=f(settings.recover_min_progress_m), end_zone=f(settings.completion_tol_m),
    )  # fmt: skip


def release_time(t_warn_off: Array, t_clear: Array) -> Array:
    """Release time ``max(t_warn_off, t_clear)`` once both happened.

    Args:
        t_warn_off: (...) float32, s, warning termination (``NEVER`` = not happened).
        t_clear: (...) float32, s, hazard clearance (``NEVER`` = not happened).

    Returns:
        (...) float32, s; ``NEVER`` until both happened.
    """
    both = happened(t_warn_off) & happened(t_clear)
    return jnp.where(both, jnp.maximum(t_warn_off, t_clear), NEVER)


def update(
    state: RecoveryState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> RecoveryState:
    """Fold one tick.

    Args:
        state: accumulators before the tick.
        sample: the tick's measurement (unused: speed and progress come with ``tick``).
        tick: shared per-tick context.
        settings: thresholds; temperature: () float32, m/s (speed test) and m (progress test).

    Returns:
        The accumulators after the tick.
    """
    temperature = settings.temperature
    t_release = release_time(tick.t_warn_off, tick.t_clear)
    post_rel = happened(t_release) & (tick.t >= t_release)
    v_thr = jnp.maximum(settings.recover_min_speed_mps, settings.recover_pre_fraction * tick.v_pre)
    n_run = run(state.run, post_rel & (tick.speed > v_thr))
    # the window's first tick: the rings are as long as the longer of the reaction and recovery
    # windows, so the recovery window is their last ``recover_window`` entries
    first = ring_length(settings) - settings.recover_window
    window_start = tick.time_ring[first]
    gain = tick.progress - tick.progress_ring[first]
    ok = (n_run >= settings.recover_window) & (gain >= settings.recover_min_progress_m)

    log_ok = push(state.log_ok, jax.nn.log_sigmoid((tick.speed - v_thr) / temperature))
    complete = post_rel & (tick.n_ticks >= settings.recover_window) & (window_start >= t_release)
    gain_ok = jax.nn.sigmoid((gain - settings.recover_min_progress_m) / temperature)
    sigma = jnp.where(complete, jnp.exp(jnp.sum(log_ok[first:])) * gain_ok, 0.0)
    p_k = state.surv * sigma
    return state.replace(
        run=n_run,
        t_recover=first_time(happened(state.t_recover), ok, window_start, state.t_recover),
        log_ok=log_ok,
        surv=state.surv * (1.0 - sigma),
        p=state.p + p_k,
        pt=state.pt + p_k * window_start,
    )


def cut_windows(state: RecoveryState, ctx: Context) -> tuple[Array, Array, Array]:
    """The windows cut short by the route's end (module docstring), judged once the execution
    has ended: when its route is completed, the windows of 1 ... ``window - 1`` ticks that end
    on its last tick (the one that completed it: an execution ends there), after that tick's
    full window, earliest start first.

    Args:
        state: final accumulators (leading batch axes allowed, as everywhere here).
        ctx: final shared context (its rings end with the last tick).

    Returns:
        ``(t_cut, p, pt)``: (...) float32, s, the start of the earliest cut window that passes
        (``NEVER``: none); (...) float32 and (...) float32, s, the soft first crossings they
        add to ``state.p`` and ``state.pt`` (the speed sigmoids as folded, the progress sigmoid
        at the context's temperature).
    """
    ring = state.log_ok.shape[-1]
    col = lambda x: jnp.asarray(x)[..., None]  # noqa: E731  (...) -> (..., 1) beside the windows
    lengths = jnp.arange(ring - 1, 0, -1)  # window lengths, earliest start first
    starts = ctx.time_ring[..., 1:]  # (..., ring - 1) s, their first ticks
    gains = col(ctx.progress_m) - ctx.progress_ring[..., 1:]  # (..., ring - 1) m
    t_release = col(release_time(ctx.t_warn_off, ctx.t_clear))
    completed = col(reached_end_zone(ctx.progress_m, ctx.route_length_m, state.end_zone))
    opened = (completed & happened(t_release) & (starts >= t_release)
              & (lengths < col(state.window)) & (col(ctx.n_ticks) >= lengths))  # fmt: skip
    # hard: every tick above the threshold (``run`` counts the ticks after the release that
    # are, up to the last one) and the progress; the earliest such window
    hard_ok = opened & (lengths <= col(state.run)) & (gains >= col(state.min_gain))
    t_cut = jnp.min(jnp.where(hard_ok, starts, NEVER), axis=-1)
    # soft: each passes with its ticks' speed sigmoids times its progress sigmoid, after the
    # earlier ones failed
    suffix = jnp.cumsum(state.log_ok[..., ::-1], axis=-1)[..., ::-1][..., 1:]  # summed to the end
    gain_ok = jax.nn.sigmoid((gains - col(state.min_gain)) / col(ctx.temperature))
    sigma = jnp.where(opened, jnp.exp(suffix) * gain_ok, 0.0)
    survive = jnp.cumprod(1.0 - sigma, axis=-1)
    before = jnp.concatenate([jnp.ones_like(survive[..., :1]), survive[..., :-1]], axis=-1)
    p_k = col(state.surv) * sigma * before
    return t_cut, jnp.sum(p_k, axis=-1), jnp.sum(p_k * starts, axis=-1)


def _t_recover(state: RecoveryState, ctx: Context) -> Array:
    """() float32, s: the start of the first window that passed, full or cut (``NEVER``)."""
    return jnp.where(happened(state.t_recover), state.t_recover, cut_windows(state, ctx)[0])


def _latency(t_recover: Array, ctx: Context) -> Array:
    """() float32, s: ``t_recover - t_release`` (``NaN`` = no recovery), for the
    :func:`_t_recover` of the same execution."""
    latency = t_recover - release_time(ctx.t_warn_off, ctx.t_clear)
    return jnp.where(happened(t_recover), latency, jnp.nan)


def valid(state: RecoveryState, ctx: Context, t_fail: Array) -> Array:
    """() bool: ``t_release`` happened no later than ``t_fail``.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
    """
    return opened_by(release_time(ctx.t_warn_off, ctx.t_clear), t_fail)


def recovered_at(state: RecoveryState, ctx: Context, t_fail: Array) -> tuple[Array, Array]:
    """Start of the first recovery window.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).

    Returns:
        ``(t_recover, valid)``: () float32, s (``NaN`` = no recovery); () bool.
    """
    return time_or_nan(_t_recover(state, ctx)), valid(state, ctx, t_fail)


def hard(state: RecoveryState, ctx: Context, t_fail: Array) -> tuple[Array, Array]:
    """Hard recovery latency ``RL = t_recover - t_release``.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).

    Returns:
        ``(latency, valid)``: () float32, s (``NaN`` = no recovery); () bool.
    """
    return _latency(_t_recover(state, ctx), ctx), valid(state, ctx, t_fail)


def score(recovery_latency_s: Any, settings: ScoringSettings, available: Any = True) -> Array:
    """``S_rec = clip(1 - RL / 8 s)``, elementwise.

    Args:
        recovery_latency_s: (...) float32, s; ``NaN`` or ``inf`` = no recovery (scores 0).
        settings: the cap (``recover_cap_s``).
        available: (...) bool, ``False`` -> ``NaN``.

    Returns:
        (...) float32 in [0, 1]; ``NaN`` where unavailable.
    """
    rl = jnp.asarray(recovery_latency_s, jnp.float32)
    value = jnp.where(jnp.isfinite(rl), jnp.clip(1.0 - rl / settings.recover_cap_s, 0.0, 1.0), 0.0)
    return jnp.where(jnp.asarray(available, bool), value, jnp.nan)


def soft(
    state: RecoveryState, ctx: Context, t_fail: Array, temperature: Array,
    settings: ScoringSettings, d_safe: Any = None,
) -> tuple[Array, Array]:  # fmt: skip
    """Smooth ``S_rec``: ``P(recovered) * clip(1 - (E[t_recover | recovered] - t_release) /
    8 s)`` with a smooth clip.

    Args:
        state: final accumulators.
        ctx: final shared context.
        t_fail: () float32, s, first Route A gate failure (``NEVER`` if none).
        temperature: () float32, temperature of the smooth clip.
        settings: the response thresholds.
        d_safe: () float32, m, the scene's clearance normaliser (read by clearance only; every
            hazard term takes it: one signature per role).

    Returns:
        ``(s_rec, valid)``: () float32 in [0, 1]; () bool (the hard availability).
    """
    ok = valid(state, ctx, t_fail)
    _, p_cut, pt_cut = cut_windows(state, ctx)
    p, pt = state.p + p_cut, state.pt + pt_cut
    has, e_rec = expected_time(p, pt)
    t_rel = jnp.where(ok, release_time(ctx.t_warn_off, ctx.t_clear), 0.0)
    clipped = smooth_clip01(1.0 - (e_rec - t_rel) / settings.recover_cap_s, temperature)
    return jnp.where(has, p * clipped, 0.0), ok


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {"recovery_latency_s": ("A", "recovery_latency_s")}

#: The name of its score among the pair components and in the route-level table.
SCORE = "S_rec"


def score_of(metrics: Any, d_safe: Any, settings: ScoringSettings) -> Array:
    """``S_rec`` of Route A executions, elementwise:
    :func:`score` of their metrics' ``recovery_latency_s`` (the hazard role's ``score_of``,
    :mod:`lantern_jax.scoring.components`)."""
    return score(metrics.recovery_latency_s, settings, metrics.recovery_available)


#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("t_release_s", "t_recover_s", "recovery_latency_s", "recovery_available")


def outputs(state: RecoveryState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure).  The windows cut short by the route's end are judged once for
    both times (:func:`cut_windows`)."""
    t_recover, ok = _t_recover(state, ctx), valid(state, ctx, t_fail)
    return {
        "t_release_s": time_or_nan(release_time(ctx.t_warn_off, ctx.t_clear)),
        "t_recover_s": value_or_nan(time_or_nan(t_recover), ok),
        "recovery_latency_s": value_or_nan(_latency(t_recover, ctx), ok),
        "recovery_available": ok,
    }
