"""Ego kinematic bicycle (reference point = box centre) and control sanitising.

Model (centre-referenced kinematic bicycle, centre of the box halfway between the axles,
``lr = lf = L / 2`` with ``L = EGO_WHEELBASE``)::

    beta      = atan(lr / L * tan(delta))          slip angle of the centre's velocity
    d(yaw)/dt = v * sin(beta) / lr                 (= v * cos(beta) * tan(delta) / L)
    d(xy)/dt  = v * (cos(yaw + beta), sin(yaw + beta))

At a constant wheel angle ``delta`` the instantaneous centre of rotation lies on the rear-axle
line, ``L / tan(delta)`` from the rear axle, and the box centre is ``lr`` ahead of the rear axle,
so the centre moves on a circle of radius::

    R(delta) = lr / sin(beta) = sqrt(lr^2 + (L / tan(delta))^2)

(``turning_radius``).  With ``EGO_MAX_STEER = 0.3685 rad`` this is ~7.52 m.

Integration over one tick ``dt``: the steering angle is first moved toward the command at no more
than ``EGO_MAX_STEER_RATE`` and clipped to ``+-EGO_MAX_STEER``, then held for the tick; the
acceleration command is clipped to ``[-min(EGO_MAX_BRAKE, friction * GRAVITY), EGO_MAX_ACCEL]``
and held; the speed is integrated exactly (``v' = max(v + a dt, 0)``, stopping mid-tick when the
speed would go negative — no reversing) and the path over the tick is the exact circular arc of
constant curvature ``sin(beta) / lr`` with the distance travelled.  So a constant wheel angle
traces exactly the circle ``R(delta)`` whatever the speed profile, and braking from ``v`` at the
friction limit stops after exactly ``v^2 / (2 mu g)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import (
    DT,
    EGO_MAX_ACCEL,
    EGO_MAX_BRAKE,
    EGO_MAX_STEER,
    EGO_MAX_STEER_RATE,
    EGO_WHEELBASE,
    GRAVITY,
)
from lantern_jax.types.world import EgoState

Array = jax.Array

EGO_LR = 0.5 * EGO_WHEELBASE  # m, box centre to rear axle


def slip_angle(steer: Array) -> Array:
    """Slip angle of the box centre for a front-wheel angle.

    Args:
        steer: (...) float32, rad, front-wheel angle, + = left.

    Returns:
        (...) float32, rad, ``atan(lr / L * tan(steer))``.
    """
    return jnp.arctan(EGO_LR / EGO_WHEELBASE * jnp.tan(steer))


def turning_radius(steer: Array) -> Array:
    """Radius of the circle traced by the box centre, ``sqrt(lr^2 + (L / tan(steer))^2)``.

    Args:
        steer: (...) float32, rad, non-zero.

    Returns:
        (...) float32, m, unsigned (inf for ``steer = 0``).
    """
    return jnp.sqrt(EGO_LR**2 + (EGO_WHEELBASE / jnp.tan(steer)) ** 2)


def brake_limit(friction: Array) -> Array:
    """Largest deceleration the brakes can apply on a road with this friction.

    Args:
        friction: () float32, tyre-road friction coefficient.

    Returns:
        () float32, m/s^2, ``min(EGO_MAX_BRAKE, friction * GRAVITY)`` (>= 0).
    """
    return jnp.minimum(EGO_MAX_BRAKE, jnp.maximum(friction, 0.0) * GRAVITY)


def longitudinal_step(speed: Array, accel: Array, dt: float = DT) -> tuple[Array, Array]:
    """Exact constant-acceleration step that stops at zero speed (no reversing).

    Args:
        speed: (...) float32, m/s, >= 0.
        accel: (...) float32, m/s^2, held for the step.
        dt: step, s.

    Returns:
        distance: (...) float32, m, travelled during the step (>= 0).
        speed_next: (...) float32, m/s, ``max(speed + accel * dt, 0)``.
    """
    v1 = speed + accel * dt
    stops = v1 < 0.0
    speed_next = jnp.maximum(v1, 0.0)
    decel = jnp.where(stops, -accel, 1.0)  # > 0 wherever it is used
    distance = jnp.where(stops, 0.5 * speed * speed / decel, 0.5 * (speed + speed_next) * dt)
    return jnp.maximum(distance, 0.0), speed_next


def sanitize_controls(steer_cmd: Array, accel_cmd: Array) -> tuple[Array, Array, Array]:
    """Replace non-finite controls by a safe command and flag the fault.

    If either command is NaN or infinite, both are replaced: steering 0 (straight) and full
    braking ``-EGO_MAX_BRAKE`` (the bicycle then applies its friction limit).

    Args:
        steer_cmd: () float32, rad, requested front-wheel angle.
        accel_cmd: () float32, m/s^2, requested longitudinal acceleration.

    Returns:
        steer: () float32, rad.
        accel: () float32, m/s^2.
        fault: () bool, True when the commands were replaced.
    """
    steer_cmd = jnp.asarray(steer_cmd, jnp.float32)
    accel_cmd = jnp.asarray(accel_cmd, jnp.float32)
    fault = ~(jnp.isfinite(steer_cmd) & jnp.isfinite(accel_cmd))
    steer = jnp.where(fault, 0.0, steer_cmd)
    accel = jnp.where(fault, -EGO_MAX_BRAKE, accel_cmd)
    return steer, accel, fault


def bicycle_step(
    ego: EgoState, steer_cmd: Array, accel_cmd: Array, friction: Array, dt: float = DT
) -> EgoState:
    """Advance the ego by one tick.

    Non-finite commands are sanitised (see :func:`sanitize_controls`), so the returned state is
    always finite; call :func:`sanitize_controls` yourself to record the fault.

    Args:
        ego: current state (box centre reference).
        steer_cmd: () float32, rad, requested front-wheel angle, + = left.
        accel_cmd: () float32, m/s^2, requested longitudinal acceleration.
        friction: () float32, tyre-road friction coefficient (limits braking).
        dt: tick, s.

    Returns:
        The state after ``dt``; ``steer`` is the rate- and angle-limited wheel angle used during
        the tick and ``accel`` the realised acceleration ``(speed' - speed) / dt`` (0 when held
        at standstill).
    """
    steer_cmd, accel_cmd, _ = sanitize_controls(steer_cmd, accel_cmd)
    target = jnp.clip(steer_cmd, -EGO_MAX_STEER, EGO_MAX_STEER)
    max_delta = EGO_MAX_STEER_RATE * dt
    steer = ego.steer + jnp.clip(target - ego.steer, -max_delta, max_delta)
    steer = jnp.clip(steer, -EGO_MAX_STEER, EGO_MAX_STEER)

    accel = jnp.clip(accel_cmd, -brake_limit(friction), EGO_MAX_ACCEL)
    speed0 = jnp.maximum(ego.speed, 0.0)
    distance, speed = longitudinal_step(speed0, accel, dt)

    beta = slip_angle(steer)
    dyaw = distance * jnp.sin(beta) / EGO_LR
    # chord of a circular arc of length `distance` turning by `dyaw`
    chord = distance * jnp.sinc(0.5 * dyaw / jnp.pi)
    direction = ego.yaw + beta + 0.5 * dyaw
    xy = ego.xy + chord * jnp.stack([jnp.cos(direction), jnp.sin(direction)])
    yaw = ego.yaw + dyaw
    yaw = jnp.arctan2(jnp.sin(yaw), jnp.cos(yaw))
    return EgoState(
        xy=xy.astype(jnp.float32),
        yaw=yaw.astype(jnp.float32),
        speed=speed.astype(jnp.float32),
        steer=steer.astype(jnp.float32),
        accel=((speed - speed0) / dt).astype(jnp.float32),
    )
