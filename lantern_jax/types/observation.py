"""What a policy observes at one tick (one scenario), and the sensors that decide it.

The simulator (:mod:`lantern_jax.sim.observe`) builds the observation from the sensors a policy
declares (``Policy.sensors``) and from nothing else; every policy reads it, so the type lives
below both.  A policy cannot read what its sensors do not deliver: the boundary is the
simulator's, not a convention.

All positions and vectors are in the **ego frame of the paper: x forward, y to the right**,
metres, relative to the ego box centre.

Sensors (the built-in ones, :data:`SENSORS`; ``FRONT_CAMERA`` is every policy's and need not be
named; the table of every sensor, with those registered from user code, is
:mod:`lantern_jax.sensors.registry`):

* ``"front_camera"`` — the 110 deg front camera: the actors it sees now (``visible``; their
  position, velocity, heading, extent and kind) and its range image.  The route ahead, the
  navigation targets, the ego's own state, its traffic light and stop line come with every
  policy (map and ego state, as in CARLA's leaderboard sensors).
* ``"surround_rig"`` — the six-camera 360 deg rig (:class:`SurroundView`); the actors it sees
  join ``visible`` and the per-actor fields.
* ``"warning"`` — the cooperative warning, **only as its delivered text**: ``warning_tokens``
  (token ids of the grounded string) and ``warning_values`` (the numbers the string writes, at
  its number tokens; :mod:`lantern_jax.types.language`, "Numbers").  No flag says a warning is on:
  an all-padding row is no warning, and an empty text reads the same.  Without this sensor the
  row is always padding.
* ``"privileged"`` — ground truth (:class:`PrivilegedView`): every actor that exists, hidden
  or not, and its forecast from the scenario's own scripts.  Only a privileged reference (the
  ``expert``) declares it; its results are an upper reference, never a submission.
* a sensor registered from user code (:func:`lantern_jax.sensors.registry.view_sensor`) — its
  reading is ``views[name]``.

**The sentinel.**  For an actor slot that the declared cameras do not see at this tick (hidden,
out of range, not yet spawned, or padding), every per-actor field is exactly zero — position,
velocity, heading, extent and kind — and ``visible`` is False.  A zero kind is also
``KIND_VEHICLE``: read the kind only where ``visible`` holds.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import EGO_HALF_LENGTH
from lantern_jax.maths.polyline import project_uniform
from lantern_jax.types.language import NUMBER_ID, PAD_ID

Array = jax.Array

FRONT_CAMERA = "front_camera"  # every policy's camera (implied)
SURROUND_RIG = "surround_rig"  # the six-camera 360 deg rig
WARNING = "warning"  # the delivered warning text
PRIVILEGED = "privileged"  # ground truth and scripted forecasts (reference experts only)
SENSORS = (FRONT_CAMERA, SURROUND_RIG, WARNING, PRIVILEGED)  # the built-in sensors

NUM_ROUTE_POINTS = 24  # route points ahead in the observation
ROUTE_STEP = 2.0  # m between observed route points
NUM_RANGE_RAYS = 32  # rays of the front-camera range image
FORECAST_STEPS = 40  # forecast times of the privileged view: 2 s at 20 Hz (PDM-Lite)
FORECAST_DT = 0.05  # s between forecast times


@struct.dataclass
class PrivilegedView:
    """Ground truth of every actor slot and its forecast (ego frame), from the actors' own
    scripts.

    The ``actor_*`` fields are those of the observation without the camera's mask: every actor
    that exists now (``present``), hidden or not; a slot with no actor holds the sentinel (zero).

    Forecast entry ``[i, k]`` is actor ``i`` at ``t + FORECAST_DT * (k + 1)``; one array per
    component (x and y apart), which XLA vectorises far better than a trailing axis of 2.  A
    scenario actor whose trigger (the protocol's physical event) is still pending may start at
    any moment from the earliest possible event onset on; its entry is then the box covering
    every such start (:mod:`lantern_jax.dynamics.forecast`).
    """

    present: Array  # (A,) bool, the actor exists in the world now
    actor_xy: Array  # (A, 2) float32, m, box centres
    actor_vel: Array  # (A, 2) float32, m/s, velocities
    actor_dir: Array  # (A, 2) float32, unit heading vectors
    actor_extent: Array  # (A, 2) float32, m, (half length, half width)
    actor_kind: Array  # (A,) int32, KIND_*

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
    """One tick of policy input (no batch axis); see the module docstring for the sensors and
    the zero sentinel of actors the policy does not see."""

    ego_speed: Array  # () float32, m/s
    ego_accel: Array  # () float32, m/s^2, last applied longitudinal acceleration
    ego_steer: Array  # () float32, rad, front-wheel angle (+ = left)
    v_ref: Array  # () float32, m/s, route reference speed (speed limit of the scenario)
    route: Array  # (NUM_ROUTE_POINTS, 2) float32, m, route centre-line ahead, ROUTE_STEP apart,
    #               starting at the ego's projection onto the route
    target_points: Array  # (2, 2) float32, m, navigation targets 10 m and 30 m ahead on the route
    dist_to_route_end: Array  # () float32, m
    actor_xy: Array  # (A, 2) float32, m, actor box centres (0 where not visible)
    actor_vel: Array  # (A, 2) float32, m/s, actor velocities (0 where not visible)
    actor_dir: Array  # (A, 2) float32, unit heading vectors of the actors (0 where not visible)
    actor_extent: Array  # (A, 2) float32, m, (half length, half width) (0 where not visible)
    actor_kind: Array  # (A,) int32, KIND_* (0 where not visible)
    visible: Array  # (A,) bool, seen now by the declared cameras (front, and the rig if declared)
    range_image: Array  # (NUM_RANGE_RAYS,) float32, m, front-camera ray ranges (capped)
    range_class: Array  # (NUM_RANGE_RAYS,) int32, class of each front ray's first hit
    #                     (``constants.RAY_CLASS_NAMES``: actor kinds, then static occluder
    #                     kinds; -1: nothing within range)
    light_state: Array  # () int32, LIGHT_* of the ego's traffic light (GREEN when none)
    dist_to_stop: Array  # () float32, m, route distance from the ego centre to its stop line
    warning_tokens: Array  # (MAX_TOKENS,) int32, token ids of the delivered text (all PAD_ID
    #                        when none is delivered or the policy has no warning sensor)
    warning_values: Array  # (MAX_TOKENS,) float32, the numbers the text writes (m), at its
    #                        number tokens; 0 elsewhere
    privileged: PrivilegedView | None = None  # only with the "privileged" sensor (else None)
    surround: SurroundView | None = None  # only with the "surround_rig" sensor (else None)
    views: dict[str, Any] | None = None  # the readings of the declared sensors registered from
    #                                      user code, by name (None: the policy declares none)


def warning_delivered(obs: Observation) -> Array:
    """() bool: the observation holds a warning text (any token that is not padding)."""
    return jnp.any(obs.warning_tokens != PAD_ID)


def stated_position(obs: Observation) -> tuple[Array, Array]:
    """The position the warning text writes: its first two numbers, read from the value
    channel at its number tokens.

    Returns:
        position: (2,) float32, m, ego frame (x forward, y right); zeros without two numbers.
        stated: () bool, the text writes at least two numbers.
    """
    is_num = obs.warning_tokens == NUMBER_ID
    rank = jnp.cumsum(is_num) - 1  # index of each number among the text's numbers
    x = jnp.sum(jnp.where(is_num & (rank == 0), obs.warning_values, 0.0))
    y = jnp.sum(jnp.where(is_num & (rank == 1), obs.warning_values, 0.0))
    stated = jnp.sum(is_num) >= 2
    return jnp.where(stated, jnp.stack([x, y]), 0.0), stated


def corridor_gaps(
    route: Array, actor_xy: Array, actor_dir: Array, actor_extent: Array
) -> tuple[Array, Array]:
    """Route gap ahead of the ego and lateral clearance from the route of every actor.

    Args:
        route: (NUM_ROUTE_POINTS, 2) float32, m, the route ahead in the ego frame (as observed).
        actor_xy, actor_dir, actor_extent: (A, 2) float32, the actors in the ego frame.

    The projection runs on the ``NUM_ROUTE_POINTS`` route points ahead rather than the whole
    route.
    The actor's box is measured along and across the route at its projection (its heading
    against the route tangent there), so a long vehicle parked beside the lane is as far from
    the route as its side, not as its half length.

    Returns:
        gap: (A,) float32, m, route distance from the ego front to the actor box's near end.
        lateral: (A,) float32, m, distance of the actor centre from the route minus its half
            extent across the route (<= 0: the box reaches the route centre line).
    """
    arc, dist = project_uniform(route, ROUTE_STEP, actor_xy)
    k = jnp.clip(jnp.floor(arc / ROUTE_STEP).astype(jnp.int32), 0, route.shape[0] - 2)
    d = route[k + 1] - route[k]  # (A, 2)
    tang = d / jnp.sqrt(jnp.maximum(jnp.sum(d * d, -1, keepdims=True), 1e-12))
    cos = jnp.abs(jnp.sum(actor_dir * tang, -1))
    sin = jnp.abs(actor_dir[:, 0] * tang[:, 1] - actor_dir[:, 1] * tang[:, 0])
    hl, hw = actor_extent[:, 0], actor_extent[:, 1]
    return arc - EGO_HALF_LENGTH - (hl * cos + hw * sin), dist - (hl * sin + hw * cos)
