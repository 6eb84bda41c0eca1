"""What a policy observes at one tick (one scenario).

The simulator (:mod:`lantern_jax.sim.observe`) produces it and every policy reads it, so the type
lives below both.

All positions and vectors are in the **ego frame of the paper: x forward, y to the right**,
metres, relative to the ego box centre.  Perception masks:

* ``visible`` — the front camera (110 deg frustum + unobstructed ray) sees the actor now;
  onboard policies must only use actors with ``visible``.
* ``present`` — the actor exists in the world (privileged; only the ``expert`` uses it).

The cooperative warning reaches a policy as language: ``warning_tokens`` are the token ids of
the delivered text's template (:mod:`lantern_jax.language`: fixed length, ``PAD_ID`` padding, a
``PLACEHOLDER_ID`` token where ``<FRONT_CAR_POS>`` stands), ``warning_pos`` the grounded position
as numbers and ``warning_has_position`` whether the text states one at all (a high-ambiguity
paraphrase or a non-actionable message does not: then ``warning_pos`` is zero and must not be
read as a position).  ``render_warning(warning_text_id, warning_pos)`` gives the exact string.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.constants import EGO_HALF_LENGTH
from lantern_jax.polyline import project_uniform

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
    warning_pos: Array  # (2,) float32, m, grounded <FRONT_CAR_POS> (zeros when inactive or when
    #                     the text states no position)
    warning_has_position: Array  # () bool, the delivered text states a position (False when
    #                              inactive)
    warning_tokens: Array  # (MAX_TOKENS,) int32, token ids of the delivered template (all
    #                        PAD_ID when inactive)


def corridor_gaps(obs: Observation) -> tuple[Array, Array]:
    """Route gap ahead of the ego and lateral distance from the route of every actor.

    Uses the observation's route points ahead of the ego and the actors in the ego frame, so the
    projection runs on the ``NUM_ROUTE_POINTS`` observed route points rather than the whole route.

    Returns:
        gap: (A,) float32, m, route distance from the ego front to the actor's nearest point.
        lateral: (A,) float32, m, distance of the actor centre from the route minus its half size.
    """
    arc, dist = project_uniform(obs.route, ROUTE_STEP, obs.actor_xy)
    half = jnp.max(obs.actor_extent, axis=-1)
    return arc - EGO_HALF_LENGTH - half, dist - half
