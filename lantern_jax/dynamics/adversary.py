"""Adversarial actor tracks: bounded actions per knot through a kinematic model, closed form.

A track (:class:`lantern_jax.types.world.ActorTrack`, in the manner of KING's adversarial agents)
perturbs one actor's motion after its **start** — its trigger time, or the physical event for an
actor that never triggers (background traffic) — knot by knot: knot ``k`` covers
``u in [k h, (k + 1) h)`` with ``u = t - start`` and ``h`` the knot length.  Each of the ``N``
knots holds two actions, a commanded longitudinal acceleration ``a_k`` and a lateral target
``Q_k``; after the last knot the actor **returns** to its script: to its scripted speed and to
a zero lateral channel, within its limits (``E`` more knots, enough to return from anywhere),
keeping the offset it has gained, and then holds.

**Longitudinal** (every kind).  The speed at the knots is ``v_0`` (the scripted speed after the
trigger, ``v_post``) and ``v_{k+1} = clip(v_k + a_k h, 0, max(v_max, v_0))``, linear in between
(on the return knots ``a_k = clip((v_0 - v_k) / h, -b_max, a_max)``); the arc gains
``ds(u) = integral of (v - v_0)`` on top of the script.  The clip is 1-Lipschitz, so the realised
acceleration never exceeds the commanded one: ``|dv/dt| <= a_max`` or ``b_max`` whatever the
actions.

**Lateral**.  The channel starts at 0 and moves toward each knot's target at the lateral rate
limit: ``q_{k+1} = q_k + clip(Q_k - q_k, -lat_rate h, lat_rate h)`` with
``|Q_k| <= lat_max``, linear in between.  A **holonomic** actor (a walker) moves sideways at
``w = q`` (m/s: lateral speed ``<= lat_max``, lateral acceleration ``<= lat_rate``); a
**vehicle** keeps its heading within ``q`` (rad) of its path and moves sideways at ``w = v q``
(m/s), so it cannot slide at a standstill (heading offset ``<= lat_max``, its rate
``<= lat_rate``).  The lateral offset gains ``dlat(u) = integral of w``, a cubic in ``u`` inside
each knot (product of two linear functions), so everything is closed form in ``u``.

**IDM actors** (background traffic, and scripted actors once handed over to the IDM) add the
commanded ``a_k`` to the IDM acceleration during the ``N`` knots, the sum clipped to
``[-b_max, a_max]`` (no acceleration beyond ``v_max``), after which the IDM itself brings them
back to their desired speed; their lateral offset integrates ``w = speed * q`` tick by tick with
the actual speed and the same closed-form channel ``q(u)``.

All-zero actions give ``v_k = v_0`` and ``q_k = 0`` exactly, so every deviation is an exact
zero and the motion is the script's (or the IDM's) bit for bit.  The knot profile (speeds,
lateral channel and their integrals at the ``N + E + 1`` knot times) is computed once per track
(:func:`track_profile`, differentiable in the actions) and stored in the track, so a tick
evaluates a few multiply-adds per actor.

Kinematic limits per kind (one table, :data:`KINEMATIC_LIMITS`; the world builder copies them
into each track slot):

==========  =====  =====  =====  ==============  ===============  =====================
class       v_max  a_max  b_max  lateral bound   lateral rate     sources
==========  =====  =====  =====  ==============  ===============  =====================
pedestrian  4.5    2.5    3.0    1.0 m/s         2.0 m/s^2        see below
cyclist     8.3    1.5    3.4    0.35 rad        0.6 rad/s        AASHTO, FHWA-HRT-04-103
car         16.7   3.0    8.0    0.2 rad         0.4 rad/s        the ego's own limits
==========  =====  =====  =====  ==============  ===============  =====================

(m/s, m/s^2; lateral bound: of the sideways speed for walkers, of the heading offset from the
path for vehicles; lateral rate: its rate of change.) *Pedestrian*: a run (adult running speeds
in accident-reconstruction data are about 3-5 m/s; the Pedestrian Emergence speed range ends
here); acceleration from a standing start at signalised crosswalks 0.14 +/- 0.09 g (Randles et
al., real-world video of 288 pedestrians): 2.5 m/s^2 is the mean plus about one standard
deviation; braking 3.0 m/s^2 and the sidestep (1 m/s, 2 m/s^2) are ours. *Cyclist*: AASHTO's
design speed 30 km/h (8.3 m/s) and design deceleration 0.35 g (3.4 m/s^2, "Guide for the
Development of Bicycle Facilities"); the 85th-percentile start acceleration measured for
bicycles is 1.4 m/s^2 (FHWA-HRT-04-103, table 10); heading bound and rate are ours. No actor
kind of the simulator is a cyclist yet (:data:`lantern_jax.core.constants.KIND_NAMES`); the row is
what one gets. *Car*: 60 km/h (an urban 50 km/h limit + 20 %), the ego's throttle limit (3
m/s^2, ``EGO_MAX_ACCEL``) and full braking on dry asphalt (8 m/s^2, ``EGO_MAX_BRAKE``; passenger
cars reach 0.6-0.9 g); heading offset 0.2 rad (11 deg: a 2 m/s lateral speed at 10 m/s, an
abrupt lane change; ordinary ones are 0.5-1 m/s) and its rate 0.4 rad/s (4 m/s^2 of lateral
acceleration at 10 m/s, half the friction limit) are ours. Static objects take no track.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import KIND_PEDESTRIAN, KIND_VEHICLE, TRIGGER_NEVER
from lantern_jax.types.world import ActorTrack

Array = jax.Array


@dataclasses.dataclass(frozen=True)
class KindLimits:
    """Kinematic limits of one class of actor (see the module docstring for the sources)."""

    v_max: float  # m/s
    a_max: float  # m/s^2, acceleration
    b_max: float  # m/s^2, braking (positive)
    lat_max: float  # m/s (holonomic) or rad (heading offset)
    lat_rate: float  # m/s^2 (holonomic) or rad/s (heading-offset rate)
    holonomic: bool  # lateral channel is a velocity (walkers), else a heading offset


KINEMATIC_LIMITS: dict[str, KindLimits] = {
    "pedestrian": KindLimits(4.5, 2.5, 3.0, 1.0, 2.0, True),
    "cyclist": KindLimits(30.0 / 3.6, 1.5, 3.4, 0.35, 0.6, False),
    "car": KindLimits(60.0 / 3.6, 3.0, 8.0, 0.2, 0.4, False),
}

#: The class of limits each simulator actor kind takes (static objects take no track).
CLASS_OF_KIND = {KIND_VEHICLE: "car", KIND_PEDESTRIAN: "pedestrian"}

#: s, the longest return to the script any class needs after its last knot: from standstill or
#: its top speed back to its scripted speed, and from its lateral bound back to 0.
RETURN_S = max(
    max(k.v_max / min(k.a_max, k.b_max), k.lat_max / k.lat_rate) for k in KINEMATIC_LIMITS.values()
)


def limits_of_kind(kind: int) -> KindLimits:
    """The limits of a simulator actor kind.

    Raises:
        ValueError: for a kind that cannot move (static objects).
    """
    if int(kind) not in CLASS_OF_KIND:
        raise ValueError(f"actor kind {int(kind)} takes no track (only vehicles and pedestrians)")
    return KINEMATIC_LIMITS[CLASS_OF_KIND[int(kind)]]


def return_knots(knot_s: float) -> int:
    """Knots ``E`` after the last action knot in which any actor, at its limits, gets back to
    its scripted speed and a zero lateral channel (:data:`RETURN_S` seconds, rounded up)."""
    return int(math.ceil(RETURN_S / float(knot_s) - 1e-9))


def scale_actions(u_accel: Array, u_lateral: Array, lim: KindLimits) -> tuple[Array, Array]:
    """Physical actions from normalised ones in ``[-1, 1]``.

    Args:
        u_accel: (..., N) float32, ``1`` = ``a_max``, ``-1`` = ``-b_max``.
        u_lateral: (..., N) float32, ``+-1`` = ``+-lat_max`` (the lateral target).
        lim: the actor's limits.

    Returns:
        ``(accel m/s^2, lateral target)``, each (..., N) float32.
    """
    u_accel = jnp.asarray(u_accel, jnp.float32)
    accel = jnp.where(u_accel >= 0.0, u_accel * lim.a_max, u_accel * lim.b_max)
    return accel, jnp.asarray(u_lateral, jnp.float32) * jnp.float32(lim.lat_max)


def track_profile(
    accel: Array, lateral: Array, knot_s: Array, v0: Array, lim: KindLimits
) -> dict[str, Array]:
    """Knot profile of ONE actor's track (see the module docstring).

    Args:
        accel: (N,) float32, m/s^2, commanded acceleration per knot.
        lateral: (N,) float32, lateral target per knot (m/s or rad).
        knot_s: static knot length ``h``, s.
        v0: () float32, m/s, speed at the start (the scripted ``v_post``).
        lim: the actor's limits.

    Returns:
        ``dv`` speed deviation ``v_j - v_0`` (m/s), ``ds`` its integral (m), ``q`` lateral
        channel, ``g`` lateral gain (1 or the speed ``v_j``), ``dlat`` the lateral offset's
        integral (m); each (N + E + 1,) float32 at the knots ``u = j h``
        (:func:`return_knots`).

    The speed stays in ``[max(0, v0 - v_max), max(v_max, v0)]``: never more than ``v_max``
    below the script, so the return window (:data:`RETURN_S`) brings back every actor, also one
    scripted faster than its kind's ``v_max`` (a pedestrian braked to a stop from 16 m/s could
    not regain its speed in it).
    """
    h = jnp.float32(knot_s)
    v0 = jnp.asarray(v0, jnp.float32)
    v_hi = jnp.maximum(jnp.float32(lim.v_max), v0)
    v_lo = jnp.maximum(v0 - jnp.float32(lim.v_max), 0.0)
    a_max, b_max = jnp.float32(lim.a_max), jnp.float32(lim.b_max)
    step, lat_max = jnp.float32(lim.lat_rate * float(knot_s)), jnp.float32(lim.lat_max)
    e = return_knots(knot_s)
    act = jnp.concatenate([jnp.ones(accel.shape[-1], bool), jnp.zeros(e, bool)])
    accel = jnp.concatenate([jnp.asarray(accel, jnp.float32), jnp.zeros(e, jnp.float32)])
    lateral = jnp.concatenate([jnp.asarray(lateral, jnp.float32), jnp.zeros(e, jnp.float32)])

    def knot(carry, action):
        v, q = carry
        a, target, acting = action
        a = jnp.where(acting, a, jnp.clip((v0 - v) / h, -b_max, a_max))
        v_next = jnp.clip(v + a * h, v_lo, v_hi)
        q_next = jnp.clip(q + jnp.clip(target - q, -step, step), -lat_max, lat_max)
        return (v_next, q_next), (v_next, q_next)

    zero = jnp.zeros((), jnp.float32)
    _, (v, q) = jax.lax.scan(knot, (v0, zero), (accel, lateral, act))
    v = jnp.concatenate([v0[None], v])
    q = jnp.concatenate([zero[None], q])
    dv = v - v0
    g = jnp.ones_like(v) if lim.holonomic else v
    ds = jnp.concatenate([zero[None], jnp.cumsum(h * 0.5 * (dv[:-1] + dv[1:]))])
    alpha, beta = (g[1:] - g[:-1]) / h, (q[1:] - q[:-1]) / h
    per_knot = _lateral_integral(g[:-1], q[:-1], alpha, beta, h)
    dlat = jnp.concatenate([zero[None], jnp.cumsum(per_knot)])
    return dict(dv=dv, ds=ds, q=q, g=g, dlat=dlat)


def _lateral_integral(g: Array, q: Array, alpha: Array, beta: Array, r: Array) -> Array:
    """``integral_0^r (g + alpha x) (q + beta x) dx`` (exactly 0 when ``q = beta = 0``)."""
    return g * q * r + (g * beta + alpha * q) * r * r / 2.0 + alpha * beta * r * r * r / 3.0


def track_start(trigger: Array, tau: Array, t_event: Array) -> Array:
    """(...) float32, s: when an actor's track starts — its trigger time ``tau``, or the
    physical event ``t_event`` for an actor that never triggers (``NEVER`` until then)."""
    return jnp.where(trigger == TRIGGER_NEVER, t_event, tau).astype(jnp.float32)


def _knot_at(track_h: Array, n: int, u: Array) -> tuple[Array, Array, Array]:
    """Knot index ``k`` in ``[0, n]``, index of its end ``min(k + 1, n)`` and time ``r`` into it."""
    k = jnp.clip(jnp.floor(u / track_h), 0, n).astype(jnp.int32)
    return k, jnp.minimum(k + 1, n), u - k.astype(jnp.float32) * track_h


def scripted_offsets(
    dv: Array, ds: Array, q: Array, g: Array, dlat: Array, knot_s: Array, u: Array
) -> tuple[Array, Array, Array, Array]:
    """Deviations of ONE scripted actor from its script at time ``u`` after its start.

    Args:
        dv, ds, q, g, dlat: (P,) float32, the knot profile (:func:`track_profile`).
        knot_s: () float32, s.
        u: () float32, s, time since the start (the deviations are 0 for ``u <= 0``).

    Returns:
        ``ds`` (m, extra arc), ``dv`` (m/s, extra speed), ``dlat`` (m, extra lateral offset),
        ``w`` (m/s, extra lateral speed); each () float32, exact zeros for all-zero actions.
        Beyond the profile's last knot the speed and the channel hold (both are back to the
        script's by then).
    """
    n = dv.shape[-1] - 1
    h = jnp.asarray(knot_s, jnp.float32)
    started = u > 0.0
    u = jnp.where(started, u, 0.0)
    k, k1, r = _knot_at(h, n, u)
    slope = (dv[k1] - dv[k]) / h
    off_s = ds[k] + dv[k] * r + slope * r * r / 2.0
    off_v = dv[k] + slope * r
    alpha, beta = (g[k1] - g[k]) / h, (q[k1] - q[k]) / h
    off_lat = dlat[k] + _lateral_integral(g[k], q[k], alpha, beta, r)
    w = (g[k] + alpha * r) * (q[k] + beta * r)
    zero = jnp.zeros_like(off_s)
    return tuple(jnp.where(started, x, zero) for x in (off_s, off_v, off_lat, w))


def commanded(accel: Array, q: Array, knot_s: Array, u: Array) -> tuple[Array, Array]:
    """The commanded acceleration and lateral channel of ONE actor at time ``u`` after its start
    (both 0 before the start; the acceleration 0 after the last action knot).

    Args:
        accel: (N,) float32, m/s^2.
        q: (P,) float32, lateral channel at the profile's knots.
        knot_s: () float32, s.
        u: () float32, s.

    Returns:
        ``(a m/s^2, q)``, each () float32.
    """
    n = accel.shape[-1]
    h = jnp.asarray(knot_s, jnp.float32)
    started = u >= 0.0
    u = jnp.where(started, u, 0.0)
    k = jnp.clip(jnp.floor(u / h), 0, n).astype(jnp.int32)
    a = jnp.where(started & (k < n), accel[jnp.minimum(k, n - 1)], 0.0)
    j, j1, r = _knot_at(h, q.shape[-1] - 1, u)
    q_now = jnp.where(started, q[j] + (q[j1] - q[j]) / h * r, 0.0)
    return a, q_now


def zero_track(num: int, knots: int, knot_s: float = 0.5) -> ActorTrack:
    """A track of ``num`` slots and ``knots`` knots with all-zero actions (no effect).

    Args:
        num: slots A.
        knots: knots N (>= 1).
        knot_s: s, knot length.
    """
    z = jnp.zeros((num, knots), jnp.float32)
    zp = jnp.zeros((num, knots + return_knots(knot_s) + 1), jnp.float32)
    one = jnp.ones((num,), jnp.float32)
    limits = dict.fromkeys(("v_max", "a_max", "b_max", "lat_max", "lat_rate"), one)
    return ActorTrack(
        accel=z,
        lateral=z,
        knot_s=one * knot_s,
        holonomic=jnp.zeros((num,), bool),
        dv=zp,
        ds=zp,
        q=zp,
        g=zp,
        dlat=zp,
        **limits,
    )


def set_track(
    track: ActorTrack,
    slot: int,
    kind: int,
    v0: Array,
    u_accel: Array,
    u_lateral: Array,
    knot_s: float,
) -> ActorTrack:
    """``track`` with slot ``slot`` given normalised actions (differentiable in them).

    Args:
        track: the tracks of every slot (A slots, N knots, knot length ``knot_s``).
        slot: static slot index.
        kind: static KIND_* of the actor (its limits, :func:`limits_of_kind`).
        v0: () float32, m/s, the actor's speed at its start (``v_post``).
        u_accel, u_lateral: (N,) float32 in ``[-1, 1]``.
        knot_s: static knot length, s.
    """
    lim = limits_of_kind(kind)
    accel, lateral = scale_actions(u_accel, u_lateral, lim)
    prof = track_profile(accel, lateral, knot_s, v0, lim)
    f32 = jnp.float32
    upd = dict(
        accel=accel,
        lateral=lateral,
        knot_s=f32(knot_s),
        v_max=f32(lim.v_max),
        a_max=f32(lim.a_max),
        b_max=f32(lim.b_max),
        lat_max=f32(lim.lat_max),
        lat_rate=f32(lim.lat_rate),
        holonomic=jnp.asarray(lim.holonomic),
        **prof,
    )
    return track.replace(**{k: getattr(track, k).at[slot].set(v) for k, v in upd.items()})
