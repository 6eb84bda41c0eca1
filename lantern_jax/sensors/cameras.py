"""Camera rigs: what a camera (the 110 deg front camera or the 360 deg six-camera rig) reports
of one scenario's world at one tick — the actors it sees and a semantic range image — by the
ray casting of :mod:`lantern_jax.sensors.visibility`.

The simulator's front camera runs every tick (:func:`lantern_jax.sim.sense.sense`, whose
visibility and ranges equal :func:`camera_view` at ``FRONT_CAMERA_FOV``); the six-camera rig
runs only for a policy that declares it (the ``"surround_rig"`` sensor,
:mod:`lantern_jax.sensors.registry`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import NUM_ACTOR_KINDS, RAY_CLASS_NONE
from lantern_jax.sensors.visibility import camera_pose, range_image, visible_actors
from lantern_jax.types.observation import NUM_RANGE_RAYS
from lantern_jax.types.world import ActorState, EgoState, Scenario, present

Array = jax.Array

FRONT_RAYS = NUM_RANGE_RAYS  # rays of the front camera's range image (110 deg)
SURROUND_RAYS = 72  # rays of the six-camera rig's range image (6 cameras x 12 rays, 360 deg)
NO_HIT = RAY_CLASS_NONE  # semantic class of a ray that hits nothing within range


@struct.dataclass
class CameraView:
    """What one camera rig reports: visibility of every actor and a semantic range image."""

    visible: Array  # (A,) bool, the rig sees the actor (field of view, range, occlusion)
    ranges: Array  # (N,) float32, m, distance to the first hit along each ray (capped at range)
    hit_class: Array  # (N,) int32, class of the first hit (``constants.RAY_CLASS_NAMES``: an
    #                   actor's KIND_*, NUM_ACTOR_KINDS + OCC_* for a static occluder; NO_HIT)


def camera_view(
    scenario: Scenario, ego: EgoState, actors: ActorState, fov_deg: float, num_rays: int
) -> CameraView:
    """A camera rig's view of the current world (110 deg front camera or the 360 deg rig).

    Actor boxes and the map's static occluders block the rays of both rigs, as in
    :func:`lantern_jax.sim.sense.sense` (for the front camera its visibility and ranges equal
    that function's).

    Args:
        scenario: the execution's static scenario (actor boxes and kinds, occluders, range).
        ego: the ego now.
        actors: the actors now.
        fov_deg: static, horizontal field of view in degrees (``FRONT_CAMERA_FOV`` or 360).
        num_rays: static, rays of the range image.
    """
    boxes, occ = scenario.actors, scenario.occluders
    on = present(boxes, actors)
    cam_xy, cam_yaw = camera_pose(ego.xy, ego.yaw)
    rng = scenario.config.sensing_range
    vis = visible_actors(
        cam_xy, cam_yaw, actors.xy, actors.yaw, boxes.extent, on, fov_deg, rng, occ
    )
    ranges, hit = range_image(
        cam_xy, cam_yaw, actors.xy, actors.yaw, boxes.extent, on, fov_deg, num_rays, rng, occ
    )
    return CameraView(visible=vis, ranges=ranges, hit_class=ray_classes(hit, boxes.kind, occ.kind))


def ray_classes(hit_index: Array, actor_kind: Array, occluder_kind: Array) -> Array:
    """Semantic class of each ray's first hit (``constants.RAY_CLASS_NAMES``).

    Args:
        hit_index: (N,) int32, from :func:`~lantern_jax.sensors.visibility.range_image`: actor
            slot ``a`` (0..A-1), ``A + k`` for static occluder ``k``, -1 for no hit.
        actor_kind: (A,) int32, KIND_* of each actor slot.
        occluder_kind: (K,) int32, OCC_* of each occluder slot.

    Returns:
        (N,) int32: the actor's KIND_*, ``NUM_ACTOR_KINDS + OCC_*`` for an occluder, or
        ``NO_HIT``.
    """
    classes = jnp.concatenate(
        [actor_kind.astype(jnp.int32), NUM_ACTOR_KINDS + occluder_kind.astype(jnp.int32)]
    )
    return jnp.where(hit_index >= 0, classes[jnp.clip(hit_index, 0, None)], NO_HIT).astype(
        jnp.int32
    )
