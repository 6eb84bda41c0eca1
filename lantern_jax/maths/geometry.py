"""Planar geometry: frames, oriented boxes, box distances and rays (pure JAX, one scenario).

Frames (see :mod:`lantern_jax.core.constants`):

* **World frame**: x east, y north, metres; yaw in radians counter-clockwise from +x.
* **Ego frame** (policy convention of the paper): x forward, y to the **right**, metres.
* **Box frame** (internal): x along the box heading, y to the box's left.

A box is ``(center (2,), yaw (), extent (2,))`` with ``extent = (half length, half width)``.
Every function works on one scenario; the ``*_boxes`` helpers broadcast one query against the
``A`` padded actor slots in a single vectorised expression, and batches of scenarios are made
with ``jax.vmap`` outside.

All functions are jittable and vmappable, compute in float32, and keep values *and* gradients
finite for degenerate input (zero-extent padded boxes, coincident points, rays parallel to a
box face): square roots and divisions are guarded on their input as well as their output
("double where").  Padded slots are not masked here; callers mask with their ``valid`` flags.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import BIG

Array = jax.Array

TWO_PI = 2.0 * math.pi
PARALLEL_EPS = 1e-6  # |ray direction component| in a box frame below which the ray is parallel
SQRT_EPS = 1e-12  # m^2, squared lengths below this are treated as zero by ``safe_norm``

# corner signs in the order front-left, rear-left, rear-right, front-right (counter-clockwise)
_CORNER_SX = np.array([1.0, -1.0, -1.0, 1.0], np.float32)
_CORNER_SY = np.array([1.0, 1.0, -1.0, -1.0], np.float32)


def _f32(x) -> Array:
    return jnp.asarray(x, jnp.float32)


# ---------------------------------------------------------------------------------------------
# scalars and frames
# ---------------------------------------------------------------------------------------------
def safe_sqrt(x: Array) -> Array:
    """Square root with a finite gradient everywhere.

    Args:
        x: (...) float32, non-negative input (e.g. a squared distance in m^2).

    Returns:
        (...) float32, ``sqrt(x)`` where ``x > SQRT_EPS`` and 0 elsewhere; the gradient is 0
        below the threshold instead of infinite.
    """
    x = _f32(x)
    ok = x > SQRT_EPS
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0)


def safe_norm(v: Array) -> Array:
    """Euclidean norm over the last axis with a finite gradient at the zero vector.

    Args:
        v: (..., 2) float32 vectors (any last-axis size works).

    Returns:
        (...) float32 norms, same unit as ``v``.
    """
    v = _f32(v)
    return safe_sqrt(jnp.sum(v * v, axis=-1))


def wrap_angle(a: Array) -> Array:
    """Wrap angles to ``[-pi, pi)``.

    Args:
        a: (...) float32 angles, rad.

    Returns:
        (...) float32 angles in ``[-pi, pi)``, rad (gradient 1).
    """
    a = _f32(a)
    w = jnp.mod(a + jnp.pi, TWO_PI) - jnp.pi
    # float rounding in ``mod`` can land exactly on the upper end
    return jnp.where(w >= jnp.pi, w - TWO_PI, w)


def rotate(v: Array, angle: Array) -> Array:
    """Rotate vectors counter-clockwise by ``angle``.

    Args:
        v: (..., 2) float32 vectors.
        angle: float32 angle(s) in rad, broadcastable against ``v[..., 0]``.

    Returns:
        (..., 2) float32 rotated vectors, same unit as ``v``.
    """
    v, angle = _f32(v), _f32(angle)
    c, s = jnp.cos(angle), jnp.sin(angle)
    x, y = v[..., 0], v[..., 1]
    return jnp.stack([c * x - s * y, s * x + c * y], axis=-1)


def world_to_ego_vec(vec: Array, ego_yaw: Array) -> Array:
    """Express world-frame free vectors (e.g. velocities) in the ego frame.

    Args:
        vec: (..., 2) float32 vectors in the world frame (any unit, e.g. m/s).
        ego_yaw: () float32 ego heading, rad, counter-clockwise from +x.

    Returns:
        (..., 2) float32 vectors in the ego frame (x forward, y right), same unit.
    """
    vec, ego_yaw = _f32(vec), _f32(ego_yaw)
    c, s = jnp.cos(ego_yaw), jnp.sin(ego_yaw)
    x, y = vec[..., 0], vec[..., 1]
    return jnp.stack([c * x + s * y, s * x - c * y], axis=-1)


def ego_to_world_vec(vec: Array, ego_yaw: Array) -> Array:
    """Express ego-frame free vectors in the world frame (inverse of :func:`world_to_ego_vec`).

    Args:
        vec: (..., 2) float32 vectors in the ego frame (x forward, y right).
        ego_yaw: () float32 ego heading, rad.

    Returns:
        (..., 2) float32 vectors in the world frame, same unit.
    """
    # the map (x, y) -> (c x + s y, s x - c y) is a reflection, hence its own inverse
    return world_to_ego_vec(vec, ego_yaw)


def world_to_ego(points: Array, ego_xy: Array, ego_yaw: Array) -> Array:
    """Transform world-frame points into the ego frame.

    Args:
        points: (..., 2) float32 points, m, world frame.
        ego_xy: (2,) float32 ego reference point (box centre), m, world frame.
        ego_yaw: () float32 ego heading, rad.

    Returns:
        (..., 2) float32 points, m, ego frame (x forward, y right).
    """
    return world_to_ego_vec(_f32(points) - _f32(ego_xy), ego_yaw)


def ego_to_world(points: Array, ego_xy: Array, ego_yaw: Array) -> Array:
    """Transform ego-frame points into the world frame (inverse of :func:`world_to_ego`).

    Args:
        points: (..., 2) float32 points, m, ego frame (x forward, y right).
        ego_xy: (2,) float32 ego reference point, m, world frame.
        ego_yaw: () float32 ego heading, rad.

    Returns:
        (..., 2) float32 points, m, world frame.
    """
    return ego_to_world_vec(points, ego_yaw) + _f32(ego_xy)


# ---------------------------------------------------------------------------------------------
# boxes
# ---------------------------------------------------------------------------------------------
def box_corners(center: Array, yaw: Array, extent: Array) -> Array:
    """Corners of oriented boxes, counter-clockwise from the front-left corner.

    Args:
        center: (..., 2) float32 box centres, m, world frame.
        yaw: (...) float32 box headings, rad.
        extent: (..., 2) float32 (half length, half width), m.

    Returns:
        (..., 4, 2) float32 corners (front-left, rear-left, rear-right, front-right), m.
    """
    center, yaw, extent = _f32(center), _f32(yaw), _f32(extent)
    c, s = jnp.cos(yaw)[..., None], jnp.sin(yaw)[..., None]
    lx = _CORNER_SX * extent[..., 0:1]  # (..., 4) along the heading
    ly = _CORNER_SY * extent[..., 1:2]  # (..., 4) to the left
    x = center[..., 0:1] + c * lx - s * ly
    y = center[..., 1:2] + s * lx + c * ly
    return jnp.stack([x, y], axis=-1)


def _pair_overlap_distance(c1, yaw1, e1, c2, yaw2, e2) -> tuple[Array, Array]:
    """Overlap flag and surface distance of box pairs; all arguments broadcast elementwise.

    The distance between two disjoint convex polygons is attained at a corner of one of them,
    so it is the minimum over the 8 corners of the distance from that corner to the other box
    (computed in the other box's frame as ``|max(|q| - e, 0)|``).  Overlap is decided by the
    separating-axis theorem on the 4 box axes; touching boxes count as overlapping.
    """
    c1, yaw1, e1 = _f32(c1), _f32(yaw1), _f32(e1)
    c2, yaw2, e2 = _f32(c2), _f32(yaw2), _f32(e2)
    ca1, sa1 = jnp.cos(yaw1), jnp.sin(yaw1)
    ca2, sa2 = jnp.cos(yaw2), jnp.sin(yaw2)
    e1x, e1y = e1[..., 0], e1[..., 1]
    e2x, e2y = e2[..., 0], e2[..., 1]
    dx, dy = c2[..., 0] - c1[..., 0], c2[..., 1] - c1[..., 1]  # centre 1 -> centre 2

    # axes u = (cos, sin), v = (-sin, cos); u1.u2 = v1.v2 = ca, u1.v2 = -(v1.u2) = cb
    ca = ca1 * ca2 + sa1 * sa2
    cb = sa1 * ca2 - ca1 * sa2
    aca, acb = jnp.abs(ca), jnp.abs(cb)
    d_u1, d_v1 = dx * ca1 + dy * sa1, -dx * sa1 + dy * ca1  # d in box-1 frame
    d_u2, d_v2 = dx * ca2 + dy * sa2, -dx * sa2 + dy * ca2  # d in box-2 frame
    separated = (
        (jnp.abs(d_u1) > e1x + e2x * aca + e2y * acb)
        | (jnp.abs(d_v1) > e1y + e2x * acb + e2y * aca)
        | (jnp.abs(d_u2) > e2x + e1x * aca + e1y * acb)
        | (jnp.abs(d_v2) > e2y + e1x * acb + e1y * aca)
    )

    sx, sy = _CORNER_SX, _CORNER_SY  # (4,)

    def _corner_d2(bx, by, ex, ey, ox_x, ox_y, oy_x, oy_y, fx, fy):
        # corners b + sx*ex*ox + sy*ey*oy of one box, in the frame of the box with extent (fx, fy)
        px = bx[..., None] + sx * (ex * ox_x)[..., None] + sy * (ey * oy_x)[..., None]
        py = by[..., None] + sx * (ex * ox_y)[..., None] + sy * (ey * oy_y)[..., None]
        qx = jnp.maximum(jnp.abs(px) - fx[..., None], 0.0)
        qy = jnp.maximum(jnp.abs(py) - fy[..., None], 0.0)
        return jnp.min(qx * qx + qy * qy, axis=-1)

    # corners of box 1 in box-2 frame: base -d (in frame 2), u1 -> (ca, cb), v1 -> (-cb, ca)
    d2_12 = _corner_d2(-d_u2, -d_v2, e1x, e1y, ca, cb, -cb, ca, e2x, e2y)
    # corners of box 2 in box-1 frame: base d (in frame 1), u2 -> (ca, -cb), v2 -> (cb, ca)
    d2_21 = _corner_d2(d_u1, d_v1, e2x, e2y, ca, -cb, cb, ca, e1x, e1y)
    dist = safe_sqrt(jnp.minimum(d2_12, d2_21))
    overlap = ~separated
    return overlap, jnp.where(overlap, 0.0, dist)


def boxes_overlap(c1: Array, yaw1: Array, e1: Array, c2: Array, yaw2: Array, e2: Array) -> Array:
    """Whether two oriented boxes overlap (separating-axis test; touching counts as overlap).

    Args:
        c1: (2,) float32 centre of box 1, m, world frame.
        yaw1: () float32 heading of box 1, rad.
        e1: (2,) float32 (half length, half width) of box 1, m.
        c2: (2,) float32 centre of box 2, m.
        yaw2: () float32 heading of box 2, rad.
        e2: (2,) float32 half extents of box 2, m.

    Returns:
        () bool, True when the boxes share at least one point.
    """
    return _pair_overlap_distance(c1, yaw1, e1, c2, yaw2, e2)[0]


def box_distance(c1: Array, yaw1: Array, e1: Array, c2: Array, yaw2: Array, e2: Array) -> Array:
    """Surface-to-surface distance between two oriented boxes, 0 when they overlap.

    Args:
        c1: (2,) float32 centre of box 1, m, world frame.
        yaw1: () float32 heading of box 1, rad.
        e1: (2,) float32 (half length, half width) of box 1, m.
        c2: (2,) float32 centre of box 2, m.
        yaw2: () float32 heading of box 2, rad.
        e2: (2,) float32 half extents of box 2, m.

    Returns:
        () float32 distance, m (>= 0); gradients are finite everywhere.
    """
    return _pair_overlap_distance(c1, yaw1, e1, c2, yaw2, e2)[1]


def overlap_with_boxes(
    c: Array, yaw: Array, e: Array, centers: Array, yaws: Array, extents: Array
) -> Array:
    """Overlap of one box against ``A`` boxes (e.g. the ego against every actor slot).

    Args:
        c: (2,) float32 centre of the query box, m, world frame.
        yaw: () float32 heading of the query box, rad.
        e: (2,) float32 half extents of the query box, m.
        centers: (A, 2) float32 box centres, m.
        yaws: (A,) float32 box headings, rad.
        extents: (A, 2) float32 box half extents, m.

    Returns:
        (A,) bool overlap flags (padded slots are not masked).
    """
    return _pair_overlap_distance(c, yaw, e, centers, yaws, extents)[0]


def distance_to_boxes(
    c: Array, yaw: Array, e: Array, centers: Array, yaws: Array, extents: Array
) -> Array:
    """Surface distance of one box to ``A`` boxes, 0 where they overlap.

    Args:
        c: (2,) float32 centre of the query box, m, world frame.
        yaw: () float32 heading of the query box, rad.
        e: (2,) float32 half extents of the query box, m.
        centers: (A, 2) float32 box centres, m.
        yaws: (A,) float32 box headings, rad.
        extents: (A, 2) float32 box half extents, m.

    Returns:
        (A,) float32 distances, m (padded slots are not masked).
    """
    return _pair_overlap_distance(c, yaw, e, centers, yaws, extents)[1]


# ---------------------------------------------------------------------------------------------
# rays and segments
# ---------------------------------------------------------------------------------------------
def _to_box_frame(px: Array, py: Array, ca: Array, sa: Array) -> tuple[Array, Array]:
    return px * ca + py * sa, -px * sa + py * ca


def _slab_axis(o: Array, d: Array, e: Array) -> tuple[Array, Array]:
    """Entry/exit ray parameters for one slab ``|x| <= e`` of a box (box frame)."""
    parallel = jnp.abs(d) < PARALLEL_EPS
    inv = 1.0 / jnp.where(parallel, 1.0, d)
    t1 = (-e - o) * inv
    t2 = (e - o) * inv
    inside = jnp.abs(o) <= e
    near = jnp.where(parallel, jnp.where(inside, -BIG, BIG), jnp.minimum(t1, t2))
    far = jnp.where(parallel, jnp.where(inside, BIG, -BIG), jnp.maximum(t1, t2))
    return near, far


def _ray_hit_local(ox: Array, oy: Array, dx: Array, dy: Array, ex: Array, ey: Array) -> Array:
    """Slab-method hit distance of rays against boxes, everything in the box frame."""
    nx, fx = _slab_axis(ox, dx, ex)
    ny, fy = _slab_axis(oy, dy, ey)
    t_in = jnp.maximum(nx, ny)
    t_out = jnp.minimum(fx, fy)
    hit = (t_in <= t_out) & (t_out >= 0.0)
    return jnp.where(hit, jnp.clip(t_in, 0.0, BIG), BIG)


def ray_box_intersect(
    origin: Array, direction: Array, center: Array, yaw: Array, extent: Array
) -> Array:
    """Distance along a ray to its first hit with an oriented box (slab method).

    Args:
        origin: (2,) float32 ray origin, m, world frame.
        direction: (2,) float32 unit ray direction, world frame (a non-unit direction gives the
            ray parameter, i.e. distances in units of its length).
        center: (2,) float32 box centre, m.
        yaw: () float32 box heading, rad.
        extent: (2,) float32 (half length, half width), m.

    Returns:
        () float32 distance to the first hit, m; 0 when the origin is inside the box;
        ``constants.BIG`` when the ray misses or the box lies behind the origin.
    """
    origin, direction, center = _f32(origin), _f32(direction), _f32(center)
    yaw, extent = _f32(yaw), _f32(extent)
    ca, sa = jnp.cos(yaw), jnp.sin(yaw)
    ox, oy = _to_box_frame(origin[0] - center[0], origin[1] - center[1], ca, sa)
    dx, dy = _to_box_frame(direction[0], direction[1], ca, sa)
    return _ray_hit_local(ox, oy, dx, dy, extent[0], extent[1])


def _cos_sin(yaws: Array, headings: tuple[Array, Array] | None) -> tuple[Array, Array]:
    """``(cos, sin)`` of ``yaws``, or ``headings`` when the caller has them already."""
    if headings is not None:
        return _f32(headings[0]), _f32(headings[1])
    yaws = _f32(yaws)
    return jnp.cos(yaws), jnp.sin(yaws)


def rays_boxes_hit(
    origins: Array,
    dirs: Array,
    centers: Array,
    yaws: Array,
    extents: Array,
    headings: tuple[Array, Array] | None = None,
) -> Array:
    """Hit distances of ``N`` rays against ``A`` boxes in one broadcasted computation.

    Args:
        origins: (N, 2) float32 ray origins, m, world frame; a shared origin may be passed
            as (2,).
        dirs: (N, 2) float32 unit ray directions, world frame.
        centers: (A, 2) float32 box centres, m.
        yaws: (A,) float32 box headings, rad.
        extents: (A, 2) float32 box half extents, m.
        headings: optional ``(cos(yaws), sin(yaws))``, each (A,) float32, computed once by a
            caller that tests the same boxes many times (every trigonometric element is a
            call into the scalar math library on CPU); ``yaws`` is then not read.

    Returns:
        (N, A) float32 distances along each ray to its first hit with each box, m; 0 when the
        origin is inside the box, ``constants.BIG`` on a miss (padded slots are not masked).
    """
    origins, dirs, centers = _f32(origins), _f32(dirs), _f32(centers)
    extents = _f32(extents)
    ca, sa = _cos_sin(yaws, headings)  # (A,)
    rel = origins[..., None, :] - centers  # (A, 2) for a shared origin, else (N, A, 2)
    ox, oy = _to_box_frame(rel[..., 0], rel[..., 1], ca, sa)
    dx, dy = _to_box_frame(dirs[:, None, 0], dirs[:, None, 1], ca, sa)  # (N, A)
    return _ray_hit_local(ox, oy, dx, dy, extents[:, 0], extents[:, 1])


def segments_hit_boxes(
    starts: Array,
    ends: Array,
    centers: Array,
    yaws: Array,
    extents: Array,
    headings: tuple[Array, Array] | None = None,
) -> Array:
    """Whether closed segments touch oriented boxes (separating axes, no divisions).

    Args:
        starts: (N, 2) float32 segment start points, m, world frame; a shared start may be
            passed as (2,).
        ends: (N, 2) float32 segment end points, m, world frame.
        centers: (A, 2) float32 box centres, m.
        yaws: (A,) float32 box headings, rad.
        extents: (A, 2) float32 box half extents, m.
        headings: optional ``(cos(yaws), sin(yaws))``, each (A,) float32 (as
            :func:`rays_boxes_hit`).

    Returns:
        (N, A) bool, True where segment n and box a share at least one point.
    """
    starts, ends, centers = _f32(starts), _f32(ends), _f32(centers)
    extents = _f32(extents)
    ca, sa = _cos_sin(yaws, headings)
    ex, ey = extents[:, 0], extents[:, 1]
    # The barrier keeps the algebraic simplifier from rewriting these inputs into the (N, A)
    # test.  It does not make XLA compute them once: on CPU the barrier is expanded before the
    # fusion passes (see lantern_jax.maths.split_map, which is what does).
    sx, sy = starts[..., 0], starts[..., 1]
    qx, qy = ends[:, 0], ends[:, 1]
    ca, sa, cx, cy, sx, sy, qx, qy = jax.lax.optimization_barrier(
        (ca, sa, centers[:, 0], centers[:, 1], sx, sy, qx, qy)
    )
    ax, ay = _to_box_frame(sx[..., None] - cx, sy[..., None] - cy, ca, sa)
    bx, by = _to_box_frame(qx[:, None] - cx, qy[:, None] - cy, ca, sa)
    return ~segment_separated_from_box(ax, ay, bx, by, ex, ey)


def segment_separated_from_box(
    ax: Array, ay: Array, bx: Array, by: Array, ex: Array, ey: Array
) -> Array:
    """Separating-axis test of segments against boxes, everything in the box frame
    (elementwise: any broadcastable shapes, in any axis order).

    Args:
        ax, ay: float32, m, the segments' start points in the box frame.
        bx, by: float32, m, their end points in the box frame.
        ex, ey: float32, m, the boxes' half extents.

    Returns:
        bool, True where a separating axis exists (the segment and the box share no point).
    """
    gx, gy = bx - ax, by - ay
    return (
        (jnp.minimum(ax, bx) > ex)
        | (jnp.maximum(ax, bx) < -ex)
        | (jnp.minimum(ay, by) > ey)
        | (jnp.maximum(ay, by) < -ey)
        # axis normal to the segment, (-gy, gx): the segment projects to a single value
        | (jnp.abs(ay * gx - ax * gy) > ex * jnp.abs(gy) + ey * jnp.abs(gx))
    )
