"""Tests for lantern_jax.sensors.visibility: tiny hand-built scenes, reference parity, gradients.

Unless stated otherwise the camera sits at the origin looking east (+x), fov 110 deg, range 50 m.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import (
    CAMERA_BACK_OFFSET,
    FRONT_CAMERA_FOV,
    OCC_BUILDING,
    OCC_WALL,
    SURROUND_FOV,
)
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.road import OccluderSpec
from lantern_jax.scoring.measure import TickEnd, measure
from lantern_jax.scoring.thresholds import DEFAULT_SCORING
from lantern_jax.sensors import visibility as vis
from lantern_jax.types.world import Occluders, ProtocolState

try:  # tests/ as a rootdir-relative folder or as a package
    import reference_numpy_geometry as ref
except ImportError:  # pragma: no cover
    from tests import reference_numpy_geometry as ref

CAM = np.zeros(2, np.float32)
CAM_YAW = np.float32(0.0)
CAR = (2.4, 1.0)  # half extents of a car, m
RANGE = np.float32(50.0)


@functools.partial(jax.jit, static_argnames=("fov_deg",))
def visible(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range):
    return vis.visible_actors(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range)


@functools.partial(jax.jit, static_argnames=("fov_deg", "num_rays"))
def ranges_of(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, num_rays, max_range):
    return vis.range_image(
        cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, num_rays, max_range
    )


def scene(*actors, pad: int = 0):
    """Arrays for actors given as (x, y, yaw, half_length, half_width[, present])."""
    rows = [tuple(a) + (True,) if len(a) == 5 else tuple(a) for a in actors]
    rows += [(0.0, 0.0, 0.0, 0.0, 0.0, False)] * pad
    arr = np.array([r[:5] for r in rows], np.float32)
    present = np.array([r[5] for r in rows], bool)
    return arr[:, :2], arr[:, 2], arr[:, 3:5], present


def see(actors, fov=FRONT_CAMERA_FOV, rng=RANGE, cam=CAM, cam_yaw=CAM_YAW):
    c, y, e, p = actors
    return np.asarray(visible(cam, cam_yaw, c, y, e, p, fov, rng))


# ---------------------------------------------------------------------------------------------
# camera pose
# ---------------------------------------------------------------------------------------------
def test_camera_pose():
    # ego at (0, 0) heading north: camera 1.5 m south of the centre, looking north
    xy, yaw = vis.camera_pose(np.zeros(2, np.float32), np.float32(np.pi / 2))
    np.testing.assert_allclose(xy, [0.0, -CAMERA_BACK_OFFSET], atol=1e-6)
    assert float(yaw) == pytest.approx(np.pi / 2)
    xy, _ = vis.camera_pose(np.array([10.0, 0.0], np.float32), np.float32(0.0))
    np.testing.assert_allclose(xy, [8.5, 0.0], atol=1e-6)


def test_sample_points_layout():
    # axis-aligned box at (1, 2), half extents (2, 1): centre, 4 corners, 4 edge midpoints
    pts = vis.actor_sample_points(np.array([1, 2], np.float32), np.float32(0), np.float32([2, 1]))
    want = [[1, 2], [3, 3], [-1, 3], [-1, 1], [3, 1], [3, 2], [1, 3], [-1, 2], [1, 1]]
    np.testing.assert_allclose(pts, want, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# visibility goldens
# ---------------------------------------------------------------------------------------------
def test_target_straight_ahead_is_visible():
    assert see(scene((20, 0, 0, *CAR))).tolist() == [True]


def test_full_occlusion():
    # target car x in [17.6, 22.4], y in [-1, 1]; occluder x in [9, 11], y in [-5, 5].
    # every sight line reaches |y| <= 11/17.6 < 5 inside the occluder -> target hidden,
    # while the occluder itself is in plain view
    assert see(scene((20, 0, 0, *CAR), (10, 0, 0, 1, 5))).tolist() == [False, True]


def test_partial_occlusion_one_corner_visible():
    # occluder x in [9, 11], y in [-2.5, 0.48] (centre y = -1.01, half width 1.49).
    # sight lines rise with x, so each is lowest at the occluder's near face x = 9, where
    # y = 9 * y_p / x_p: rear-left corner (17.6, 1) -> 0.511 > 0.48 (clears it);
    # left midpoint (20, 1) -> 0.45 and front-left corner (22.4, 1) -> 0.40 (blocked);
    # all other points have y_p <= 0 and are blocked too.  Exactly one point is seen.
    actors = scene((20, 0, 0, *CAR), (10, -1.01, 0, 1, 1.49))
    pts = ref.point_visibility(CAM, 0.0, *actors, FRONT_CAMERA_FOV, 50.0)
    assert pts[0].tolist() == [False, False, True] + [False] * 6
    assert see(actors).tolist() == [True, True]
    # raising the occluder top to 0.6 > 0.511 hides the last corner
    assert see(scene((20, 0, 0, *CAR), (10, -0.95, 0, 1, 1.55))).tolist() == [False, True]


def test_field_of_view():
    # pedestrian 20 m away at a bearing of +60 deg (and -60 deg): outside the 110 deg fov
    # (half angle 55 deg; the 0.3 m box subtends < 1.3 deg), inside the 360 deg rig's field
    b = math.radians(60.0)
    for sign in (1.0, -1.0):
        actors = scene((20 * math.cos(b), sign * 20 * math.sin(b), 0, 0.3, 0.3))
        assert see(actors).tolist() == [False]
        assert see(actors, fov=SURROUND_FOV).tolist() == [True]
    # straight behind the camera: only the six-camera rig sees it
    actors = scene((-15, 0, 0, *CAR))
    assert see(actors).tolist() == [False]
    assert see(actors, fov=SURROUND_FOV).tolist() == [True]
    # the field follows the camera heading: looking north, the +60 deg pedestrian (30 deg
    # off the heading) is in view
    actors = scene((20 * math.cos(b), 20 * math.sin(b), 0, 0.3, 0.3))
    assert see(actors, cam_yaw=np.float32(np.pi / 2)).tolist() == [True]


def test_max_range():
    # nearest sample point of a car centred 60 m ahead is 57.6 m away
    actors = scene((60, 0, 0, *CAR))
    assert see(actors, rng=np.float32(50.0)).tolist() == [False]
    assert see(actors, rng=np.float32(58.0)).tolist() == [True]


def test_non_present_occluder_does_not_block():
    actors = scene((20, 0, 0, *CAR), (10, 0, 0, 1, 5, False))
    assert see(actors).tolist() == [True, False]


def test_padding_changes_nothing():
    base = scene((20, 0, 0, *CAR), (10, -1.01, 0, 1, 1.49), (30, 8, 0.5, *CAR))
    want = see(base)
    # zero-extent padding at the camera position, plus non-present garbage boxes that would
    # hide everything if they counted
    padded = scene(
        (20, 0, 0, *CAR),
        (10, -1.01, 0, 1, 1.49),
        (30, 8, 0.5, *CAR),
        (5, 0, 0, 3, 20, False),
        (0, 0, 0, 5, 5, False),
        pad=3,
    )
    got = see(padded)
    assert got[:3].tolist() == want.tolist()
    assert not got[3:].any()


def test_camera_inside_a_box_sees_only_that_box():
    # a present box around the camera blocks every sight line that leaves it
    actors = scene((20, 0, 0, *CAR), (0, 0, 0, 2, 2))
    assert see(actors, fov=SURROUND_FOV).tolist() == [False, True]


def test_matches_reference_on_random_scenes():
    rng = np.random.default_rng(7)
    n, a = 24, 8
    centers = rng.uniform(-30, 30, (n, a, 2)).astype(np.float32)
    yaws = rng.uniform(-np.pi, np.pi, (n, a)).astype(np.float32)
    ext = rng.uniform(0.3, 3.0, (n, a, 2)).astype(np.float32)
    present = rng.uniform(size=(n, a)) < 0.8
    cams = rng.uniform(-5, 5, (n, 2)).astype(np.float32)
    cam_yaws = rng.uniform(-np.pi, np.pi, n).astype(np.float32)
    for fov in (FRONT_CAMERA_FOV, SURROUND_FOV):
        f = jax.jit(jax.vmap(functools.partial(vis.visible_actors, fov_deg=fov, max_range=RANGE)))
        got = np.asarray(f(cams, cam_yaws, centers, yaws, ext, present))
        want = np.array(
            [
                ref.visible_actors(
                    cams[i], float(cam_yaws[i]), centers[i], yaws[i], ext[i], present[i], fov, 50.0
                )
                for i in range(n)
            ]
        )
        assert 0 < want.sum() < present.sum()  # some actors seen, some hidden
        np.testing.assert_array_equal(got, want)
        # batch invariance: vmap(f)(batch)[i] == f(batch[i])
        for i in (0, n - 1):
            single = see(
                (centers[i], yaws[i], ext[i], present[i]), fov, RANGE, cams[i], cam_yaws[i]
            )
            np.testing.assert_array_equal(got[i], single)


def test_compiles_once():
    traces = []

    @functools.partial(jax.jit, static_argnames=("fov_deg",))
    def f(cam, yaw, c, y, e, p, fov_deg):
        traces.append(1)
        return vis.visible_actors(cam, yaw, c, y, e, p, fov_deg, RANGE)

    for x in (10.0, 20.0, 30.0):
        c, y, e, p = scene((x, 0, 0, *CAR), (5, 3, 0, 1, 1), pad=2)
        f(CAM, CAM_YAW, c, y, e, p, FRONT_CAMERA_FOV)
    assert len(traces) == 1


# ---------------------------------------------------------------------------------------------
# range image
# ---------------------------------------------------------------------------------------------
def test_ray_angles_layout():
    a = vis.ray_angles(FRONT_CAMERA_FOV, 11)
    np.testing.assert_allclose(a[[0, 5, 10]], np.radians([-55, 0, 55]), atol=1e-6)
    a = vis.ray_angles(SURROUND_FOV, 8)
    # full circle at 45 deg spacing, ray 4 straight ahead, no duplicated seam
    np.testing.assert_allclose(a, np.radians(np.arange(-180, 180, 45)), atol=1e-6)
    assert vis.ray_angles(FRONT_CAMERA_FOV, 1).tolist() == [0.0]


def test_range_image_box_ahead():
    # box x in [9, 11], y in [-1, 1]: the central ray (index 5 of 11) hits the face x = 9.
    # the +-11 deg rays reach y = 9 tan(11 deg) = 1.75 at x = 9 and miss (all the others too)
    c, y, e, p = scene((10, 0, 0, 1, 1), pad=2)
    r, idx = ranges_of(CAM, CAM_YAW, c, y, e, p, FRONT_CAMERA_FOV, 11, RANGE)
    assert float(r[5]) == pytest.approx(9.0, abs=1e-5) and int(idx[5]) == 0
    mask = np.arange(11) != 5
    np.testing.assert_allclose(np.asarray(r)[mask], 50.0)
    assert np.all(np.asarray(idx)[mask] == -1)
    assert r.dtype == jnp.float32 and idx.dtype == jnp.int32
    # the six-camera rig with 8 rays: ray 4 looks ahead (9 m), ray 0 looks back (nothing)
    r, idx = ranges_of(CAM, CAM_YAW, c, y, e, p, SURROUND_FOV, 8, RANGE)
    assert float(r[4]) == pytest.approx(9.0, abs=1e-5) and int(idx[4]) == 0
    assert float(r[0]) == 50.0 and int(idx[0]) == -1
    # nearest box wins; beyond max_range is capped and reported as no hit
    c, y, e, p = scene((30, 0, 0, 1, 1), (10, 0, 0, 1, 1), (70, 0, 0, 1, 1), pad=1)
    r, idx = ranges_of(CAM, CAM_YAW, c, y, e, p, FRONT_CAMERA_FOV, 11, RANGE)
    assert float(r[5]) == pytest.approx(9.0, abs=1e-5) and int(idx[5]) == 1
    c, y, e, p = scene((70, 0, 0, 1, 1))
    r, idx = ranges_of(CAM, CAM_YAW, c, y, e, p, FRONT_CAMERA_FOV, 11, RANGE)
    assert float(r[5]) == 50.0 and int(idx[5]) == -1


def test_range_image_matches_reference():
    rng = np.random.default_rng(8)
    c = rng.uniform(-25, 25, (10, 2)).astype(np.float32)
    y = rng.uniform(-np.pi, np.pi, 10).astype(np.float32)
    e = rng.uniform(0.3, 3.0, (10, 2)).astype(np.float32)
    p = rng.uniform(size=10) < 0.8
    cam, cam_yaw = np.float32([1.0, -2.0]), np.float32(0.7)
    for fov, n in ((FRONT_CAMERA_FOV, 33), (SURROUND_FOV, 64)):
        r, idx = ranges_of(cam, cam_yaw, c, y, e, p, fov, n, RANGE)
        want_r, want_idx = ref.range_image(cam, float(cam_yaw), c, y, e, p, fov, n, 50.0)
        assert (want_idx >= 0).sum() > 3
        np.testing.assert_array_equal(idx, want_idx)
        np.testing.assert_allclose(r, want_r, atol=1e-3)


def test_range_image_gradients_finite_with_padding():
    # one real box ahead, padded zero-extent slots at the camera position and elsewhere
    c, y, e, p = scene((10, 0, 0, 1, 1), (0, 0, 0, 0, 0, False), (5, 0, 0, 0, 0, False), pad=2)

    def total(centers, yaws, extents, cam):
        r, _ = vis.range_image(cam, CAM_YAW, centers, yaws, extents, p, FRONT_CAMERA_FOV, 11, RANGE)
        return jnp.sum(r)

    grads = jax.jit(jax.grad(total, argnums=(0, 1, 2, 3)))(c, y, e, CAM)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in grads)
    # only the central ray hits the box face x = cx - ex: d(sum)/d(cx) = 1, d/d(ex) = -1
    np.testing.assert_allclose(grads[0][0], [1.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(grads[2][0], [-1.0, 0.0], atol=1e-5)
    np.testing.assert_allclose(grads[0][1:], 0.0)


# ---------------------------------------------------------------------------------------------
# static occluders (buildings, walls, parked vehicles)
# ---------------------------------------------------------------------------------------------
def occluders(*boxes, pad: int = 2) -> Occluders:
    """Occluders given as (x, y, yaw, half_length, half_width); ``pad`` invalid slots."""
    rows = [tuple(b) for b in boxes] + [(0.0, 0.0, 0.0, 0.0, 0.0)] * pad
    arr = np.array(rows, np.float32).reshape(-1, 5)
    n = arr.shape[0]
    return Occluders(
        center=jnp.asarray(arr[:, :2]), yaw=jnp.asarray(arr[:, 2]),
        extent=jnp.asarray(arr[:, 3:5]), kind=jnp.full((n,), OCC_BUILDING, jnp.int32),
        valid=jnp.asarray(np.arange(n) < len(boxes)),
    )  # fmt: skip


@functools.partial(jax.jit, static_argnames=("fov_deg",))
def visible_occ(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range, occ):
    return vis.visible_actors(
        cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range, occ
    )


def see_occ(actors, occ, fov=FRONT_CAMERA_FOV, cam=CAM, cam_yaw=CAM_YAW):
    c, y, e, p = actors
    return np.asarray(visible_occ(cam, cam_yaw, c, y, e, p, fov, RANGE, occ))


def test_building_blocks_every_ray_to_an_actor():
    # A car behind a corner building, seen from the camera at the origin looking east.
    # car: x in [27.6, 32.4], y in [13, 15] (centre (30, 14)); building x in [10, 20],
    # y in [2, 12] (centre (15, 7), half extents (5, 5)).  The sight line to a car point
    # (xp, yp) has slope yp / xp in [13 / 32.4, 15 / 27.6] = [0.401, 0.543]: at the building's
    # near face x = 10 it is at y = 10 yp / xp in [4.0, 5.4] inside [2, 12] -> blocked, for
    # all 9 sample points.  Bearing of the centre = atan(14/30) = 25 deg, inside the field.
    car = scene((30, 14, 0, *CAR))
    assert see(car).tolist() == [True]  # without the building: in plain view
    assert see_occ(car, occluders((15, 7, 0, 5, 5))).tolist() == [False]
    # the 360-degree rig is blocked the same way
    assert see_occ(car, occluders((15, 7, 0, 5, 5)), fov=SURROUND_FOV).tolist() == [False]
    # an invalid (padding) occluder at the same place blocks nothing
    padded = occluders((15, 7, 0, 5, 5))
    padded = padded.replace(valid=jnp.zeros_like(padded.valid))
    assert see_occ(car, padded).tolist() == [True]


def test_gap_between_buildings_lets_one_ray_through():
    # Two buildings leave a gap between y = 4.6 and y = 5.4 at x in [10, 20]:
    # lower x in [10, 20], y in [0, 4.6] (centre (15, 2.3), half (5, 2.3));
    # upper x in [10, 20], y in [5.4, 12] (centre (15, 8.7), half (5, 3.3)).
    # A sight line to (xp, yp) passes the gap only if it stays in [4.6, 5.4] over x in [10, 20]:
    # y(10) = 10 k >= 4.6 and y(20) = 20 k <= 5.4 with k = yp / xp, i.e. k in [0.46, 0.27] -
    # empty.  So make the buildings thin (x in [14.5, 15.5]): k in [4.6 / 14.5, 5.4 / 15.5]
    # = [0.317, 0.348].  The car centre (40, 13.2) has k = 0.330 -> passes, and so do the
    # corners (37.6, 12.2) k = 0.325 and (42.4, 14.2) k = 0.335; the other six points
    # (k = 0.288, 0.305, 0.311, 0.351, 0.355, 0.378) are blocked.
    car = scene((40, 13.2, 0, *CAR))
    gap = occluders((15, 2.3, 0, 0.5, 2.3), (15, 8.7, 0, 0.5, 3.3))
    assert see_occ(car, gap).tolist() == [True]
    # closing the gap (one wall from y = 0 to 12) hides the car
    assert see_occ(car, occluders((15, 6.0, 0, 0.5, 6.0))).tolist() == [False]


def test_occluders_are_never_targets_and_shape_the_range_image():
    # one actor box ahead at x in [29, 31]; a wall at x in [9, 11] blocks the central ray first
    c, y, e, p = scene((30, 0, 0, 1, 1), pad=1)
    occ = occluders((10, 0, 0, 1, 1))
    vis_mask = see_occ((c, y, e, p), occ)
    assert vis_mask.shape == (2,) and vis_mask.tolist() == [False, False]
    r, idx = jax.jit(
        functools.partial(vis.range_image, fov_deg=FRONT_CAMERA_FOV, num_rays=11),
    )(CAM, CAM_YAW, c, y, e, p, max_range=RANGE, occluders=occ)
    # central ray hits the occluder face x = 9; its index is A + k = 2 + 0
    assert float(r[5]) == pytest.approx(9.0, abs=1e-5) and int(idx[5]) == 2


def test_ego_collides_with_an_occluder():
    # the ego drives straight into a wall across its lane: the collision gate fails
    wall = OccluderSpec(np.array([20.0, 0.0]), 0.0, (0.5, 3.0), OCC_WALL, "wall")
    world = straight_scene([], length=60.0, occluders=[wall])
    end = TickEnd(
        ego=world.ego0.replace(xy=jnp.asarray([18.0, 0.0], jnp.float32)),
        actors=world.actors0, present=jnp.zeros(world.actors.num, bool),
        protocol=ProtocolState.initial(), t=jnp.float32(1.0), progress=jnp.float32(18.0),
        dist_to_route=jnp.float32(0.0), arc_before=jnp.float32(17.9), arc_now=jnp.float32(18.0),
        light=jnp.int32(0), justified=jnp.asarray(False), fault=jnp.asarray(False),
    )  # fmt: skip
    sample = measure(world, end, DEFAULT_SCORING)
    # ego front at 18 + 2.45 = 20.45 > wall face 19.5, moving at 8 m/s -> collision
    assert bool(sample.collision)
    at_rest = measure(world, end.replace(ego=end.ego.replace(speed=0.0)), DEFAULT_SCORING)
    assert not bool(at_rest.collision)  # contacts at standstill are ignored (leaderboard)


def test_six_camera_rig_is_blocked_by_static_occluders():
    # The 360-degree rig of the dataset and of Observation.surround: a car parked 20 m behind the
    # ego (x in [-22.3, -17.7], |y| <= 1) and a wall across the road between them (x in
    # [-10.5, -9.5], |y| <= 6).  Camera at x = -1.5 (CAMERA_BACK_OFFSET behind the centre).
    # Every sight line to a car point has |y| <= 1 * 8.5 / 16.2 < 6 at x = -10: blocked.  Ray 0
    # of the rig looks straight back (bearing -pi): it meets the wall's face x = -9.5 at 8.0 m
    # (a wall ray, class NUM_ACTOR_KINDS + OCC_WALL), or without the wall the car's face
    # x = -17.7 at 16.2 m (class KIND_VEHICLE).
    from lantern_jax.core.constants import (
        KIND_VEHICLE,
        NUM_ACTOR_KINDS,
        RAY_CLASS_NAMES,
        SURROUND_FOV,
    )
    from lantern_jax.scenarios.handmade import ActorSpec
    from lantern_jax.sim.sense import SURROUND_RAYS, camera_view

    assert vis.ray_angles(SURROUND_FOV, SURROUND_RAYS)[0] == pytest.approx(-math.pi)
    car = ActorSpec(path=np.array([[-20.0, 0.0]]), extent=(2.3, 1.0))
    wall = OccluderSpec(np.array([-10.0, 0.0]), math.pi / 2, (6.0, 0.5), OCC_WALL, "wall")
    rig = jax.jit(lambda w: camera_view(w, w.ego0, w.actors0, SURROUND_FOV, SURROUND_RAYS))

    open_view = rig(straight_scene([car], length=60.0))
    assert bool(open_view.visible[0])
    assert float(open_view.ranges[0]) == pytest.approx(16.2, abs=1e-4)
    assert int(open_view.hit_class[0]) == KIND_VEHICLE

    walled = rig(straight_scene([car], length=60.0, occluders=[wall]))
    assert not bool(walled.visible[0])
    assert float(walled.ranges[0]) == pytest.approx(8.0, abs=1e-4)
    assert int(walled.hit_class[0]) == NUM_ACTOR_KINDS + OCC_WALL
    assert RAY_CLASS_NAMES[int(walled.hit_class[0])] == "wall"


def test_front_camera_view_equals_the_simulators_front_camera_on_a_junction():
    # The dataset's front rig (camera_view at 110 deg) and the closed loop's front camera
    # (sense) see the same world the same way, corner buildings included: LWW's first pair,
    # whose wrong-way car waits hidden behind the buildings and the waiting truck.
    from lantern_jax.scenarios.families import build_pair
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.sim.sense import FRONT_RAYS, camera_view, sense

    pair = next(p for p in load_suite().pairs if p.family == "LWW")
    world = build_pair(pair.params)[0]
    assert bool(np.asarray(world.occluders.valid).any())

    @jax.jit
    def both(w):
        e = w.ego0
        percept = sense(w, e, w.actors0, jnp.float32(0.0), jnp.float32(0.0), jnp.float32(0.0))
        return percept, camera_view(w, e, w.actors0, FRONT_CAMERA_FOV, FRONT_RAYS)

    percept, view = both(world)
    np.testing.assert_array_equal(np.asarray(view.visible), np.asarray(percept.visible))
    np.testing.assert_array_equal(np.asarray(view.ranges), np.asarray(percept.ranges))
    np.testing.assert_array_equal(np.asarray(view.hit_class), np.asarray(percept.range_class))
    # some front rays end on a corner building (class NUM_ACTOR_KINDS + OCC_BUILDING)
    from lantern_jax.core.constants import NUM_ACTOR_KINDS

    assert (np.asarray(percept.range_class) == NUM_ACTOR_KINDS + OCC_BUILDING).any()
    assert not bool(view.visible[world.config.hazard_index])  # the premise: hidden at start
