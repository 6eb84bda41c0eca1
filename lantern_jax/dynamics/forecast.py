"""Forecast of every actor's box over the next seconds, from the actors' own motion models.

This is privileged knowledge (it reads each actor's script, not what a camera sees); the
simulator computes it only for a policy that asks for it (the ``expert``), see
:mod:`lantern_jax.sim.observe`.  One scenario; the A actor slots and the K forecast times are
vectorised.  Times are ``t + dt * k`` for ``k = 1 .. K``.

* **Scripted actors** (``MOTION_SCRIPTED``) follow their closed form
  (:func:`lantern_jax.dynamics.scripted.scripted_arc`), which is exact: the forecast of a
  scripted actor whose trigger time is known equals its future pose.
* **An event-triggered actor whose event is still pending** may start at any trigger time
  ``tau >= t_earliest``: from the moment the ego has reached the warning point on (the
  protocol's event cannot begin before; see :func:`earliest_event_time`).  Its forecast at
  ``t_k`` is the set of poses over all those trigger times: the segment from the pose it holds
  if it is not triggered (``tau`` never) to the pose it reaches if triggered at
  ``tau = t_earliest``.  Along-path arc and lateral offset are both monotone in ``tau`` for
  every script (``v_post >= v_pre`` or a hold point), so the set lies inside the bounding box
  of those two poses' boxes, taken in the frame of the untriggered pose; that box is reported
  (exact for the straight scenario paths; a slight under-cover of the intermediate headings
  during a lateral manoeuvre).
* **Adversarial tracks** (:mod:`lantern_jax.dynamics.adversary`) are part of the script: a
  scripted actor's forecast follows its track; an IDM actor with a track holds its current
  lateral offset.
* **IDM actors** (``MOTION_IDM``: background traffic, and any walker that is not scripted)
  keep their current speed along their path (PDM-Lite forecasts other vehicles with their last
  control and walkers at constant velocity); clipped at the path end, where a despawning actor
  leaves the forecast.

Cost: the poses of all A x K entries are evaluated twice (untriggered and earliest start), with
components kept in separate (A, K) arrays and unit vectors instead of angles (no trigonometry):
XLA on CPU vectorises that layout far better than trailing axes of 2.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import MOTION_IDM, TRIGGER_EVENT
from lantern_jax.core.times import NEVER, happened
from lantern_jax.dynamics.scripted import ScriptedMotion, scripted_arc, trigger_time
from lantern_jax.types.world import ActorScript, ActorState

Array = jax.Array


@struct.dataclass
class ActorForecast:
    """Forecast boxes of every actor slot (world frame), one array per component (XLA
    vectorises (A, K) arrays far better than a trailing axis of 2)."""

    x: Array  # (A, K) float32, m, box centre at t + dt * (k + 1)
    y: Array  # (A, K) float32, m
    ux: Array  # (A, K) float32, unit vector along the box length
    uy: Array  # (A, K) float32
    half_length: Array  # (A, K) float32, m, of the (swept) box
    half_width: Array  # (A, K) float32, m
    speed: Array  # (A, K) float32, m/s, speed of the fastest pose of the box
    valid: Array  # (A, K) bool, the actor is (may be) in the world then


def earliest_event_time(
    t: Array, t_warn_point: Array, t_event: Array, force_event: Array = True
) -> Array:
    """() float32, s: the earliest time the protocol's event can begin, seen from ``t``.

    The event never begins before the ego reaches the warning point (the geometric trigger
    lies at or beyond it and the anti-deadlock countdown starts there) and, with the
    anti-deadlock rule on, may begin at any moment after: so ``t_event`` once it happened,
    ``t`` (now) once the warning point has been reached, and ``NEVER`` before.  A waiting
    hazard is thus forecast as waiting until the protocol makes its start possible, not from an
    extrapolation of the ego's own arrival.  Without the rule (``force_event`` False: open-loop
    data collection, Right-Turn Yield) only the ego's own arrival at the event point starts it,
    so a pending event stays ``NEVER`` (a waiting ego would otherwise wait for itself).

    Args:
        t: () float32, s, now.
        t_warn_point: () float32, s, ego reached the warning point (``NEVER`` if not).
        t_event: () float32, s, event onset (``NEVER`` if pending).
        force_event: () bool, the anti-deadlock rule may start the event.
    """
    out = jnp.where(happened(t_warn_point) & force_event, t, NEVER)
    return jnp.where(happened(t_event), t_event, out).astype(jnp.float32)


def _places(script: ActorScript, times: Array, tau: Array) -> tuple[Array, ...]:
    """Scripted (s, lat, v_long, v_lat, active) of every slot at every time, each (A, K)."""
    motion = ScriptedMotion.of(script)
    if script.track is None:
        per_actor = jax.vmap(scripted_arc, in_axes=(0, None, 0))

        def at(tk):
            return per_actor(motion, tk, tau)
    else:  # the track is part of the script: the forecast follows it (exact once tau is known)
        tr = script.track
        per_actor = jax.vmap(scripted_arc, in_axes=(0, None, 0, 0))

        def at(tk):
            return per_actor(motion, tk, tau, (tr.dv, tr.ds, tr.q, tr.g, tr.dlat, tr.knot_s))

    return tuple(jnp.swapaxes(x, 0, 1) for x in jax.vmap(at)(times))


def _segments(script: ActorScript) -> tuple[Array, ...]:
    """Per-slot path segments: start x, start y, unit x, unit y, start arc, each (A, P - 1);
    degenerate segments point along +x (as :func:`lantern_jax.maths.polyline.interpolate`)."""
    p, ps, pv = script.path, script.path_s, script.path_valid
    dx, dy = p[:, 1:, 0] - p[:, :-1, 0], p[:, 1:, 1] - p[:, :-1, 1]
    n2 = dx * dx + dy * dy
    ok = pv[:, 1:] & pv[:, :-1] & (n2 > 1e-12)
    inv = jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)
    return p[:, :-1, 0], p[:, :-1, 1], jnp.where(ok, dx * inv, 1.0), dy * inv, ps[:, :-1]


def _pose(script: ActorScript, s: Array, lat: Array, v_long: Array, v_lat: Array):
    """Centre x, y and unit heading x, y (each (A, K)) of every slot at arcs ``s`` (A, K).

    The point at arc ``s`` of a slot's path (linear extension beyond its ends, as
    :func:`lantern_jax.maths.polyline.interpolate`), offset ``lat`` to the left of travel; the
    heading follows the velocity ``(v_long, v_lat)`` in the path frame.  Components are kept
    apart (x and y arrays) so that XLA vectorises over the (A, K) grid.
    """
    x0, y0, ux, uy, s0 = _segments(script)
    # The barrier shields the arcs from the algebraic simplifier; it does not stop XLA on CPU
    # from fusing them into the (A, K, P) search below (expanded before fusion, see split_map).
    s, lat, v_long, v_lat = jax.lax.optimization_barrier((s, lat, v_long, v_lat))
    n = jnp.sum(script.path_valid.astype(jnp.int32), -1)  # (A,)
    passed = jnp.sum(
        (script.path_valid[:, None, 1:] & (script.path_s[:, None, 1:] <= s[..., None])), -1
    )  # (A, K)
    i = jnp.clip(passed, 0, jnp.maximum(n - 2, 0)[:, None])

    def take(a):
        return jnp.take_along_axis(a, i, axis=1)

    sx, sy, tx, ty, sa = take(x0), take(y0), take(ux), take(uy), take(s0)
    along = s - sa
    cx = sx + along * tx - ty * lat
    cy = sy + along * ty + tx * lat
    vx = tx * v_long - ty * v_lat
    vy = ty * v_long + tx * v_lat
    n2 = vx * vx + vy * vy
    moving = n2 > 1e-12
    inv = jnp.where(moving, 1.0 / jnp.sqrt(jnp.where(moving, n2, 1.0)), 0.0)
    return cx, cy, jnp.where(moving, vx * inv, tx), jnp.where(moving, vy * inv, ty)


def _union_box(lo, hi, hl, hw):
    """Bounding box, in the frame of the ``lo`` box, of the ``lo`` and ``hi`` boxes.

    Args:
        lo, hi: (cx, cy, ux, uy) of two boxes with the same half extents, each (...) float32
            (centre m, unit heading).
        hl, hw: (...) float32, m, the actor's half length and half width.

    Returns:
        (cx, cy, ux, uy, half length, half width) of the union box, each (...).
    """
    cx, cy, ux, uy = lo
    nx, ny = -uy, ux
    dx, dy = hi[0] - cx, hi[1] - cy
    dl, dw = dx * ux + dy * uy, dx * nx + dy * ny
    cos = jnp.abs(hi[2] * ux + hi[3] * uy)
    sin = jnp.abs(hi[2] * nx + hi[3] * ny)
    el, ew = hl * cos + hw * sin, hl * sin + hw * cos  # hi box projected on the lo axes
    lo_l, hi_l = jnp.minimum(-hl, dl - el), jnp.maximum(hl, dl + el)
    lo_w, hi_w = jnp.minimum(-hw, dw - ew), jnp.maximum(hw, dw + ew)
    ml, mw = 0.5 * (lo_l + hi_l), 0.5 * (lo_w + hi_w)
    return (cx + ux * ml + nx * mw, cy + uy * ml + ny * mw, ux, uy,
            0.5 * (hi_l - lo_l), 0.5 * (hi_w - lo_w))  # fmt: skip


def forecast_actors(
    script: ActorScript,
    actors: ActorState,
    present: Array,
    t: Array,
    t_event: Array,
    t_earliest: Array,
    steps: int,
    dt: float,
) -> ActorForecast:
    """Forecast every actor slot over ``steps`` times ``dt`` apart (see the module docstring).

    Args:
        script: (A,) slots: paths, motion models and scripts.
        actors: (A,) actor states now.
        present: (A,) bool, actors in the world now (others are not forecast: ``valid`` False).
        t: () float32, s, now.
        t_event: () float32, s, event onset (``NEVER`` while pending).
        t_earliest: () float32, s, earliest possible event onset (:func:`earliest_event_time`).
        steps: static number of forecast times K.
        dt: static spacing of the forecast times, s.

    Returns:
        :class:`ActorForecast` with (A, K) leading axes.
    """
    times = t + dt * jnp.arange(1, steps + 1, dtype=jnp.float32)  # (K,)
    tau_known = trigger_time(script.trigger, script.trigger_delay, t_event)  # (A,)
    pending = (script.trigger == TRIGGER_EVENT) & ~happened(t_event)
    early = jnp.where(happened(t_earliest), t_earliest + script.trigger_delay, NEVER)
    tau_hi = jnp.where(pending, early, tau_known).astype(jnp.float32)
    tau_lo = jnp.where(pending, NEVER, tau_known).astype(jnp.float32)
    lo = _places(script, times, tau_lo)
    hi = _places(script, times, tau_hi)

    # IDM actors: current speed along the path, stopped at the path end.
    idm = (script.motion == MOTION_IDM)[:, None]
    v_now = jnp.maximum(actors.speed, 0.0)[:, None]
    s_idm = jnp.minimum(actors.s[:, None] + v_now * (times - t)[None, :], script.s_end[:, None])
    reached = s_idm >= script.s_end[:, None]
    v_idm = jnp.where(reached, 0.0, v_now)
    alive_idm = ~(script.despawn_at_end[:, None] & reached)

    def pick(idm_value, scripted_value):
        return jnp.where(idm, idm_value, scripted_value)

    zero = jnp.zeros_like(s_idm)
    lat_idm = zero
    if script.track is not None:  # an IDM actor with a track holds its lateral offset
        lat_idm = jnp.broadcast_to(actors.lat[:, None], s_idm.shape)
    pose_lo = _pose(script, pick(s_idm, lo[0]), pick(lat_idm, lo[1]), pick(v_idm, lo[2]),
                    pick(zero, lo[3]))  # fmt: skip
    pose_hi = _pose(script, pick(s_idm, hi[0]), pick(lat_idm, hi[1]), pick(v_idm, hi[2]),
                    pick(zero, hi[3]))  # fmt: skip
    hl, hw = script.extent[:, 0:1], script.extent[:, 1:2]
    cx, cy, ux, uy, el, ew = _union_box(pose_lo, pose_hi, hl, hw)
    speed_lo = jnp.sqrt(lo[2] ** 2 + lo[3] ** 2)
    speed_hi = jnp.sqrt(hi[2] ** 2 + hi[3] ** 2)
    speed = pick(v_idm, jnp.maximum(speed_lo, speed_hi))
    alive = pick(alive_idm, lo[4] | hi[4])
    valid = present[:, None] & script.valid[:, None] & alive
    return ActorForecast(
        x=cx,
        y=cy,
        ux=ux,
        uy=uy,
        half_length=el,
        half_width=ew,
        speed=speed,
        valid=valid,
    )
