"""Padded polyline utilities: arc length, interpolation along the arc, projection onto the line.

A padded polyline is ``points`` (P, 2) float32 metres, its cumulative arc length ``s`` (P,) float32
metres (0 at the first point) and ``valid`` (P,) bool, a *prefix* mask (the first ``n`` points are
real, the rest is padding).  Every function here handles one polyline and is jittable and
vmappable; gradients stay finite with padding and with zero-length segments (every ``sqrt``,
``arctan2`` and division has its input masked as well as its output).

Conventions:

* the travel direction is the point order; "left" is left of travel (counter-clockwise);
* a polyline with a single valid point is a fixed point with heading 0;
* arcs beyond either end extrapolate linearly along the first / last segment.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import BIG
from lantern_jax.maths.geometry import safe_norm

Array = jax.Array

_EPS2 = 1e-12  # m^2, squared lengths at or below this count as zero


def safe_atan2(y: Array, x: Array) -> Array:
    """``arctan2(y, x)`` that returns 0 (with zero gradient) when ``x = y = 0``.

    Args:
        y: (...) float32.
        x: (...) float32.

    Returns:
        (...) float32, rad, in (-pi, pi].
    """
    ok = (x * x + y * y) > _EPS2
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, y, 0.0), jnp.where(ok, x, 1.0)), 0.0)


def left_normal(heading: Array) -> Array:
    """Unit vector pointing left of travel for a heading.

    Args:
        heading: (...) float32, rad, CCW from +x.

    Returns:
        (..., 2) float32, ``(-sin h, cos h)``.
    """
    return jnp.stack([-jnp.sin(heading), jnp.cos(heading)], axis=-1)


def num_valid(valid: Array) -> Array:
    """Number of valid points of a prefix-masked polyline.

    Args:
        valid: (P,) bool.

    Returns:
        () int32.
    """
    return jnp.sum(valid.astype(jnp.int32))


def arc_length(points: Array, valid: Array) -> Array:
    """Cumulative arc length of a padded polyline.

    Args:
        points: (P, 2) float32, m.
        valid: (P,) bool, prefix mask.

    Returns:
        (P,) float32, m: 0 at the first point, non-decreasing; padded entries hold the last valid
        value.
    """
    seg = safe_norm(points[1:] - points[:-1])  # (P-1,)
    seg = jnp.where(valid[1:] & valid[:-1], seg, 0.0)
    return jnp.concatenate([jnp.zeros((1,), points.dtype), jnp.cumsum(seg)])


def _segment(points: Array, s: Array, valid: Array, i: Array):
    """Start point, start arc, unit direction and non-degeneracy flag of segment ``i``."""
    n = num_valid(valid)
    has_seg = n >= 2
    j = jnp.where(has_seg, i + 1, i)
    p0 = points[i]
    d = points[j] - p0
    length = safe_norm(d)
    ok = has_seg & (length > 0.0)
    u = jnp.where(ok, d / jnp.where(ok, length, 1.0), 0.0)
    return p0, s[i], u, ok


def interpolate(points: Array, s: Array, valid: Array, s_query: Array) -> tuple[Array, Array]:
    """Point and heading at arc ``s_query`` along a padded polyline.

    Beyond the ends the polyline is extended linearly along its first / last segment.  At a
    vertex the heading is that of the following segment.  A zero-length segment has heading 0
    and no extent.

    Args:
        points: (P, 2) float32, m.
        s: (P,) float32, m, cumulative arc length (see :func:`arc_length`).
        valid: (P,) bool, prefix mask.
        s_query: () float32, m, arc length (any real value).

    Returns:
        xy: (2,) float32, m, the point at ``s_query``.
        heading: () float32, rad, CCW from +x, direction of travel at ``s_query``.
    """
    n = num_valid(valid)
    last_seg = jnp.maximum(n - 2, 0)
    passed = jnp.sum((valid[1:] & (s[1:] <= s_query)).astype(jnp.int32))
    i = jnp.clip(passed, 0, last_seg)
    p0, s0, u, ok = _segment(points, s, valid, i)
    xy = p0 + (s_query - s0) * u
    heading = jnp.where(ok, safe_atan2(u[1], u[0]), 0.0)
    return xy, heading


def nearest_segment(points: Array, valid: Array, query: Array) -> tuple[Array, Array]:
    """Distance to a padded polyline and the travel direction of its nearest segment.

    A lean single-query variant of :func:`project` (no arc, no extrapolation) for hot loops such
    as the per-tick lane check.

    Args:
        points: (P, 2) float32, m.
        valid: (P,) bool, prefix mask.
        query: (2,) float32, m.

    Returns:
        distance: () float32, m, to the nearest valid segment (BIG-ish when none).
        direction: (2,) float32, unnormalised direction vector of that segment.
    """
    ax, ay = points[:-1, 0], points[:-1, 1]
    dx, dy = points[1:, 0] - ax, points[1:, 1] - ay
    seg_valid = valid[1:] & valid[:-1]
    len2 = dx * dx + dy * dy
    inv = jnp.where(len2 > _EPS2, 1.0 / jnp.maximum(len2, _EPS2), 0.0)
    rx, ry = query[0] - ax, query[1] - ay
    t = jnp.clip((rx * dx + ry * dy) * inv, 0.0, 1.0)
    ex, ey = rx - t * dx, ry - t * dy
    d2 = jnp.where(seg_valid, ex * ex + ey * ey, BIG)
    best = jnp.min(d2)
    sel = d2 <= best
    direction = jnp.stack([jnp.sum(jnp.where(sel, dx, 0.0)), jnp.sum(jnp.where(sel, dy, 0.0))])
    pos = best > _EPS2
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, best, 1.0)), 0.0), direction


def project_uniform(points: Array, step: float, qs: Array) -> tuple[Array, Array]:
    """Project many points onto a polyline whose points are ``step`` m apart (no padding).

    The policy observation's route (points a fixed arc step apart, starting at the ego's
    projection) is such a polyline, so the arc of segment ``k`` starts at ``k * step``.  Laid
    out segments-major / points-minor with x and y split, which XLA on CPU vectorises far better
    than a (points, segments, 2) layout.  Ties go to the furthest segment; queries behind the
    first point get negative arcs along the first segment's line.

    Args:
        points: (N, 2) float32, m, polyline points ``step`` apart.
        step: static float, m, arc length between consecutive points.
        qs: (M, 2) float32, m, query points.

    Returns:
        arc: (M,) float32, m along the polyline from its first point (negative behind it).
        dist: (M,) float32, m, distance from the polyline.
    """
    a = points[:-1]
    ab = points[1:] - a
    inv = 1.0 / jnp.maximum(jnp.sum(ab * ab, -1), 1e-6)  # (N-1,)
    ax, ay, bx, by = a[:, 0:1], a[:, 1:2], ab[:, 0:1], ab[:, 1:2]
    rx, ry = qs[None, :, 0] - ax, qs[None, :, 1] - ay  # (N-1, M)
    along = (rx * bx + ry * by) * inv[:, None]
    u = jnp.clip(along, 0.0, 1.0)
    dx, dy = rx - u * bx, ry - u * by
    d2 = dx * dx + dy * dy
    m = jnp.min(d2, axis=0)
    k = jnp.arange(a.shape[0], dtype=jnp.float32)[:, None]
    arc = jnp.max(jnp.where(d2 <= m[None, :], (k + u) * step, -BIG), axis=0)
    # Behind the first point: extend the first segment backwards (negative arcs).
    back = along[0] * step
    arc = jnp.where((arc <= 0.0) & (back < 0.0), back, arc)
    return arc, jnp.sqrt(jnp.maximum(m, 1e-12))


def project(
    points: Array, s: Array, valid: Array, query: Array
) -> tuple[Array, Array, Array, Array]:
    """Project a point onto a padded polyline (nearest segment).

    The nearest segment is the one with the smallest Euclidean distance (ties go to the first).
    On it, the along-track parameter is clipped to the segment except on the first segment
    (negative arcs allowed) and the last segment (arcs beyond the end allowed), so points before
    the start or after the end get extrapolated arcs.

    Args:
        points: (P, 2) float32, m.
        s: (P,) float32, m, cumulative arc length.
        valid: (P,) bool, prefix mask.
        query: (2,) float32, m.

    Returns:
        arc: () float32, m, arc length of the projection.
        lateral: () float32, m, signed offset from the nearest segment's line, + = left of travel.
        heading: () float32, rad, heading of the nearest segment.
        distance: () float32, m, Euclidean distance to the nearest point of the polyline (its
            ends not extended); ``|query - points[0]|`` for a single-point polyline.
    """
    # One query: keep the segments on the minor axis (a (P-1,) layout); the nearest segment is
    # picked with a min and a first-index mask rather than argmin + gather (slow on CPU).
    n = num_valid(valid)
    nseg = points.shape[0] - 1
    ax, ay = points[:-1, 0], points[:-1, 1]
    dx, dy = points[1:, 0] - ax, points[1:, 1] - ay
    seg_valid = valid[1:] & valid[:-1]
    len2 = dx * dx + dy * dy
    nonzero = seg_valid & (len2 > _EPS2)
    inv_len2 = jnp.where(nonzero, 1.0 / jnp.where(nonzero, len2, 1.0), 0.0)
    rx, ry = query[0] - ax, query[1] - ay
    t_raw = (rx * dx + ry * dy) * inv_len2
    t_clip = jnp.clip(t_raw, 0.0, 1.0)
    ex, ey = rx - t_clip * dx, ry - t_clip * dy
    dist2 = jnp.where(seg_valid, ex * ex + ey * ey, BIG)
    best = jnp.min(dist2)
    iota = jnp.arange(nseg, dtype=jnp.int32)
    first = jnp.min(jnp.where(dist2 <= best, iota, nseg))
    sel = iota == first

    def pick(x):
        return jnp.sum(jnp.where(sel, x, 0.0))

    lo = jnp.where(first == 0, -jnp.inf, 0.0)
    hi = jnp.where(first == jnp.maximum(n - 2, 0), jnp.inf, 1.0)
    t_i = jnp.clip(pick(t_raw), lo, hi)
    l2 = pick(len2)
    ok = pick(nonzero.astype(jnp.float32)) > 0.5
    length = jnp.where(ok, jnp.sqrt(jnp.where(ok, l2, 1.0)), 0.0)
    ux = jnp.where(ok, pick(dx) / jnp.where(ok, length, 1.0), 0.0)
    uy = jnp.where(ok, pick(dy) / jnp.where(ok, length, 1.0), 0.0)
    arc = pick(s[:-1]) + t_i * length
    lateral = ux * pick(ry) - uy * pick(rx)
    heading = jnp.where(ok, safe_atan2(uy, ux), 0.0)
    pos = best > _EPS2
    distance = jnp.where(pos, jnp.sqrt(jnp.where(pos, best, 1.0)), 0.0)
    single = n < 2
    distance = jnp.where(single, safe_norm(query - points[0]), distance)
    arc = jnp.where(single, 0.0, arc)
    lateral = jnp.where(single, 0.0, lateral)
    heading = jnp.where(single, 0.0, heading)
    return arc, lateral, heading, distance
