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

``privileged`` holds what only a privileged policy may read (:class:`PrivilegedView`: every
actor's forecast from its own script or motion model).  The simulator fills it only for a policy
whose ``Policy.privileged`` flag is set (a static switch of the rollout), so ordinary policies
pay nothing for it; for them it is ``None``.

``surround`` is the six-camera rig (:class:`SurroundView`, 360 deg: visibility of every actor and
its own range image), the sensor of the surround-view learned model (the VAD analogue).  It is
filled only for a policy whose act function asks for it (``act.surround = True``, a static
switch read by :func:`lantern_jax.sim.step.step`); for every other policy it is ``None``.
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
FORECAST_STEPS = 40  # forecast times of the privileged view: 2 s at 20 Hz (PDM-Lite)
FORECAST_DT = 0.05  # s between forecast times


@struct.dataclass
class PrivilegedView:
    """Privileged forecast of every actor slot (ego frame), from the actors' own scripts.

    Entry ``[i, k]`` is actor ``i`` at ``t + FORECAST_DT * (k + 1)``; one array per component
    (x and y apart), which XLA vectorises far better than a trailing axis of 2.  A scenario actor
    whose
    trigger (the protocol's physical event) is still pending may start at any moment from the
    earliest possible event onset on; its entry is then the box covering every such start
    (:mod:`lantern_jax.dynamics.forecast`).
    """

    forecast_x: Array  # (A, K) float32, m, box centres (x forward)
    forecast_y: Array  # (A, K) float32, m, (y right)
    forecast_ux: Array  # (A, K) float32, unit vectors along the box lengths
    forecast_uy: Array  # (A, K) float32
    forecast_half_length: Array  # (A, K) float32, m
    forecast_half_width: Array  # (A, K) float32, m
    forecast_speed: Array  # (A, K) float32, m/s
    forecast_valid: Array  # (A, K) bool, the actor is (may be) in the world then


@struct.dataclass
class SurroundView:
    """The six-camera rig (360 deg, one mounting point) at one tick."""

    visible: Array  # (A,) bool, the rig sees the actor (field of view, range, occlusion)
    ranges: Array  # (SURROUND_RAYS,) float32, m, distance to the first hit along each ray
    #                (capped at the sensing range; ray 0 points backwards, counter-clockwise)
    hit_class: Array  # (SURROUND_RAYS,) int32, class of each ray's first hit
    #                   (``constants.RAY_CLASS_NAMES``; -1: nothing within range)


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
    range_class: Array  # (NUM_RANGE_RAYS,) int32, class of each front ray's first hit
    #                     (``constants.RAY_CLASS_NAMES``: actor kinds, then static occluder
    #                     kinds; -1: nothing within range)
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
    privileged: PrivilegedView | None = None  # only for privileged policies (else None)
    surround: SurroundView | None = None  # only for surround-rig policies (else None)


def corridor_gaps(obs: Observation) -> tuple[Array, Array]:
    """Route gap ahead of the ego and lateral clearance from the route of every actor.

    Uses the observation's route points ahead of the ego and the actors in the ego frame, so the
    projection runs on the ``NUM_ROUTE_POINTS`` observed route points rather than the whole route.
    The actor's box is measured along and across the route at its projection (its heading
    against the route tangent there), so a long vehicle parked beside the lane is as far from
    the route as its side, not as its half length.

    Returns:
        gap: (A,) float32, m, route distance from the ego front to the actor box's near end.
        lateral: (A,) float32, m, distance of the actor centre from the route minus its half
            extent across the route (<= 0: the box reaches the route centre line).
    """
    route = obs.route
    arc, dist = project_uniform(route, ROUTE_STEP, obs.actor_xy)
    k = jnp.clip(jnp.floor(arc / ROUTE_STEP).astype(jnp.int32), 0, route.shape[0] - 2)
    d = route[k + 1] - route[k]  # (A, 2)
    tang = d / jnp.sqrt(jnp.maximum(jnp.sum(d * d, -1, keepdims=True), 1e-12))
    cos = jnp.abs(jnp.sum(obs.actor_dir * tang, -1))
    sin = jnp.abs(obs.actor_dir[:, 0] * tang[:, 1] - obs.actor_dir[:, 1] * tang[:, 0])
    hl, hw = obs.actor_extent[:, 0], obs.actor_extent[:, 1]
    return arc - EGO_HALF_LENGTH - (hl * cos + hw * sin), dist - (hl * sin + hw * cos)
