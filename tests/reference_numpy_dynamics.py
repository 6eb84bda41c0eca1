"""Slow, loop-based float64 NumPy reference for the ego bicycle and polyline projection.

Written independently of the vectorised JAX code and with different algorithms:

* bicycle: the kinematic-bicycle ODE integrated with many small RK4 sub-steps (the JAX step
  uses the exact circular arc of each tick);
* projection: a loop over segments keeping the best one, with explicit end extrapolation.
"""

from __future__ import annotations

import math

import numpy as np

WHEELBASE = 2.85
LR = 0.5 * WHEELBASE
MAX_STEER = 0.3685
MAX_STEER_RATE = 0.7
MAX_ACCEL = 3.0
MAX_BRAKE = 8.0
GRAVITY = 9.81


def bicycle_step(state: dict, steer_cmd: float, accel_cmd: float, friction: float, dt: float,
                 substeps: int = 200) -> dict:  # fmt: skip
    """One tick of the centre-referenced kinematic bicycle, ODE integrated by RK4 sub-steps.

    ``state`` has keys x, y, yaw, speed, steer (floats).  Returns a new dict with accel added.
    """
    if not (math.isfinite(steer_cmd) and math.isfinite(accel_cmd)):
        steer_cmd, accel_cmd = 0.0, -MAX_BRAKE
    target = min(max(steer_cmd, -MAX_STEER), MAX_STEER)
    delta = target - state["steer"]
    step = MAX_STEER_RATE * dt
    delta = min(max(delta, -step), step)
    steer = min(max(state["steer"] + delta, -MAX_STEER), MAX_STEER)

    brake = min(MAX_BRAKE, max(friction, 0.0) * GRAVITY)
    accel = min(max(accel_cmd, -brake), MAX_ACCEL)
    beta = math.atan(LR / WHEELBASE * math.tan(steer))

    def deriv(z):
        x, y, yaw, v = z
        v = max(v, 0.0)
        return np.array(
            [v * math.cos(yaw + beta), v * math.sin(yaw + beta), v * math.sin(beta) / LR, 0.0]
        )

    z = np.array([state["x"], state["y"], state["yaw"], state["speed"]], float)
    h = dt / substeps
    for _ in range(substeps):
        # speed evolves in closed form (clamped at zero); RK4 for the pose
        v0 = z[3]
        v1 = max(v0 + accel * h, 0.0)
        vm = max(v0 + 0.5 * accel * h, 0.0)
        k1 = deriv(np.array([z[0], z[1], z[2], v0]))
        k2 = deriv(np.array([*(z[:3] + 0.5 * h * k1[:3]), vm]))
        k3 = deriv(np.array([*(z[:3] + 0.5 * h * k2[:3]), vm]))
        k4 = deriv(np.array([*(z[:3] + h * k3[:3]), v1]))
        z[:3] = z[:3] + h / 6.0 * (k1[:3] + 2 * k2[:3] + 2 * k3[:3] + k4[:3])
        z[3] = v1
    yaw = (z[2] + math.pi) % (2 * math.pi) - math.pi
    return {
        "x": z[0],
        "y": z[1],
        "yaw": yaw,
        "speed": z[3],
        "steer": steer,
        "accel": (z[3] - state["speed"]) / dt,
    }


def project(points, n_valid: int, query) -> tuple[float, float, float, float, float]:
    """Project ``query`` onto the first ``n_valid`` points of ``points``.

    Returns (arc, lateral (+ left), heading of the nearest segment, distance to the polyline,
    margin = distance to the second-nearest segment minus the distance; a near-zero margin
    means the nearest segment is ambiguous, e.g. the query is nearest to a shared vertex).
    """
    pts = np.asarray(points, float)[:n_valid]
    q = np.asarray(query, float)
    if n_valid < 2:
        return 0.0, 0.0, 0.0, float(np.hypot(*(q - pts[0]))), math.inf
    cum = [0.0]
    for i in range(n_valid - 1):
        cum.append(cum[-1] + float(np.hypot(*(pts[i + 1] - pts[i]))))
    best = None
    dists = []
    for i in range(n_valid - 1):
        a, b = pts[i], pts[i + 1]
        length = float(np.hypot(*(b - a)))
        if length <= 1e-9:
            t, u = 0.0, np.zeros(2)
        else:
            u = (b - a) / length
            t = float((q - a) @ u) / length
        tc = min(max(t, 0.0), 1.0)
        closest = a + tc * (b - a)
        dist = float(np.hypot(*(q - closest)))
        dists.append(dist)
        if best is None or dist < best[0]:
            best = (dist, i, t, u, length)
    dist, i, t, u, length = best
    if i > 0:
        t = max(t, 0.0)
    if i < n_valid - 2:
        t = min(t, 1.0)
    rel = q - pts[i]
    lateral = float(u[0] * rel[1] - u[1] * rel[0])
    heading = math.atan2(u[1], u[0]) if length > 1e-9 else 0.0
    margin = sorted(dists)[1] - dist if len(dists) > 1 else math.inf
    return cum[i] + t * length, lateral, heading, dist, margin
