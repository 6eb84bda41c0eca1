"""Camera visibility of actors and planar range images, by ray casting against actor boxes and
the map's static occluders.

The front camera sits ``constants.CAMERA_BACK_OFFSET`` behind the ego centre and looks along
the ego heading with a ``constants.FRONT_CAMERA_FOV`` (110 degree) horizontal field of view.
A six-camera rig covering the full circle is the same machinery with
``fov_deg = SURROUND_FOV`` (360 degrees): the field-of-view test then accepts every bearing,
and occlusion and range work exactly as for a single camera (the rig's cameras share one
mounting point here).

An actor is **visible** when at least one of its 9 sample points (box centre, 4 corners,
4 edge midpoints) is inside the field of view, within ``max_range`` of the camera, and the
sight line from the camera to the point is not blocked by *another* present actor's box or by
a valid static occluder (:class:`~lantern_jax.types.world.Occluders`: buildings, walls, parked
vehicles): a box blocks the point when the sight line enters it more than ``OCCLUSION_EPS``
before reaching the point.  The target's own box never blocks its own points, non-present
actors neither block nor are visible, occluders block but are never targets, and the ego's own
box is not part of either set.  The range image sees both kinds of box.

One scenario per call; batches of scenarios are made with ``jax.vmap`` outside.  Visibility
tests one target per loop step (its 9 sight lines against all A + K boxes) and the range image
runs its rays in two loop steps (:func:`~lantern_jax.maths.split_map.split_map`): the loop
boundaries make XLA compute the actor poses once instead of re-deriving the tick's actor update for
every (point, box) or (ray, box) element.  ``fov_deg`` and ``num_rays`` are static Python numbers.
Occluders are static, so their trigonometry is loop-invariant inside a rollout's scan (the
compiler hoists it).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import BIG, CAMERA_BACK_OFFSET
from lantern_jax.maths.geometry import rays_boxes_hit, safe_norm, segments_hit_boxes
from lantern_jax.maths.split_map import split_map
from lantern_jax.types.world import Occluders

Array = jax.Array

OCCLUSION_EPS = 0.05  # m, a blocker must be hit at least this far before the sample point
NUM_SAMPLE_POINTS = 9  # per actor: centre, 4 corners, 4 edge midpoints

# sample points in box units (x along the heading, y to the left):
# centre, corners (front-left, rear-left, rear-right, front-right),
# edge midpoints (front, left, rear, right)
_SAMPLE_SX = np.array([0.0, 1.0, -1.0, -1.0, 1.0, 1.0, 0.0, -1.0, 0.0], np.float32)
_SAMPLE_SY = np.array([0.0, 1.0, 1.0, -1.0, -1.0, 0.0, 1.0, 0.0, -1.0], np.float32)


def camera_pose(ego_xy: Array, ego_yaw: Array) -> tuple[Array, Array]:
    """Pose of the front camera mounted behind the ego centre.

    Args:
        ego_xy: (2,) float32 ego box centre, m, world frame.
        ego_yaw: () float32 ego heading, rad, counter-clockwise from +x.

    Returns:
        cam_xy: (2,) float32 camera position, m, world frame
            (``CAMERA_BACK_OFFSET`` behind the centre along the heading).
        cam_yaw: () float32 camera viewing direction, rad (the ego heading).
    """
    ego_xy = jnp.asarray(ego_xy, jnp.float32)
    ego_yaw = jnp.asarray(ego_yaw, jnp.float32)
    heading = jnp.stack([jnp.cos(ego_yaw), jnp.sin(ego_yaw)])
    return ego_xy - CAMERA_BACK_OFFSET * heading, ego_yaw


def actor_sample_points(centers: Array, yaws: Array, extents: Array) -> Array:
    """The 9 visibility sample points of each box.

    Args:
        centers: (..., 2) float32 box centres, m, world frame.
        yaws: (...) float32 box headings, rad.
        extents: (..., 2) float32 (half length, half width), m.

    Returns:
        (..., 9, 2) float32 points, m, world frame: centre, corners (front-left, rear-left,
        rear-right, front-right), edge midpoints (front, left, rear, right).
    """
    yaws = jnp.asarray(yaws, jnp.float32)
    return _sample_points(centers, jnp.cos(yaws), jnp.sin(yaws), extents)


def _sample_points(centers: Array, cos: Array, sin: Array, extents: Array) -> Array:
    """:func:`actor_sample_points` from the headings' cosines and sines (...) float32."""
    centers = jnp.asarray(centers, jnp.float32)
    extents = jnp.asarray(extents, jnp.float32)
    c, s = cos[..., None], sin[..., None]
    lx = _SAMPLE_SX * extents[..., 0:1]
    ly = _SAMPLE_SY * extents[..., 1:2]
    x = centers[..., 0:1] + c * lx - s * ly
    y = centers[..., 1:2] + s * lx + c * ly
    return jnp.stack([x, y], axis=-1)


def _in_fov(rel: Array, dist: Array, cam_yaw: Array, fov_deg: float) -> Array:
    """|bearing| <= fov / 2 for camera-relative points ``rel`` (..., 2) at range ``dist``."""
    if fov_deg >= 360.0:
        return jnp.ones(dist.shape, bool)
    half = math.radians(0.5 * fov_deg)
    along = rel[..., 0] * jnp.cos(cam_yaw) + rel[..., 1] * jnp.sin(cam_yaw)
    return along >= dist * math.cos(half)


def _with_occluders(
    centers: Array, yaws: Array, extents: Array, occluders: Occluders | None
) -> tuple[Array, Array, Array, Array]:
    """Actor boxes followed by the occluder boxes, and the occluders' valid mask (K,)."""
    centers = jnp.asarray(centers, jnp.float32)
    yaws = jnp.asarray(yaws, jnp.float32)
    extents = jnp.asarray(extents, jnp.float32)
    if occluders is None:
        return centers, yaws, extents, jnp.zeros((0,), bool)
    return (
        jnp.concatenate([centers, jnp.asarray(occluders.center, jnp.float32)]),
        jnp.concatenate([yaws, jnp.asarray(occluders.yaw, jnp.float32)]),
        jnp.concatenate([extents, jnp.asarray(occluders.extent, jnp.float32)]),
        jnp.asarray(occluders.valid, bool),
    )


def visible_actors(
    cam_xy: Array,
    cam_yaw: Array,
    centers: Array,
    yaws: Array,
    extents: Array,
    present: Array,
    fov_deg: float,
    max_range: Array,
    occluders: Occluders | None = None,
) -> Array:
    """Which actors the camera sees (field of view, range, occlusion by other actors and by the
    static occluders).

    Args:
        cam_xy: (2,) float32 camera position, m, world frame (see :func:`camera_pose`).
        cam_yaw: () float32 camera viewing direction, rad.
        centers: (A, 2) float32 actor box centres, m, world frame.
        yaws: (A,) float32 actor headings, rad.
        extents: (A, 2) float32 actor (half length, half width), m.
        present: (A,) bool, actor exists in the world (valid and active).
        fov_deg: static Python float, horizontal field of view in degrees
            (``FRONT_CAMERA_FOV`` = 110 or ``SURROUND_FOV`` = 360).
        max_range: () float32 sensing range, m.
        occluders: the map's static occluders (K slots, ``valid``-masked); None = none.

    Returns:
        (A,) bool, True for a present actor with at least one unoccluded sample point inside
        the field of view and range.
    """
    cam_xy = jnp.asarray(cam_xy, jnp.float32)
    cam_yaw = jnp.asarray(cam_yaw, jnp.float32)
    present = jnp.asarray(present, bool)
    num = present.shape[0]
    box_c, box_yaw, box_e, occ_valid = _with_occluders(centers, yaws, extents, occluders)

    box_heading = (jnp.cos(box_yaw), jnp.sin(box_yaw))  # once, not in every loop step
    blockers = present[None, :] & ~jnp.eye(num, dtype=bool)  # (target, blocker actor)
    occ = jnp.broadcast_to(occ_valid[None, :], (num, occ_valid.shape[0]))
    blockers = jnp.concatenate([blockers, occ], axis=1)  # (target, A + K)

    # One target per loop step, its sample points derived inside the step: the loop boundary
    # makes the compiler compute the actor poses once (they are its operands) instead of
    # re-deriving the tick's whole actor update for every (point, coordinate) element.  The
    # headings' cosines and sines are operands too: inside the step the compiler would
    # evaluate them once per sample point coordinate (18 times per target).
    def one_target(args):
        center, cos, sin, extent, blockers_t = args  # (2,), (), (), (2,), (A + K,)
        pts = _sample_points(center, cos, sin, extent)  # (9, 2)
        rel = pts - cam_xy
        dist = safe_norm(rel)  # (9,)
        in_view = _in_fov(rel, dist, cam_yaw, fov_deg) & (dist <= max_range)
        # shorten each sight line by OCCLUSION_EPS: a box entered before its end blocks it
        far = dist > OCCLUSION_EPS
        frac = jnp.where(far, 1.0 - OCCLUSION_EPS / jnp.where(far, dist, 1.0), 0.0)
        ends = cam_xy + rel * frac[..., None]
        hits = segments_hit_boxes(cam_xy, ends, box_c, box_yaw, box_e, box_heading)  # (9, A+K)
        blocked = jnp.any(hits & blockers_t[None, :], axis=-1) & far
        return jnp.any(in_view & ~blocked)

    seen = jax.lax.map(
        one_target, (box_c[:num], box_heading[0][:num], box_heading[1][:num], box_e[:num], blockers)
    )
    return present & seen


def ray_angles(fov_deg: float, num_rays: int) -> np.ndarray:
    """Ray bearings of a range image relative to the camera heading.

    Rays are ordered counter-clockwise (right to left) and ray ``num_rays // 2`` looks
    straight ahead when ``num_rays`` is odd or the field is 360 degrees.  A field below 360
    degrees includes both edges; a 360 degree field is covered at spacing ``2 pi / num_rays``
    without a duplicated seam.

    Args:
        fov_deg: static Python float, horizontal field of view, degrees.
        num_rays: static Python int >= 1.

    Returns:
        (num_rays,) float32 numpy array of bearings, rad.
    """
    if num_rays < 1:
        raise ValueError(f"ray_angles: num_rays must be >= 1, got {num_rays}")
    if fov_deg >= 360.0:
        k = np.arange(num_rays) - num_rays // 2
        return (2.0 * np.pi * k / num_rays).astype(np.float32)
    if num_rays == 1:
        return np.zeros(1, np.float32)
    half = math.radians(0.5 * fov_deg)
    return np.linspace(-half, half, num_rays).astype(np.float32)


def range_image(
    cam_xy: Array,
    cam_yaw: Array,
    centers: Array,
    yaws: Array,
    extents: Array,
    present: Array,
    fov_deg: float,
    num_rays: int,
    max_range: Array,
    occluders: Occluders | None = None,
) -> tuple[Array, Array]:
    """Planar range image: distance to the nearest present actor box or static occluder along
    evenly spread rays.

    Args:
        cam_xy: (2,) float32 camera position, m, world frame.
        cam_yaw: () float32 camera viewing direction, rad.
        centers: (A, 2) float32 actor box centres, m, world frame.
        yaws: (A,) float32 actor headings, rad.
        extents: (A, 2) float32 actor half extents, m.
        present: (A,) bool, actor exists in the world.
        fov_deg: static Python float, horizontal field of view, degrees (see
            :func:`ray_angles` for the ray layout).
        num_rays: static Python int, number of rays.
        max_range: () float32 sensing range, m.
        occluders: the map's static occluders (K slots, ``valid``-masked); None = none.

    Returns:
        ranges: (num_rays,) float32 distance to the first hit, m, capped at ``max_range``
            (0 when the camera is inside a box).
        hit_index: (num_rays,) int32 what each ray hits first: the actor slot ``a`` (0..A-1),
            ``A + k`` for occluder ``k``, or -1 when nothing is hit within ``max_range``.
    """
    cam_xy = jnp.asarray(cam_xy, jnp.float32)
    cam_yaw = jnp.asarray(cam_yaw, jnp.float32)
    max_range = jnp.asarray(max_range, jnp.float32)
    box_c, box_yaw, box_e, occ_valid = _with_occluders(centers, yaws, extents, occluders)
    hittable = jnp.concatenate([jnp.asarray(present, bool), occ_valid])  # (A + K,)
    # the fixed ray bearings' unit vectors, turned by the camera heading (one sine and cosine)
    bearing = ray_angles(fov_deg, num_rays)
    bx, by = np.cos(bearing).astype(np.float32), np.sin(bearing).astype(np.float32)
    c, s = jnp.cos(cam_yaw), jnp.sin(cam_yaw)
    dirs = jnp.stack([c * bx - s * by, s * bx + c * by], axis=-1)  # (num_rays, 2)
    box_heading = (jnp.cos(box_yaw), jnp.sin(box_yaw))  # once, not in both loop steps

    def nearest_hits(dirs_part):
        t = rays_boxes_hit(cam_xy, dirs_part, box_c, box_yaw, box_e, box_heading)  # (rays, A+K)
        t = jnp.where(hittable[None, :], t, 2.0 * BIG)  # never within range
        nearest = jnp.min(t, axis=-1)
        # the first box at the minimum, as argmin picks it, from two plain min-reductions:
        # XLA on CPU runs argmin's (value, index) reduction far slower
        boxes = jnp.arange(t.shape[-1], dtype=jnp.int32)
        first = jnp.min(jnp.where(t <= nearest[:, None], boxes, t.shape[-1]), axis=-1)
        return nearest, first

    # in loop steps, so that the boxes' poses are computed once, not per (ray, box) element
    nearest, first = split_map(nearest_hits, dirs)
    hit = nearest <= max_range
    ranges = jnp.where(hit, nearest, max_range)
    hit_index = jnp.where(hit, first, -1).astype(jnp.int32)
    return ranges, hit_index
