"""Scripted actors: closed-form motion along a path (see
:class:`lantern_jax.types.world.ActorScript`).

For one actor with trigger time ``tau``::

    before tau   s(t) = min(s_init + v_pre t, s_hold)                speed v_pre (0 once held)
    after tau    s(t) = s(tau) + v_post (t - tau)                     speed v_post
                 lat(t) = lat_shift * smoothstep((t - tau) / lat_duration)
    always       s clipped to s_end (speed 0 there); inactive from s_end on if despawn_at_end
    pose         xy = path(s) + left_normal(path_heading(s)) * lat
                 yaw = path_heading(s) + atan2(dlat/dt, ds/dt)

with ``smoothstep(x) = 3 x^2 - 2 x^3`` on ``[0, 1]`` (0 below, 1 above).  An adversarial
track (:mod:`lantern_jax.dynamics.adversary`) adds its closed-form deviations after ``tau``.
Everything is a piecewise-smooth function of the script parameters and of ``tau``, so the
position has finite gradients with respect to ``v_pre``, ``v_post``, ``s_init``, ``lat_shift``,
``lat_duration`` and the trigger time (hence ``trigger_delay`` and ``t_event``).  A trigger
time that has not happened (``times.NEVER``) means "not (yet) triggered": it is replaced by
``t`` before any arithmetic, so no huge number ever enters a value or a gradient.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import TRIGGER_CLOCK, TRIGGER_EVENT
from lantern_jax.core.times import NEVER, happened
from lantern_jax.dynamics.adversary import scripted_offsets
from lantern_jax.maths.geometry import safe_norm
from lantern_jax.maths.polyline import interpolate, left_normal, safe_atan2
from lantern_jax.types.world import ActorScript

Array = jax.Array


@struct.dataclass
class ScriptedMotion:
    """The closed-form motion of scripted actors: the fields of
    :class:`~lantern_jax.types.world.ActorScript` that :func:`scripted_arc` reads, shaped ``()`` for
    one actor or ``(A,)`` for every slot (:meth:`of`)."""

    s_init: Array  # float32, m, arc at t = 0
    v_pre: Array  # float32, m/s, speed before the trigger (>= 0)
    v_post: Array  # float32, m/s, speed after the trigger (>= 0)
    s_hold: Array  # float32, m, arc where the actor waits for its trigger (BIG = none)
    s_end: Array  # float32, m, arc where the actor stops or despawns
    lat_shift: Array  # float32, m, lateral offset reached after the trigger, + = left
    lat_duration: Array  # float32, s, duration of the lateral manoeuvre (> 0)
    despawn_at_end: Array  # bool, the actor leaves the world when it reaches ``s_end``

    @classmethod
    def of(cls, script: ActorScript) -> ScriptedMotion:
        """Every slot's motion (leaves (A,)) from the actors' scripts."""
        return cls(
            s_init=script.s_init, v_pre=script.v_pre, v_post=script.v_post,
            s_hold=script.s_hold, s_end=script.s_end, lat_shift=script.lat_shift,
            lat_duration=script.lat_duration, despawn_at_end=script.despawn_at_end,
        )  # fmt: skip


def trigger_time(
    trigger: Array, trigger_delay: Array, t_event: Array, deadline: Array | None = None
) -> Array:
    """Trigger time of a scripted actor.

    Args:
        trigger: (...) int32, TRIGGER_* source.
        trigger_delay: (...) float32, s, delay after the source.
        t_event: () or (...) float32, s, physical event onset (``times.NEVER`` until it happens).
        deadline: (...) float32, s, latest trigger time (``times.NEVER`` = none); None = none.

    Returns:
        (...) float32, s: ``trigger_delay`` (clock), ``t_event + trigger_delay`` (event; stays
        ``NEVER`` while the event is pending), ``NEVER`` (never) — or the deadline when it comes
        first.
    """
    event_pending = ~happened(t_event)
    t_ev = jnp.where(event_pending, 0.0, t_event)
    tau_event = jnp.where(event_pending, NEVER, t_ev + trigger_delay)
    tau = jnp.where(
        trigger == TRIGGER_CLOCK,
        trigger_delay,
        jnp.where(trigger == TRIGGER_EVENT, tau_event, NEVER),
    )
    if deadline is not None:
        tau = jnp.minimum(tau, deadline)
    return tau.astype(jnp.float32)


def smoothstep(x: Array) -> Array:
    """``3 x^2 - 2 x^3`` on ``x`` clipped to ``[0, 1]``.

    Args:
        x: (...) float32.

    Returns:
        (...) float32 in [0, 1].
    """
    x = jnp.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def scripted_arc(
    motion: ScriptedMotion,
    t: Array,
    t_trigger: Array,
    track: tuple[Array, ...] | None = None,
) -> tuple[Array, Array, Array, Array, Array]:
    """Closed-form place of ONE scripted actor along its path at time ``t`` (no geometry).

    Args:
        motion: the actor's :class:`ScriptedMotion` (leaves shaped ``()``).
        t: () float32, s, time.
        t_trigger: () float32, s, trigger time ``tau`` (``NEVER`` = not triggered).
        track: the actor's adversarial track after its trigger, ``(dv, ds, q, g, dlat,
            knot_s)`` of :class:`lantern_jax.types.world.ActorTrack` for this slot
            (:mod:`lantern_jax.dynamics.adversary`), or None for none; its deviations add to
            the arc, the speed, the lateral offset and the lateral speed (exact zeros for
            all-zero actions).

    Returns:
        s: () float32, m, arc along the path.
        lat: () float32, m, lateral offset, + = left of travel.
        v_long: () float32, m/s, speed along the path.
        v_lat: () float32, m/s, lateral speed (during the manoeuvre).
        active: () bool, False once ``s_end`` is reached when ``despawn_at_end``.
    """
    m = motion
    s_init, v_pre, v_post, s_hold, s_end = m.s_init, m.v_pre, m.v_post, m.s_hold, m.s_end
    lat_shift, lat_duration, despawn_at_end = m.lat_shift, m.lat_duration, m.despawn_at_end
    pending = ~happened(t_trigger)
    tau = jnp.where(pending, t, t_trigger)
    t_pre = jnp.minimum(t, tau)  # time spent in the pre-trigger phase
    fired = (~pending) & (t >= tau)
    dt_post = jnp.where(fired, t - tau, 0.0)

    s_free = s_init + v_pre * t_pre
    held = s_free >= s_hold
    s_pre = jnp.minimum(s_free, s_hold)
    s_raw = s_pre + v_post * dt_post
    v_after = v_post
    if track is not None:
        off_s, off_v, off_lat, off_w = scripted_offsets(*track, dt_post)
        s_raw = s_raw + off_s
        v_after = v_post + off_v
    reached = s_raw >= s_end
    s = jnp.minimum(s_raw, s_end)
    v_long = jnp.where(fired, v_after, jnp.where(held, 0.0, v_pre))
    v_long = jnp.where(reached, 0.0, v_long)

    dur = jnp.maximum(lat_duration, 1e-3)
    x = jnp.where(fired, dt_post / dur, 0.0)
    lat = lat_shift * smoothstep(x)
    in_manoeuvre = fired & (x < 1.0)
    xc = jnp.clip(x, 0.0, 1.0)
    v_lat = jnp.where(in_manoeuvre, lat_shift * 6.0 * xc * (1.0 - xc) / dur, 0.0)
    if track is not None:
        lat = lat + off_lat
        v_lat = v_lat + jnp.where(reached, 0.0, off_w)
    active = ~(despawn_at_end & reached)
    return s, lat, v_long, v_lat, active


def scripted_pose(
    path: Array,
    path_s: Array,
    path_valid: Array,
    motion: ScriptedMotion,
    t: Array,
    t_trigger: Array,
    track: tuple[Array, ...] | None = None,
) -> tuple[Array, Array, Array, Array, Array, Array]:
    """Closed-form state of ONE scripted actor at time ``t``.

    Args:
        path: (P, 2) float32, m, world-frame polyline.
        path_s: (P,) float32, m, its cumulative arc length.
        path_valid: (P,) bool, prefix mask of valid points.
        motion: as in :func:`scripted_arc`, and so are ``t``, ``t_trigger`` and ``track``.

    Returns:
        s: () float32, m, arc along the path.
        lat: () float32, m, lateral offset, + = left of travel.
        speed: () float32, m/s, ``sqrt((ds/dt)^2 + (dlat/dt)^2)`` along ``yaw``.
        xy: (2,) float32, m, world-frame box centre.
        yaw: () float32, rad, CCW from +x.
        active: () bool, False once ``s_end`` is reached when ``despawn_at_end``.
    """
    s, lat, v_long, v_lat, active = scripted_arc(motion, t, t_trigger, track)
    point, heading = interpolate(path, path_s, path_valid, s)
    xy = point + left_normal(heading) * lat
    yaw = heading + safe_atan2(v_lat, v_long)
    yaw = jnp.arctan2(jnp.sin(yaw), jnp.cos(yaw))
    speed = safe_norm(jnp.stack([v_long, v_lat]))
    return s, lat, speed, xy, yaw, active
