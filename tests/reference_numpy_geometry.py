"""Slow, loop-based float64 NumPy reference for geometry and visibility.

Written independently of the vectorised JAX code, with different algorithms where possible:

* overlap: generic polygon separating-axis test on projected corners;
* distance: corner-to-edge point-segment distances both ways;
* ray hits: ray-segment intersection with each of the 4 edges plus a point-in-box test;
* visibility: bearings by ``atan2`` and occlusion by ray hit distances.
"""

from __future__ import annotations

import math

import numpy as np

BIG = 1.0e6
CAMERA_BACK_OFFSET = 1.5
OCCLUSION_EPS = 0.05


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def world_to_ego(p, ego_xy, ego_yaw) -> np.ndarray:
    fwd = np.array([math.cos(ego_yaw), math.sin(ego_yaw)])
    right = np.array([math.sin(ego_yaw), -math.cos(ego_yaw)])  # heading turned 90 deg clockwise
    d = np.asarray(p, float) - np.asarray(ego_xy, float)
    return np.array([d @ fwd, d @ right])


def ego_to_world(q, ego_xy, ego_yaw) -> np.ndarray:
    fwd = np.array([math.cos(ego_yaw), math.sin(ego_yaw)])
    right = np.array([math.sin(ego_yaw), -math.cos(ego_yaw)])
    return np.asarray(ego_xy, float) + q[0] * fwd + q[1] * right


def box_corners(center, yaw, extent) -> np.ndarray:
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    out = []
    for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        local = np.array([sx * extent[0], sy * extent[1]], float)
        out.append(np.asarray(center, float) + rot @ local)
    return np.array(out)


def sample_points(center, yaw, extent) -> np.ndarray:
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    signs = [(0, 0), (1, 1), (-1, 1), (-1, -1), (1, -1), (1, 0), (0, 1), (-1, 0), (0, -1)]
    out = []
    for sx, sy in signs:
        local = np.array([sx * extent[0], sy * extent[1]], float)
        out.append(np.asarray(center, float) + rot @ local)
    return np.array(out)


def boxes_overlap(c1, yaw1, e1, c2, yaw2, e2) -> bool:
    p1, p2 = box_corners(c1, yaw1, e1), box_corners(c2, yaw2, e2)
    for poly in (p1, p2):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            if np.linalg.norm(axis) == 0.0:
                continue
            a = [q @ axis for q in p1]
            b = [q @ axis for q in p2]
            if max(a) < min(b) or max(b) < min(a):
                return False
    # degenerate boxes can have no usable edge normal: fall back to the world axes
    for axis in (np.array([1.0, 0.0]), np.array([0.0, 1.0])):
        a = [q @ axis for q in p1]
        b = [q @ axis for q in p2]
        if max(a) < min(b) or max(b) < min(a):
            return False
    return True


def point_segment_distance(p, a, b) -> float:
    ab = b - a
    den = ab @ ab
    t = 0.0 if den == 0.0 else min(max((p - a) @ ab / den, 0.0), 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


def box_distance(c1, yaw1, e1, c2, yaw2, e2) -> float:
    if boxes_overlap(c1, yaw1, e1, c2, yaw2, e2):
        return 0.0
    p1, p2 = box_corners(c1, yaw1, e1), box_corners(c2, yaw2, e2)
    best = math.inf
    for pa, pb in ((p1, p2), (p2, p1)):
        for q in pa:
            for i in range(4):
                best = min(best, point_segment_distance(q, pb[i], pb[(i + 1) % 4]))
    return best


def point_in_box(p, center, yaw, extent) -> bool:
    d = np.asarray(p, float) - np.asarray(center, float)
    lx = d[0] * math.cos(yaw) + d[1] * math.sin(yaw)
    ly = -d[0] * math.sin(yaw) + d[1] * math.cos(yaw)
    return abs(lx) <= extent[0] and abs(ly) <= extent[1]


def ray_box_intersect(origin, direction, center, yaw, extent) -> float:
    origin = np.asarray(origin, float)
    direction = np.asarray(direction, float)
    if point_in_box(origin, center, yaw, extent):
        return 0.0
    poly = box_corners(center, yaw, extent)
    best = BIG
    for i in range(4):
        a, b = poly[i], poly[(i + 1) % 4]
        e = b - a
        # origin + t * direction = a + u * e
        den = direction[0] * (-e[1]) - direction[1] * (-e[0])
        if abs(den) < 1e-12:
            continue
        r = a - origin
        t = (r[0] * (-e[1]) - r[1] * (-e[0])) / den
        u = (direction[0] * r[1] - direction[1] * r[0]) / den
        if t >= 0.0 and -1e-12 <= u <= 1.0 + 1e-12:
            best = min(best, t)
    return best


def rays_boxes_hit(origins, dirs, centers, yaws, extents) -> np.ndarray:
    n, a = len(origins), len(centers)
    out = np.zeros((n, a))
    for i in range(n):
        for j in range(a):
            out[i, j] = ray_box_intersect(origins[i], dirs[i], centers[j], yaws[j], extents[j])
    return out


def point_visibility(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range):
    """(A, 9) bool: sample point k of actor i is seen."""
    num = len(centers)
    out = np.zeros((num, 9), bool)
    for i in range(num):
        if not present[i]:
            continue
        for k, p in enumerate(sample_points(centers[i], yaws[i], extents[i])):
            rel = p - np.asarray(cam_xy, float)
            dist = float(np.hypot(rel[0], rel[1]))
            bearing = wrap_angle(math.atan2(rel[1], rel[0]) - cam_yaw)
            if fov_deg < 360.0 and abs(bearing) > math.radians(fov_deg / 2.0) and dist > 0:
                continue
            if dist > max_range:
                continue
            blocked = False
            if dist > OCCLUSION_EPS:
                direction = rel / dist
                for j in range(num):
                    if j == i or not present[j]:
                        continue
                    hit = ray_box_intersect(cam_xy, direction, centers[j], yaws[j], extents[j])
                    if hit < dist - OCCLUSION_EPS:
                        blocked = True
                        break
            out[i, k] = not blocked
    return out


def visible_actors(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range):
    pts = point_visibility(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, max_range)
    return pts.any(axis=1)


def ray_angles(fov_deg: float, num_rays: int) -> np.ndarray:
    if fov_deg >= 360.0:
        return np.array([2.0 * math.pi * (k - num_rays // 2) / num_rays for k in range(num_rays)])
    if num_rays == 1:
        return np.zeros(1)
    half = math.radians(fov_deg / 2.0)
    return np.array([-half + 2.0 * half * k / (num_rays - 1) for k in range(num_rays)])


def range_image(cam_xy, cam_yaw, centers, yaws, extents, present, fov_deg, num_rays, max_range):
    ranges = np.full(num_rays, float(max_range))
    index = np.full(num_rays, -1, np.int32)
    for r, off in enumerate(ray_angles(fov_deg, num_rays)):
        direction = np.array([math.cos(cam_yaw + off), math.sin(cam_yaw + off)])
        for j in range(len(centers)):
            if not present[j]:
                continue
            t = ray_box_intersect(cam_xy, direction, centers[j], yaws[j], extents[j])
            if t <= max_range and (index[r] < 0 or t < ranges[r]):
                ranges[r], index[r] = t, j
    return ranges, index
