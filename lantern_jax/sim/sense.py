"""What the ego's sensors and route localisation report after a tick (one scenario).

:func:`sense` runs the front camera (110 deg; visibility of every actor and a planar range
image, both blocked by actor boxes and the map's static occluders,
:mod:`lantern_jax.sensors.visibility`) on the world after the actors moved, and
:func:`locate_on_route` places the ego on its route (arc, distance, monotone progress).  Both
results travel in :class:`Percept`, part of the simulator's state, so the next tick's
observation and the protocol read them without recomputing.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import FRONT_CAMERA_FOV
from lantern_jax.maths import polyline

# the camera rigs' code lives in lantern_jax.sensors.cameras; these names are kept here too
from lantern_jax.sensors.cameras import FRONT_RAYS as FRONT_RAYS
from lantern_jax.sensors.cameras import NO_HIT as NO_HIT
from lantern_jax.sensors.cameras import SURROUND_RAYS as SURROUND_RAYS
from lantern_jax.sensors.cameras import CameraView as CameraView
from lantern_jax.sensors.cameras import camera_view as camera_view
from lantern_jax.sensors.cameras import ray_classes
from lantern_jax.sensors.visibility import camera_pose, range_image, visible_actors
from lantern_jax.types.observation import NUM_RANGE_RAYS
from lantern_jax.types.world import ActorState, EgoState, Route, Scenario, present

Array = jax.Array


@struct.dataclass
class Percept:
    """Sensor and localisation results of one tick (after the world has been stepped)."""

    visible: Array  # (A,) bool, front-camera visibility of each actor
    ranges: Array  # (NUM_RANGE_RAYS,) float32, m, front-camera range image
    range_class: Array  # (NUM_RANGE_RAYS,) int32, class of each ray's first hit (ray_classes)
    route_arc: Array  # () float32, m, ego projection onto the route (may be < 0 or > length)
    dist_to_route: Array  # () float32, m, ego centre distance from the route polyline
    progress: Array  # () float32, m, furthest route arc reached (monotone, clipped to length)


def locate_on_route(
    route: Route, ego_xy: Array, progress_prev: Array
) -> tuple[Array, Array, Array]:
    """The ego's place on its route.

    Args:
        route: the ego route.
        ego_xy: (2,) float32, m, world-frame ego box centre.
        progress_prev: () float32, m, progress before this tick (progress is monotone).

    Returns:
        arc: () float32, m, arc of the ego's projection (may be < 0 or > length).
        dist: () float32, m, distance of the ego centre from the route polyline.
        progress: () float32, m, ``max(progress_prev, clip(arc, 0, length))``.
    """
    arc, _, _, dist = polyline.project(route.xy, route.s, route.valid, ego_xy)
    return arc, dist, jnp.maximum(progress_prev, jnp.clip(arc, 0.0, route.length))


def sense(
    scenario: Scenario,
    ego: EgoState,
    actors: ActorState,
    route_arc: Array,
    dist_to_route: Array,
    progress: Array,
) -> Percept:
    """Front-camera visibility and range image of the current world, with the ego's route place.

    Args:
        scenario: the execution's static scenario (actor boxes, occluders, sensing range).
        ego: the ego now.
        actors: the actors now.
        route_arc, dist_to_route, progress: from :func:`locate_on_route`.
    """
    boxes = scenario.actors
    on = present(boxes, actors)
    cam_xy, cam_yaw = camera_pose(ego.xy, ego.yaw)
    rng = scenario.config.sensing_range
    occ = scenario.occluders
    vis = visible_actors(
        cam_xy, cam_yaw, actors.xy, actors.yaw, boxes.extent, on, FRONT_CAMERA_FOV, rng, occ
    )
    ranges, hit = range_image(
        cam_xy, cam_yaw, actors.xy, actors.yaw, boxes.extent, on, FRONT_CAMERA_FOV,
        NUM_RANGE_RAYS, rng, occ,
    )  # fmt: skip
    return Percept(
        visible=vis, ranges=ranges, range_class=ray_classes(hit, boxes.kind, occ.kind),
        route_arc=route_arc, dist_to_route=dist_to_route, progress=progress,
    )  # fmt: skip
