"""What a policy observes at one tick (one scenario).

All positions and vectors are in the **ego frame of the paper: x forward, y to the right**,
metres, relative to the ego box centre.  Perception masks:

* ``visible`` — the front camera (110 deg frustum + unobstructed ray) sees the actor now;
  onboard policies must only use actors with ``visible``.
* ``present`` — the actor exists in the world (privileged; only the ``expert`` uses it).
"""

from __future__ import annotations

import jax
from flax import struct

Array = jax.Array

NUM_ROUTE_POINTS = 24  # route points ahead in the observation
ROUTE_STEP = 2.0  # m between observed route points
NUM_RANGE_RAYS = 32  # rays of the front-camera range image


@struct.dataclass
class Observation:
    """One tick of policy input (no batch axis)."""

    ego_speed: Array  # () float32, m/s
    ego_accel: Array  # () float32, m/s^2, last applied longitudinal acceleration
    ego_steer: Array  # () float32, rad, front-wheel angle (+ = left)
    v_ref: Array  # () float32, m/s, route reference speed (speed limit of the scenario)
    route: Array  # (NUM_ROUTE_POINTS, 2) float32, m, route centre-line ahead, ROUTE_STEP apart,
    #               starting at the ego's projection onto the route
    target_points: Array  # (2, 2) float32, m, navigation targets 10 m and 30 m ahead on the route
    dist_to_route_end: Array  # () float32, m
    actor_xy: Array  # (A, 2) float32, m, actor box centres
    actor_vel: Array  # (A, 2) float32, m/s, actor velocities
    actor_dir: Array  # (A, 2) float32, unit heading vectors of the actors
    actor_extent: Array  # (A, 2) float32, m, (half length, half width)
    actor_kind: Array  # (A,) int32, KIND_*
    visible: Array  # (A,) bool, seen by the front camera now
    present: Array  # (A,) bool, privileged: exists in the world
    range_image: Array  # (NUM_RANGE_RAYS,) float32, m, front-camera ray ranges (capped)
    light_state: Array  # () int32, LIGHT_* of the ego's traffic light (GREEN when none)
    dist_to_stop: Array  # () float32, m, route distance from the ego centre to its stop line
    warning_active: Array  # () bool, a cooperative warning is being delivered now
    warning_text_id: Array  # () int32, text-bank id of the warning (-1 when inactive)
    warning_pos: Array  # (2,) float32, m, grounded <FRONT_CAR_POS> (zeros when inactive)
