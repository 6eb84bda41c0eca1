"""Stateless waypoint-tracking controller: plan (10 ego-frame waypoints) -> (steer, accel).

Waypoint convention (the policy interface): ``waypoints[k]`` is the planned position of the ego
box centre at ``t + WAYPOINT_DT * (k + 1)`` in the ego frame, x forward, y to the **right**,
metres.  Internally the controller flips y to point left (counter-clockwise, as the world frame).

Lateral (pure pursuit for a centre-referenced bicycle):

* the plan path is the polyline ``origin -> waypoints[0] -> ... -> waypoints[9]``;
* the target is the point at arc ``min(lookahead, path length)`` along it, with the PDM-Lite
  lookahead ``clip(0.1 * (0.9755 * v[km/h] + 1.915), 2.4, 10.5)`` m;
* the box centre moves along ``yaw + beta`` with ``tan(beta) = lr / L * tan(steer)``
  (:mod:`lantern_jax.dynamics.bicycle`) on a circle of curvature ``sin(beta) / lr``.  The wheel
  angle is chosen so that this circle, tangent to the centre's velocity, passes through the
  target at bearing ``theta`` and distance ``d``: ``2 sin(theta - beta) / d = sin(beta) / lr``,
  i.e. ``tan(beta) = 2 lr sin(theta) / (d + 2 lr cos(theta))`` and
  ``steer = atan(L / lr * tan(beta))``.  It depends on the target only (not on the current
  wheel angle), so there is no tick-to-tick feedback through the slip angle; ``d`` is floored
  at 1 m;
* a plan shorter than 0.25 m (stopping, standing) keeps the current wheel angle.

Longitudinal (proportional speed control with feed-forward, no integral state):

* planned speed at ~0.75 s (SimLingo): ``v_des = |wp[3] - wp[1]| / 0.5``;
* planned acceleration: ``a_ff = (|wp[3] - wp[2]| - |wp[1] - wp[0]|) / 0.25 / 0.5`` (difference
  of the segment speeds at 0.875 s and 0.375 s);
* planned speed now: ``v_ref = v_des - 0.75 a_ff``;
* ``accel = clip(a_ff + K_SPEED (v_ref - v), -brake_limit(friction), EGO_MAX_ACCEL)`` — a
  constant-speed plan gives 0, a constant-deceleration plan gives exactly its deceleration, and
  bunched waypoints (``v_des`` far below ``v``) reach the full friction-limited deceleration;
* SimLingo's brake rule, ``v_des < STOP_SPEED`` (0.4 m/s), commands full braking (stop and
  hold) when the end of the plan is slow as well (``|wp[9] - wp[7]| / 0.5 < STOP_SPEED``), so a
  gentle start from standstill (planned speed still below 0.4 m/s at 0.75 s) is not held back.

There is no integral term: the bicycle has no drag or grade, so proportional control has no
steady-state error, and a stateless controller keeps a rollout step a pure function of the world.

Faults: non-finite waypoints, or a plan faster than
:data:`~lantern_jax.core.constants.MAX_PLAN_SPEED` (:func:`waypoints_fault`), make both outputs NaN
(computed from zeroed waypoints, so no NaN
reaches a gradient); :func:`lantern_jax.dynamics.bicycle.sanitize_controls` then turns them into
full braking and reports the fault.  :func:`waypoints_fault` gives the same flag directly.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import (
    BIG,
    EGO_MAX_ACCEL,
    EGO_MAX_STEER,
    EGO_WHEELBASE,
    MAX_PLAN_SPEED,
    WAYPOINT_DT,
)
from lantern_jax.dynamics.bicycle import EGO_LR, bicycle_step, brake_limit, sanitize_controls
from lantern_jax.maths.geometry import safe_norm
from lantern_jax.maths.polyline import arc_length, interpolate, safe_atan2
from lantern_jax.types.world import EgoState

Array = jax.Array

K_SPEED = 2.0  # 1/s, proportional gain of the speed loop
STOP_SPEED = 0.4  # m/s, plans slower than this (at 0.75 s and at the end) brake fully
LOOKAHEAD_MIN = 2.4  # m
LOOKAHEAD_MAX = 10.5  # m
MIN_PLAN_LENGTH = 0.25  # m, shorter plans keep the current wheel angle
MIN_TARGET_DISTANCE = 1.0  # m, floor of the pursuit chord (short plans)
MAX_BETA = 1.2  # rad, slip-angle clip before the steering limit (targets behind the car)


def lookahead_distance(speed: Array) -> Array:
    """PDM-Lite lookahead ``0.1 m * (0.9755 v[km/h] + 1.915)`` clipped to [2.4, 10.5] m.

    Args:
        speed: () float32, m/s.

    Returns:
        () float32, m.
    """
    return jnp.clip(0.1 * (0.9755 * 3.6 * speed + 1.915), LOOKAHEAD_MIN, LOOKAHEAD_MAX)


def waypoints_fault(waypoints: Array) -> Array:
    """Whether a plan is unusable: any NaN or infinite coordinate, or a leg (the ego to the
    first waypoint, or one waypoint to the next) faster than
    :data:`~lantern_jax.core.constants.MAX_PLAN_SPEED` (a plan in other units, or scaled).

    Args:
        waypoints: (N, 2) float32, m, ego frame, ``WAYPOINT_DT`` apart.

    Returns:
        () bool.
    """
    finite = jnp.isfinite(waypoints)
    wp = jnp.where(finite, waypoints, 0.0)
    pts = jnp.concatenate([jnp.zeros((1, 2), wp.dtype), wp], axis=0)
    leg2 = jnp.sum(jnp.square(pts[1:] - pts[:-1]), axis=-1)  # m^2 (inf where it overflows)
    too_fast = jnp.any(leg2 > (MAX_PLAN_SPEED * WAYPOINT_DT) ** 2)
    return ~jnp.all(finite) | too_fast


def desired_speed(waypoints: Array) -> Array:
    """SimLingo desired speed: distance between the waypoints at 0.5 s and 1.0 s over 0.5 s.

    Args:
        waypoints: (N >= 4, 2) float32, m, 0.25 s apart starting at +0.25 s.

    Returns:
        () float32, m/s.
    """
    return safe_norm(waypoints[3] - waypoints[1]) / (2.0 * WAYPOINT_DT)


def track_waypoints(ego: EgoState, waypoints: Array, friction: Array) -> tuple[Array, Array]:
    """Controls that track a waypoint plan.

    Args:
        ego: current ego state (uses ``speed`` and ``steer``).
        waypoints: (10, 2) float32, m, ego frame (x forward, y right), waypoint ``k`` at
            ``t + 0.25 (k + 1)`` s.  All zeros = stop here.
        friction: () float32, tyre-road friction coefficient (sets the braking limit).

    Returns:
        steer_cmd: () float32, rad, front-wheel angle, + = left, within ``+-EGO_MAX_STEER``
            (NaN when the plan is non-finite).
        accel_cmd: () float32, m/s^2, within ``[-brake_limit(friction), EGO_MAX_ACCEL]`` (NaN
            when the plan is non-finite).
    """
    fault = waypoints_fault(waypoints)
    wp = jnp.where(jnp.isfinite(waypoints), waypoints, 0.0).astype(jnp.float32)
    wp = wp * jnp.array([1.0, -1.0], jnp.float32)  # y right -> y left
    speed = jnp.maximum(ego.speed, 0.0)

    # --- lateral: pure pursuit on the plan path ------------------------------------------------
    pts = jnp.concatenate([jnp.zeros((1, 2), jnp.float32), wp], axis=0)
    valid = jnp.ones((pts.shape[0],), bool)
    s = arc_length(pts, valid)
    length = s[-1]
    look = lookahead_distance(speed)
    target, _ = interpolate(pts, s, valid, jnp.minimum(look, length))
    dist = jnp.maximum(safe_norm(target), MIN_TARGET_DISTANCE)
    theta = safe_atan2(target[1], target[0])
    beta = jnp.arctan2(
        2.0 * EGO_LR * jnp.sin(theta), dist + 2.0 * EGO_LR * jnp.cos(theta)
    )  # denominator > 0 for targets ahead; targets behind saturate the steering
    beta = jnp.clip(beta, -MAX_BETA, MAX_BETA)
    steer = jnp.arctan(EGO_WHEELBASE / EGO_LR * jnp.tan(beta))
    steer = jnp.where(length >= MIN_PLAN_LENGTH, steer, ego.steer)
    steer = jnp.clip(steer, -EGO_MAX_STEER, EGO_MAX_STEER)

    # --- longitudinal: P speed control with feed-forward ---------------------------------------
    v_des = desired_speed(wp)
    v_early = safe_norm(wp[1] - wp[0]) / WAYPOINT_DT  # planned speed at ~0.375 s
    v_late = safe_norm(wp[3] - wp[2]) / WAYPOINT_DT  # planned speed at ~0.875 s
    a_ff = (v_late - v_early) / (2.0 * WAYPOINT_DT)
    v_ref = v_des - 3.0 * WAYPOINT_DT * a_ff
    max_brake = brake_limit(friction)
    accel = jnp.clip(a_ff + K_SPEED * (v_ref - speed), -max_brake, EGO_MAX_ACCEL)
    v_end = safe_norm(wp[9] - wp[7]) / (2.0 * WAYPOINT_DT)  # planned speed at ~2.25 s
    hold = jnp.maximum(v_des, v_end) < STOP_SPEED
    accel = jnp.where(hold, -max_brake, accel)

    nan = jnp.float32(jnp.nan)
    return jnp.where(fault, nan, steer), jnp.where(fault, nan, accel)


def follow_plan(ego: EgoState, waypoints: Array, friction: Array) -> tuple[EgoState, Array, Array]:
    """One tick of the ego driving a plan: controller, fault handling, bicycle.

    An unusable plan (non-finite, or faster than :data:`~lantern_jax.core.constants.MAX_PLAN_SPEED`:
    :func:`waypoints_fault`) or non-finite controls are a controller fault: the ego brakes fully
    (friction limited) and keeps its wheel angle; the fault is returned, never propagated as NaN.

    Args:
        ego: the ego at the start of the tick.
        waypoints: (10, 2) float32, m, ego frame (x forward, y right), as the policy returned them.
        friction: () float32, tyre-road friction coefficient.

    Returns:
        ego: the ego at the end of the tick.
        fault: () bool, the plan or the controls were not finite.
        safe_waypoints: (10, 2) float32, m, the waypoints with a faulty plan replaced by zeros.
    """
    wp_fault = waypoints_fault(waypoints)
    safe = jnp.where(wp_fault, 0.0, waypoints)
    steer_cmd, accel_cmd = track_waypoints(ego, safe, friction)
    steer_cmd, accel_cmd, ctl_fault = sanitize_controls(steer_cmd, accel_cmd)
    fault = wp_fault | ctl_fault
    accel_cmd = jnp.where(fault, -BIG, accel_cmd)  # full (friction-limited) braking
    steer_cmd = jnp.where(fault, ego.steer, steer_cmd)
    return bicycle_step(ego, steer_cmd, accel_cmd, friction), fault, safe
