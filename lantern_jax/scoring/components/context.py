"""Shared context of the score components: what every component reads, computed once per tick.

:func:`update` folds a :class:`~lantern_jax.scoring.sample.TickSample` into the stored
:class:`Context` (tick counter, latest protocol times and progress, short rings of time, progress,
speed and acceleration, the pre-warning speed ``v_pre``) and returns a :class:`Tick`: the sample's
values as float32/bool together with the window masks derived from its protocol times.  Each
component's ``update`` receives that :class:`Tick` instead of recomputing it.

Conventions (paper appendix "Complete Cooperative Unified Score"):

* Times are seconds from execution start; a time that has not happened is
  :data:`lantern_jax.core.times.NEVER`.  ``sample.t`` is the tick's time stamp and a window "starts"
  at the time stamp of its first tick.
* Window membership uses the protocol times of the current sample: ``t_ref <= t`` (post
  reference), ``t_event <= t`` (post event), ``t <= t_clear`` (before clearance).
* ``v_pre`` is the ego speed before warning onset (the paper's "pre-warning reference" speed,
  used by anticipation and recovery): the speed on the last tick with ``t < t_ref``, i.e. the
  state just before the tick in which the ego crossed the warning point (the speed on the
  first tick at/after ``t_ref`` only if no tick came before it).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.times import NEVER, happened
from lantern_jax.scoring.components.accumulate import count, push
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


def ring_length(settings: ScoringSettings) -> int:
    """Ticks of the time and progress rings: the longer of the reaction and recovery windows."""
    return max(settings.react_window, settings.recover_window)


@struct.dataclass
class Context:
    """Stored shared context of one execution (scalars unless a shape is given)."""

    n_ticks: Array  # () int32, ticks folded so far
    t_last: Array  # () float32, s, time stamp of the last folded tick (0 before any)
    temperature: Array  # () float32, temperature the soft accumulators were built with
    is_route_a: Array  # () bool, latest sample
    coincident_onset: Array  # () bool, warning and event points coincide (seen on any tick)
    t_warn_point: Array  # () float32, s, t_ref of the latest sample (NEVER = not happened)
    t_event: Array  # () float32, s, event onset (NEVER)
    t_warn_off: Array  # () float32, s, warning termination (NEVER)
    t_clear: Array  # () float32, s, hazard clearance (NEVER)
    progress_m: Array  # () float32, m, furthest route arc reached (latest sample)
    route_length_m: Array  # () float32, m
    time_ring: Array  # (ring_length,) float32, s, time stamps of the last ticks, oldest first
    progress_ring: Array  # (ring_length,) float32, m, progress of the last ticks
    speed_ring: Array  # (react_window,) float32, m/s, ego speed of the last ticks
    accel_ring: Array  # (react_window,) float32, m/s^2, ego acceleration of the last ticks
    v_pre: Array  # () float32, m/s, ego speed on the last tick before t_ref (running value
    #               until the first tick at/after t_ref, frozen from then on)
    v_pre_set: Array  # () bool, v_pre has been frozen (a tick at/after t_ref was folded)


@struct.dataclass
class Tick:
    """Per-tick view handed to every component's ``update`` (not stored; scalars)."""

    t: Array  # () float32, s, time stamp of the tick
    speed: Array  # () float32, m/s, ego speed
    accel: Array  # () float32, m/s^2, ego longitudinal acceleration
    progress: Array  # () float32, m, furthest route arc reached
    route_length: Array  # () float32, m
    present: Array  # () bool, the controlled hazard exists
    collision: Array  # () bool, the ego collides this tick
    hazard_dist: Array  # () float32, m, ego-hazard box distance clamped at 0 (0 = overlap)
    t_ref: Array  # () float32, s, warning point of the sample (NEVER)
    t_event: Array  # () float32, s, event onset of the sample (NEVER)
    t_warn_off: Array  # () float32, s, warning termination of the sample (NEVER)
    t_clear: Array  # () float32, s, clearance of the sample (NEVER)
    post_ref: Array  # () bool, t_ref happened and t >= t_ref
    post_event: Array  # () bool, t_event happened and t >= t_event
    before_clear: Array  # () bool, t <= t_clear
    n_ticks: Array  # () int32, ticks folded including this one
    time_ring: Array  # (ring_length,) float32, s, ring including this tick (last entry)
    progress_ring: Array  # (ring_length,) float32, m
    speed_ring: Array  # (react_window,) float32, m/s
    accel_ring: Array  # (react_window,) float32, m/s^2
    v_pre: Array  # () float32, m/s, pre-warning speed after this tick (final once post_ref)


def init(settings: ScoringSettings) -> Context:
    """Context before the first tick (ring lengths from ``settings``)."""
    f = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    ring, window = ring_length(settings), settings.react_window
    return Context(
        n_ticks=jnp.asarray(0, jnp.int32), t_last=f(0.0), temperature=f(1.0),
        is_route_a=jnp.asarray(True), coincident_onset=jnp.asarray(False),
        t_warn_point=f(NEVER), t_event=f(NEVER), t_warn_off=f(NEVER), t_clear=f(NEVER),
        progress_m=f(0.0), route_length_m=f(0.0),
        time_ring=jnp.zeros(ring, jnp.float32), progress_ring=jnp.zeros(ring, jnp.float32),
        speed_ring=jnp.zeros(window, jnp.float32),
        accel_ring=jnp.zeros(window, jnp.float32),
        v_pre=f(0.0), v_pre_set=jnp.asarray(False),
    )  # fmt: skip


def _tick(ctx: Context, s: TickSample) -> Tick:
    """The sample as float32/bool, the pushed rings and the window masks of this tick."""
    f32 = jnp.float32
    t = jnp.asarray(s.t, f32)
    speed = jnp.asarray(s.ego_speed, f32)
    post_ref = happened(s.t_warn_point) & (t >= s.t_warn_point)
    # Before t_ref v_pre follows the speed; the first tick at/after t_ref freezes the speed of
    # the tick before it (or its own speed when it is the very first tick).
    first_speed = jnp.where(ctx.n_ticks > 0, ctx.v_pre, speed)
    v_pre = jnp.where(ctx.v_pre_set, ctx.v_pre, jnp.where(post_ref, first_speed, speed))
    return Tick(
        t=t,
        speed=speed,
        accel=jnp.asarray(s.ego_accel, f32),
        progress=jnp.asarray(s.progress, f32),
        route_length=jnp.asarray(s.route_length, f32),
        present=jnp.asarray(s.hazard_present, bool),
        collision=jnp.asarray(s.collision, bool),
        hazard_dist=jnp.maximum(jnp.asarray(s.hazard_box_dist, f32), 0.0),
        t_ref=s.t_warn_point,
        t_event=s.t_event,
        t_warn_off=s.t_warn_off,
        t_clear=s.t_clear,
        post_ref=post_ref,
        post_event=happened(s.t_event) & (t >= s.t_event),
        before_clear=t <= s.t_clear,
        n_ticks=count(ctx.n_ticks, jnp.asarray(True)),
        time_ring=push(ctx.time_ring, t),
        progress_ring=push(ctx.progress_ring, jnp.asarray(s.progress, f32)),
        speed_ring=push(ctx.speed_ring, speed),
        accel_ring=push(ctx.accel_ring, jnp.asarray(s.ego_accel, f32)),
        v_pre=v_pre,
    )


def update(ctx: Context, s: TickSample, settings: ScoringSettings) -> tuple[Context, Tick]:
    """Fold one tick into the shared context.

    Args:
        ctx: context before the tick.
        s: the tick's measurement.
        settings: scoring settings; their temperature (of the soft accumulators) is recorded
            for decoding.

    Returns:
        ``(context after the tick, per-tick view for the components)``.
    """
    f32 = jnp.float32
    tick = _tick(ctx, s)
    new = Context(
        n_ticks=tick.n_ticks,
        t_last=tick.t,
        temperature=jnp.asarray(settings.temperature, f32),
        is_route_a=jnp.asarray(s.is_route_a, bool),
        coincident_onset=ctx.coincident_onset | jnp.asarray(s.coincident_onset, bool),
        t_warn_point=jnp.asarray(s.t_warn_point, f32),
        t_event=jnp.asarray(s.t_event, f32),
        t_warn_off=jnp.asarray(s.t_warn_off, f32),
        t_clear=jnp.asarray(s.t_clear, f32),
        progress_m=tick.progress,
        route_length_m=tick.route_length,
        time_ring=tick.time_ring,
        progress_ring=tick.progress_ring,
        speed_ring=tick.speed_ring,
        accel_ring=tick.accel_ring,
        v_pre=tick.v_pre,
        v_pre_set=ctx.v_pre_set | tick.post_ref,
    )
    return new, tick


def opened_by(t_open: Array, t_fail: Array) -> Array:
    """() bool: a window opening at ``t_open`` (s) opened no later than the first Route A gate
    failure ``t_fail`` (s, ``NEVER`` if none) -- the paper's "valid hazard telemetry" rule."""
    return happened(t_open) & (t_open <= t_fail)


def value_or_nan(value: Array, valid: Array) -> Array:
    """``value`` where ``valid``, ``NaN`` where the measurement is unavailable (never imputed)."""
    return jnp.where(valid, value, jnp.nan)
