"""Tests for lantern_jax.maths.geometry: hand-built goldens, NumPy reference parity, vmap,
gradients."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import BIG
from lantern_jax.maths import geometry as g

try:  # tests/ as a rootdir-relative folder or as a package
    import reference_numpy_geometry as ref
except ImportError:  # pragma: no cover
    from tests import reference_numpy_geometry as ref

SQ2 = math.sqrt(2.0)

# goldens are checked under jit (compiled once per shape); test_jit_matches_eager covers eager
box_distance = jax.jit(g.box_distance)
boxes_overlap = jax.jit(g.boxes_overlap)
ray_box_intersect = jax.jit(g.ray_box_intersect)


def _f(x):
    return np.asarray(x, np.float32)


def _all_finite(tree) -> bool:
    return all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree.leaves(tree))


# ---------------------------------------------------------------------------------------------
# angles and frames
# ---------------------------------------------------------------------------------------------
def test_wrap_angle_goldens():
    # 3pi/2 -> -pi/2; pi and -pi both map to -pi (half-open interval); 5pi/2 -> pi/2
    a = _f([1.5 * np.pi, np.pi, -np.pi, 2.5 * np.pi, 0.25, -7.0])
    want = [-0.5 * np.pi, -np.pi, -np.pi, 0.5 * np.pi, 0.25, -7.0 + 2 * np.pi]
    np.testing.assert_allclose(g.wrap_angle(a), want, atol=1e-5)


def test_wrap_angle_range():
    a = np.random.default_rng(0).uniform(-100, 100, 5000).astype(np.float32)
    w = np.asarray(g.wrap_angle(a))
    assert np.all(w >= -np.float32(np.pi)) and np.all(w < np.float32(np.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-4)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-4)


def test_rotate_quarter_turn():
    # (1, 0) rotated by +90 deg (counter-clockwise) is (0, 1); (0, 2) becomes (-2, 0)
    out = g.rotate(_f([[1, 0], [0, 2]]), np.float32(np.pi / 2))
    np.testing.assert_allclose(out, [[0, 1], [-2, 0]], atol=1e-6)


def test_world_to_ego_hand_computed():
    # ego at (10, 0) heading north (yaw = pi/2): forward = +y_world, right = +x_world.
    # world (10, 5) is 5 m ahead -> ego (5, 0); world (11, 0) is 1 m to the right -> ego (0, 1)
    ego_xy, yaw = _f([10, 0]), np.float32(np.pi / 2)
    out = g.world_to_ego(_f([[10, 5], [11, 0], [9, -2]]), ego_xy, yaw)
    np.testing.assert_allclose(out, [[5, 0], [0, 1], [-2, -1]], atol=1e-5)
    back = g.ego_to_world(out, ego_xy, yaw)
    np.testing.assert_allclose(back, [[10, 5], [11, 0], [9, -2]], atol=1e-5)


def test_vector_transforms_hand_computed():
    # ego heading north: a velocity of 3 m/s north is 3 m/s forward; 2 m/s east is 2 m/s right
    yaw = np.float32(np.pi / 2)
    out = g.world_to_ego_vec(_f([[0, 3], [2, 0]]), yaw)
    np.testing.assert_allclose(out, [[3, 0], [0, 2]], atol=1e-6)
    np.testing.assert_allclose(g.ego_to_world_vec(out, yaw), [[0, 3], [2, 0]], atol=1e-6)


def test_frame_round_trip_and_reference():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-50, 50, (200, 2)).astype(np.float32)
    ego_xy = _f(rng.uniform(-20, 20, 2))
    yaw = np.float32(rng.uniform(-4, 4))
    ego = np.asarray(g.world_to_ego(pts, ego_xy, yaw))
    np.testing.assert_allclose(g.ego_to_world(ego, ego_xy, yaw), pts, atol=1e-4)
    want = np.array([ref.world_to_ego(p, ego_xy, float(yaw)) for p in pts])
    np.testing.assert_allclose(ego, want, atol=1e-4)
    vec = np.asarray(g.world_to_ego_vec(pts, yaw))
    np.testing.assert_allclose(g.ego_to_world_vec(vec, yaw), pts, atol=1e-4)


# ---------------------------------------------------------------------------------------------
# boxes: goldens
# ---------------------------------------------------------------------------------------------
def test_box_corners_golden():
    # centre (1, 2), yaw 0, half extents (2, 1): x in [-1, 3], y in [1, 3]
    out = g.box_corners(_f([1, 2]), np.float32(0), _f([2, 1]))
    np.testing.assert_allclose(out, [[3, 3], [-1, 3], [-1, 1], [3, 1]], atol=1e-6)
    # yaw 90 deg: the front points north, front-left corner is (1 - 1, 2 + 2) = (0, 4)
    out = g.box_corners(_f([1, 2]), np.float32(np.pi / 2), _f([2, 1]))
    np.testing.assert_allclose(out[0], [0, 4], atol=1e-5)


E = _f([2, 1])  # car-like box: x in [cx-2, cx+2], y in [cy-1, cy+1]
Z = np.float32(0)


@pytest.mark.parametrize(
    "c2, overlap, dist",
    [
        # A spans x in [-2, 2]; B at x=3 spans [1, 5] -> 1 m of overlap
        ([3.0, 0.0], True, 0.0),
        # B at x=4 spans [2, 6] -> faces touch at x = 2 (contact counts as overlap)
        ([4.0, 0.0], True, 0.0),
        # B at x=5.5 spans [3.5, 7.5] -> gap 3.5 - 2 = 1.5 m
        ([5.5, 0.0], False, 1.5),
        # B at y=3.25 spans y in [2.25, 4.25] -> gap 2.25 - 1 = 1.25 m
        ([0.0, 3.25], False, 1.25),
        # B at (5, 3): x in [3, 7], y in [2, 4]; nearest corners (2, 1)-(3, 2) -> sqrt(2)
        ([5.0, 3.0], False, SQ2),
    ],
)
def test_axis_aligned_pairs(c2, overlap, dist):
    c1, c2 = _f([0, 0]), _f(c2)
    assert bool(boxes_overlap(c1, Z, E, c2, Z, E)) == overlap
    assert float(box_distance(c1, Z, E, c2, Z, E)) == pytest.approx(dist, abs=1e-5)
    assert float(box_distance(c2, Z, E, c1, Z, E)) == pytest.approx(dist, abs=1e-5)


def test_rotated_box_corner_distance():
    # A: unit square (half extents 1, 1) at the origin, face at x = 1.
    # B: same square rotated 45 deg at (4, 0); its corner points to -x at distance sqrt(2)
    # from its centre, i.e. at (4 - sqrt 2, 0) = (2.586, 0) -> distance 3 - sqrt(2) = 1.586.
    one = _f([1, 1])
    q = np.float32(np.pi / 4)
    d = box_distance(_f([0, 0]), Z, one, _f([4, 0]), q, one)
    assert float(d) == pytest.approx(3 - SQ2, abs=1e-5)
    assert not bool(boxes_overlap(_f([0, 0]), Z, one, _f([4, 0]), q, one))
    # moved to (2.3, 0): the corner reaches 2.3 - 1.414 = 0.886 < 1 -> overlap, distance 0
    assert bool(boxes_overlap(_f([0, 0]), Z, one, _f([2.3, 0]), q, one))
    assert float(box_distance(_f([0, 0]), Z, one, _f([2.3, 0]), q, one)) == 0.0
    # B rotated 45 deg at (3, 3): its corners lie on the axes through its centre, so the two
    # nearest to A are (3 - sqrt2, 3) and (3, 3 - sqrt2), joined by the edge x + y = 6 - sqrt2.
    # A's corner (1, 1) projects onto that edge at its midpoint, at distance
    # (6 - sqrt2 - 2) / sqrt2 = 2 sqrt2 - 1 = 1.828.
    d = box_distance(_f([0, 0]), Z, one, _f([3, 3]), q, one)
    assert float(d) == pytest.approx(2 * SQ2 - 1, abs=1e-5)


def test_cross_overlap_without_corners_inside():
    # two long thin boxes crossing like a "+": no corner of either is inside the other
    e = _f([3, 0.5])
    c = _f([0, 0])
    assert bool(boxes_overlap(c, Z, e, c, np.float32(np.pi / 2), e))
    assert float(box_distance(c, Z, e, c, np.float32(np.pi / 2), e)) == 0.0


# ---------------------------------------------------------------------------------------------
# rays: goldens
# ---------------------------------------------------------------------------------------------
def test_ray_hits_face():
    # ray from the origin along +x; box (10, 0) half extents (2, 1): near face x = 8
    t = ray_box_intersect(_f([0, 0]), _f([1, 0]), _f([10, 0]), Z, E)
    assert float(t) == pytest.approx(8.0, abs=1e-5)
    # oblique: direction (0.6, 0.8), box x in [9, 11], y in [-5, 15]: enters x = 9 at t = 15
    # (y = 12 there, inside the face)
    t = ray_box_intersect(_f([0, 0]), _f([0.6, 0.8]), _f([10, 5]), Z, _f([1, 10]))
    assert float(t) == pytest.approx(15.0, abs=1e-4)


def test_ray_hits_rotated_corner():
    # unit square rotated 45 deg at (10, 0): its corner on the ray is at x = 10 - sqrt 2
    t = ray_box_intersect(_f([0, 0]), _f([1, 0]), _f([10, 0]), np.float32(np.pi / 4), _f([1, 1]))
    assert float(t) == pytest.approx(10 - SQ2, abs=1e-4)


def test_ray_miss_behind_inside():
    o = _f([0, 0])
    # pointing north, box east of the origin: miss
    assert float(ray_box_intersect(o, _f([0, 1]), _f([10, 0]), Z, E)) == BIG
    # pointing west, box behind: miss
    assert float(ray_box_intersect(o, _f([-1, 0]), _f([10, 0]), Z, E)) == BIG
    # origin inside the box: 0
    assert float(ray_box_intersect(o, _f([0, 1]), _f([0.5, 0.2]), np.float32(0.3), E)) == 0.0
    # parallel to a face and outside its slab: miss; inside the slab: hit
    assert float(ray_box_intersect(_f([0, 1.5]), _f([1, 0]), _f([10, 0]), Z, E)) == BIG
    t = ray_box_intersect(_f([0, 0.5]), _f([1, 0]), _f([10, 0]), Z, E)
    assert float(t) == pytest.approx(8.0, abs=1e-5)


def test_segments_hit_boxes_goldens():
    # box x in [8, 12], y in [-1, 1]
    c, y, e = _f([[10, 0]]), _f([0]), _f([[2, 1]])
    ends = _f([[7.9, 0], [8.1, 0], [20, 0], [20, 3], [20, 1.9]])
    out = np.asarray(jax.jit(g.segments_hit_boxes)(_f([0, 0]), ends, c, y, e))[:, 0]
    # short of the face; just inside; through; passes above (y = 1.2 at x = 8); clips the
    # top-front corner region (y = 0.76 at x = 8)
    np.testing.assert_array_equal(out, [False, True, True, False, True])


# ---------------------------------------------------------------------------------------------
# NumPy reference parity on random boxes
# ---------------------------------------------------------------------------------------------
def _random_pairs(n: int, seed: int):
    rng = np.random.default_rng(seed)
    c1 = rng.uniform(-5, 5, (n, 2))
    c2 = c1 + rng.uniform(-8, 8, (n, 2))
    y1, y2 = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    e1 = rng.uniform(0.2, 3.0, (n, 2))
    e2 = rng.uniform(0.2, 3.0, (n, 2))
    return [_f(x) for x in (c1, y1, e1, c2, y2, e2)]


def test_overlap_and_distance_match_reference():
    c1, y1, e1, c2, y2, e2 = _random_pairs(200, 2)
    ov = np.asarray(jax.jit(jax.vmap(g.boxes_overlap))(c1, y1, e1, c2, y2, e2))
    dist = np.asarray(jax.jit(jax.vmap(g.box_distance))(c1, y1, e1, c2, y2, e2))
    args = [np.asarray(x, float) for x in (c1, y1, e1, c2, y2, e2)]
    want_ov = np.array([ref.boxes_overlap(*[a[i] for a in args]) for i in range(200)])
    want_d = np.array([ref.box_distance(*[a[i] for a in args]) for i in range(200)])
    assert 20 < want_ov.sum() < 180  # both outcomes exercised
    # overlap decisions may only differ on (numerically) touching boxes
    mismatch = ov != want_ov
    assert np.all(want_d[mismatch] < 1e-3) and np.all(dist[mismatch] < 1e-3)
    np.testing.assert_allclose(dist, want_d, atol=2e-4, rtol=1e-5)


def test_ray_box_matches_reference():
    rng = np.random.default_rng(3)
    n = 200
    centers = rng.uniform(-10, 10, (n, 2))
    yaws = rng.uniform(-np.pi, np.pi, n)
    ext = rng.uniform(0.3, 3.0, (n, 2))
    origins = rng.uniform(-20, 20, (n, 2))
    aim = np.arctan2(*(centers - origins)[:, ::-1].T) + rng.normal(0, 0.3, n)
    dirs = np.stack([np.cos(aim), np.sin(aim)], -1)
    origins[:10] = centers[:10] + 0.2 * rng.uniform(-1, 1, (10, 2))  # some inside the box
    args = [_f(x) for x in (origins, dirs, centers, yaws, ext)]
    t = np.asarray(jax.jit(jax.vmap(g.ray_box_intersect))(*args))
    want = np.array(
        [ref.ray_box_intersect(*[np.asarray(a[i], float) for a in args]) for i in range(n)]
    )
    hit = want < BIG
    assert 50 < hit.sum() < 190  # hits and misses both exercised
    np.testing.assert_array_equal(t < BIG, hit)
    np.testing.assert_allclose(t[hit], want[hit], atol=1e-3, rtol=1e-5)
    assert np.all(t[:10] == 0.0)


def test_batched_helpers_match_loops():
    rng = np.random.default_rng(4)
    a = 12
    centers = _f(rng.uniform(-15, 15, (a, 2)))
    yaws = _f(rng.uniform(-np.pi, np.pi, a))
    ext = _f(rng.uniform(0.3, 3.0, (a, 2)))
    c, yaw, e = _f([1.0, -2.0]), np.float32(0.4), _f([2.45, 1.06])
    ov = np.asarray(jax.jit(g.overlap_with_boxes)(c, yaw, e, centers, yaws, ext))
    dist = np.asarray(jax.jit(g.distance_to_boxes)(c, yaw, e, centers, yaws, ext))
    for j in range(a):
        assert ov[j] == bool(boxes_overlap(c, yaw, e, centers[j], yaws[j], ext[j]))
        want = ref.box_distance(c, float(yaw), e, centers[j], float(yaws[j]), ext[j])
        assert dist[j] == pytest.approx(want, abs=2e-4)

    n = 24
    origins = _f(rng.uniform(-15, 15, (n, 2)))
    ang = rng.uniform(-np.pi, np.pi, n)
    dirs = _f(np.stack([np.cos(ang), np.sin(ang)], -1))
    t = np.asarray(jax.jit(g.rays_boxes_hit)(origins, dirs, centers, yaws, ext))
    assert t.shape == (n, a)
    want = ref.rays_boxes_hit(origins, dirs, centers, yaws, ext)
    np.testing.assert_array_equal(t < BIG, want < BIG)
    np.testing.assert_allclose(t, want, atol=1e-3, rtol=1e-5)
    # a shared (2,) origin equals the same origin repeated
    t1 = jax.jit(g.rays_boxes_hit)(origins[0], dirs, centers, yaws, ext)
    t2 = jax.jit(g.rays_boxes_hit)(jnp.broadcast_to(origins[0], (n, 2)), dirs, centers, yaws, ext)
    np.testing.assert_allclose(t1, t2, atol=1e-5)

    # segments: a segment from o to o + L d touches box j iff the ray hits it within L
    seg_len = 12.0
    hits = np.asarray(
        jax.jit(g.segments_hit_boxes)(origins, origins + seg_len * dirs, centers, yaws, ext)
    )
    clear = np.abs(want - seg_len) > 1e-3  # skip numerically ambiguous ends
    np.testing.assert_array_equal(hits[clear], (want <= seg_len)[clear])


# ---------------------------------------------------------------------------------------------
# batching, jit and gradients
# ---------------------------------------------------------------------------------------------
def test_vmap_equals_single_calls():
    c1, y1, e1, c2, y2, e2 = _random_pairs(16, 5)
    batch_d = jax.jit(jax.vmap(g.box_distance))(c1, y1, e1, c2, y2, e2)
    batch_o = jax.jit(jax.vmap(g.boxes_overlap))(c1, y1, e1, c2, y2, e2)
    dirs = _f(np.stack([np.cos(y1), np.sin(y1)], -1))
    batch_t = jax.jit(jax.vmap(g.ray_box_intersect))(c1, dirs, c2, y2, e2)
    for i in range(16):
        assert float(batch_d[i]) == pytest.approx(
            float(box_distance(c1[i], y1[i], e1[i], c2[i], y2[i], e2[i])), abs=1e-6
        )
        assert bool(batch_o[i]) == bool(boxes_overlap(c1[i], y1[i], e1[i], c2[i], y2[i], e2[i]))
        single = ray_box_intersect(c1[i], dirs[i], c2[i], y2[i], e2[i])
        assert float(batch_t[i]) == pytest.approx(float(single), abs=1e-5)


def test_jit_matches_eager():
    c1, y1, e1, c2, y2, e2 = _random_pairs(4, 6)
    for i in range(4):
        args = (c1[i], y1[i], e1[i], c2[i], y2[i], e2[i])
        assert float(jax.jit(g.box_distance)(*args)) == pytest.approx(
            float(g.box_distance(*args)), abs=1e-6
        )


_box_distance_grad = jax.jit(jax.grad(g.box_distance, argnums=(0, 1, 2, 3, 4, 5)))


@pytest.mark.parametrize(
    "c1, e1, c2, e2",
    [
        ([0.0, 0.0], [2.0, 1.0], [6.0, 1.0], [2.0, 1.0]),  # separated
        ([0.0, 0.0], [2.0, 1.0], [0.0, 0.0], [2.0, 1.0]),  # coincident boxes
        ([0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]),  # two padded points at one place
        ([0.0, 0.0], [2.0, 1.0], [0.0, 0.0], [0.0, 0.0]),  # padded point at the centre
        ([5.0, 0.0], [0.0, 0.0], [0.0, 0.0], [2.0, 1.0]),  # padded point outside
        ([2.0, 1.0], [0.0, 0.0], [0.0, 0.0], [2.0, 1.0]),  # padded point on a corner
    ],
)
def test_box_distance_gradients_finite(c1, e1, c2, e2):
    args = (_f(c1), np.float32(0.0), _f(e1), _f(c2), np.float32(0.0), _f(e2))
    grads = _box_distance_grad(*args)
    assert _all_finite(grads)
    if c1 == [0.0, 0.0] and c2 == [6.0, 1.0]:
        # gap along x only (x faces 2 and 4): d(dist)/d(c2_x) = 1, d/d(c1_x) = -1
        np.testing.assert_allclose(grads[3], [1.0, 0.0], atol=1e-5)
        np.testing.assert_allclose(grads[0], [-1.0, 0.0], atol=1e-5)


def test_batched_gradients_finite_with_padding():
    centers = _f([[6, 0], [0, 0], [0, 0], [3, 3]])
    yaws = _f([0.3, 0, 0, 0])
    ext = _f([[2, 1], [0, 0], [0, 0], [0, 0]])  # slots 1..3 are padding
    valid = np.array([True, False, False, False])

    def loss(centers, yaws, ext, c):
        d = g.distance_to_boxes(c, np.float32(0.0), _f([2, 1]), centers, yaws, ext)
        t = g.rays_boxes_hit(c, _f([[1, 0], [0, 1], [0.6, 0.8]]), centers, yaws, ext)
        t = jnp.where(valid, t, 0.0)
        ov = g.overlap_with_boxes(c, np.float32(0.0), _f([2, 1]), centers, yaws, ext)
        return jnp.sum(jnp.where(valid, d, 0.0)) + jnp.sum(jnp.minimum(t, 50.0)) + jnp.sum(ov)

    vg = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3)))
    for c in (_f([0, 0]), _f([1e-7, 0])):
        val, grads = vg(centers, yaws, ext, c)
        assert np.isfinite(float(val))
        assert _all_finite(grads)
