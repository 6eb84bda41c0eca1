"""Procedural-road basics shared by the family builders (NumPy, build time).

Everything here runs once per scenario, outside ``jit``, on float64 NumPy arrays: polyline
helpers, the map description (:class:`RoadMap` of :class:`LaneSpec` lanes, :class:`LightSpec`
lights and :class:`OccluderSpec` static occluders), the ego :class:`RouteSpec`, the fixed
capacities shared by every scenario, and the packing helpers that turn a map and a route into
the fixed-capacity float32 pytrees of :mod:`lantern_jax.types.world` (rotation applied there).

The roads themselves are built by :mod:`lantern_jax.scenarios.road_straight` (gently curved
multi-lane roads) and :mod:`lantern_jax.scenarios.road_junction` (3- and 4-arm junctions with
skewed arms, kerb fillets and corner occluders).  Canonical frames: the family builders lay a
scene out with the ego starting near the origin and rotate the finished scene afterwards.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lantern_jax.core.constants import (  # noqa: F401  (the capacities: road.MAX_ACTORS, ...)
    BIG,
    EGO_HALF_WIDTH,
    LANE_POINTS,
    MAX_ACTORS,
    MAX_LANES,
    OCC_PARKED_VEHICLE,
    PATH_POINTS,
    ROUTE_POINTS,
)

#: m, lateral margin beyond the ego half width kept clear of occluders along the route
CORRIDOR_MARGIN = 0.5

#: m of road before the route start and after the route end (straight-road families)
ROAD_MARGIN = 60.0
#: m, half width of a parked van (Obstacle Reveal's, the reversing car's bay neighbour)
VAN_HALF_WIDTH = 1.1

# --- geometry defaults -------------------------------------------------------------------------
ROUTE_SPACING = 2.0  # m, maximum spacing of route points
LANE_SPACING = 4.0  # m, preferred spacing of straight-lane points

# --- fixed capacities: constants.MAX_ACTORS, PATH_POINTS, MAX_LANES, LANE_POINTS, ROUTE_POINTS
MAX_LIGHTS = 2  # T
MAX_OCCLUDERS = 8  # K

# --- lane kinds ---------------------------------------------------------------------------------
LANE_DRIVING = 0
LANE_SHOULDER = 1
LANE_CONNECTOR = 2

# --- traffic-light timing (s) --------------------------------------------------------------------
LIGHT_GREEN_S = 90.0
LIGHT_YELLOW_S = 3.0
LIGHT_RED_S = 96.0  # long red: a light that turns red stays red for the rest of any route


# ------------------------------------------------------------------------------------------------
# polyline helpers (float64 NumPy)
# ------------------------------------------------------------------------------------------------
def arc_length(xy: np.ndarray) -> np.ndarray:
    """Cumulative arc length of a polyline.

    Args:
        xy: (n, 2) float, m, polyline points.

    Returns:
        (n,) float64, m, 0 at the first point.
    """
    xy = np.asarray(xy, np.float64)
    out = np.zeros(len(xy))
    if len(xy) >= 2:
        d = xy[1:] - xy[:-1]
        # sqrt(dx^2 + dy^2) as np.linalg.norm computes it (same float64 values), without its
        # per-call overhead: world building calls this some ten thousand times
        np.cumsum(np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]), out=out[1:])
    return out


def point_at(xy: np.ndarray, s) -> np.ndarray:
    """Point(s) at arc length ``s`` (clipped to the polyline), shape ``s.shape + (2,)``, m."""
    xy = np.asarray(xy, np.float64)
    cs = arc_length(xy)
    s = np.minimum(np.maximum(np.asarray(s, np.float64), 0.0), cs[-1])  # np.clip, cheaper
    out = np.empty(s.shape + (2,))
    out[..., 0] = np.interp(s, cs, xy[:, 0])
    out[..., 1] = np.interp(s, cs, xy[:, 1])
    return out


def heading_at(xy: np.ndarray, s: float) -> float:
    """Yaw (rad, CCW from +x) of the segment containing arc ``s`` (next segment at a vertex)."""
    xy = np.asarray(xy, np.float64)
    cs = arc_length(xy)
    i = int(np.clip(np.searchsorted(cs, s, side="right") - 1, 0, len(xy) - 2))
    d = xy[i + 1] - xy[i]
    return float(math.atan2(d[1], d[0]))


def resample(xy: np.ndarray, n: int) -> np.ndarray:
    """``n`` points uniformly spaced in arc length along ``xy`` (end points kept), (n, 2)."""
    cs = arc_length(xy)
    return point_at(xy, np.linspace(0.0, cs[-1], n))


def segment(xy: np.ndarray, s0: float, s1: float, min_gap: float = 0.5) -> np.ndarray:
    """The part of a polyline between arcs ``s0 < s1`` (clipped to it), end points interpolated
    and the original vertices in between kept, except those closer than ``min_gap`` to an end
    (so no segment is shorter than that, unless the whole part is); (n, 2) with n >= 2."""
    xy = np.asarray(xy, np.float64)
    cs = arc_length(xy)
    s0, s1 = max(0.0, float(s0)), min(float(cs[-1]), float(s1))
    if not s1 > s0:
        raise ValueError(f"segment: empty interval [{s0}, {s1}]")
    inner = xy[(cs > s0 + min_gap) & (cs < s1 - min_gap)]
    return np.concatenate([point_at(xy, s0)[None], inner, point_at(xy, s1)[None]])


def densify(xy: np.ndarray, spacing: float) -> np.ndarray:
    """A polyline with every segment split so that points are at most ``spacing`` apart
    (original vertices kept)."""
    xy = np.asarray(xy, np.float64)
    parts = [line_points(p, q, spacing)[:-1] for p, q in zip(xy[:-1], xy[1:], strict=True)]
    return np.concatenate(parts + [xy[-1:]])


def line_points(p0, p1, spacing: float) -> np.ndarray:
    """Points from ``p0`` to ``p1`` (both included) with spacing <= ``spacing``, (n, 2)."""
    p0, p1 = np.asarray(p0, np.float64), np.asarray(p1, np.float64)
    n = max(1, int(math.ceil(np.linalg.norm(p1 - p0) / spacing - 1e-9)))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return p0 + t * (p1 - p0)


def project(xy: np.ndarray, p) -> tuple[float, float]:
    """Project a point onto a polyline.

    Returns:
        ``(s, dist)``: arc length of the closest polyline point and the distance to it, m.
    """
    xy = np.asarray(xy, np.float64)
    p = np.asarray(p, np.float64)
    a, b = xy[:-1], xy[1:]
    ab = b - a
    ll = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    t = np.clip(np.sum((p - a) * ab, axis=1) / ll, 0.0, 1.0)
    q = a + t[:, None] * ab
    d = np.linalg.norm(q - p, axis=1)
    i = int(np.argmin(d))
    return float(arc_length(xy)[i] + t[i] * math.sqrt(ll[i])), float(d[i])


def corridor_entry(route_xy: np.ndarray, line_p, line_dir, threshold: float) -> float:
    """First route arc at which the route comes within ``threshold`` of an infinite line.

    The signed distance to a line is linear along each polyline segment, so the crossing is
    solved exactly per segment.

    Args:
        route_xy: (n, 2) route polyline, m.
        line_p: (2,) a point of the line, m.
        line_dir: (2,) direction of the line.
        threshold: m.

    Raises:
        ValueError: when the route never enters the corridor.
    """
    xy = np.asarray(route_xy, np.float64)
    d = np.asarray(line_dir, np.float64)
    d = d / np.linalg.norm(d)
    nrm = np.array([-d[1], d[0]])
    sd = (xy - np.asarray(line_p, np.float64)) @ nrm
    cs = arc_length(xy)
    if abs(sd[0]) <= threshold:
        return 0.0
    for i in range(len(xy) - 1):
        a, b = sd[i], sd[i + 1]
        if abs(b) <= threshold or a * b < 0:
            target = threshold if a > 0 else -threshold
            f = (a - target) / (a - b)
            return float(cs[i] + f * (cs[i + 1] - cs[i]))
    raise ValueError("route never enters the corridor of the given line")


def fillet(
    p0, h0, p1, h1, spacing: float = ROUTE_SPACING, radius: float | None = None
) -> np.ndarray:
    """Tangent-continuous path from ``p0`` (heading ``h0``) to ``p1`` (heading ``h1``).

    Straight, circular arc, straight: the arc is tangent to both lines, of ``radius`` when that
    fits both legs to their intersection, else as large as the shorter leg allows (a pure arc
    when both legs are equal).

    Args:
        p0, p1: (2,) start and end points, m.
        h0, h1: (2,) start and end directions.
        spacing: maximum point spacing, m.
        radius: m, wanted arc radius (None = the largest that fits).

    Returns:
        (n, 2) polyline, exact points on the curve at uniform arc spacing.
    """
    p0, p1 = np.asarray(p0, np.float64), np.asarray(p1, np.float64)
    d0 = np.asarray(h0, np.float64) / np.linalg.norm(h0)
    d1 = np.asarray(h1, np.float64) / np.linalg.norm(h1)
    theta = math.atan2(d0[0] * d1[1] - d0[1] * d1[0], float(d0 @ d1))
    if abs(theta) < 1e-6 or abs(abs(theta) - math.pi) < 1e-6:
        raise ValueError("fillet: start and end headings must not be parallel")
    t0, t1 = np.linalg.solve(np.stack([d0, d1], axis=1), p1 - p0)
    if t0 < 0 or t1 < 0:
        raise ValueError("fillet: the lines meet behind the start or beyond the end")
    tl = min(t0, t1)
    if radius is not None:
        tl = min(tl, radius * math.tan(abs(theta) / 2.0))
    r = tl / math.tan(abs(theta) / 2.0)
    k = p0 + t0 * d0
    a = k - tl * d0
    b = k + tl * d1
    side = np.array([-d0[1], d0[0]]) if theta > 0 else np.array([d0[1], -d0[0]])
    centre = a + r * side
    phi0 = math.atan2(a[1] - centre[1], a[0] - centre[0])
    l1, la, l2 = t0 - tl, r * abs(theta), t1 - tl
    total = l1 + la + l2
    n = max(2, int(math.ceil(total / spacing - 1e-9)))
    out = []
    for u in np.linspace(0.0, total, n + 1):
        if u <= l1:
            out.append(p0 + u * d0)
        elif u <= l1 + la:
            ang = phi0 + math.copysign((u - l1) / r, theta)
            out.append(centre + r * np.array([math.cos(ang), math.sin(ang)]))
        else:
            out.append(b + (u - l1 - la) * d1)
    out[0], out[-1] = p0, p1
    return np.asarray(out)


# ------------------------------------------------------------------------------------------------
# road map
# ------------------------------------------------------------------------------------------------
@dataclass
class LaneSpec:
    """One lane centre line in the canonical frame (travel direction = point order)."""

    name: str
    center: np.ndarray  # (n, 2) float64, m
    width: float  # m
    kind: int  # LANE_DRIVING / LANE_SHOULDER / LANE_CONNECTOR
    light: int = -1  # traffic-light slot governing this lane's approach (-1 = none)
    stop_s: float = BIG  # m, arc of that light's stop line along the lane
    box_in_s: float = math.nan  # m, arc where the lane enters the junction box (nan = never)
    box_out_s: float = math.nan  # m, arc where the lane leaves the junction box (nan = never)

    @property
    def length(self) -> float:
        return float(arc_length(self.center)[-1])


@dataclass
class LightSpec:
    """A fixed-cycle light: phase = (t + offset) mod (green + yellow + red)."""

    green: float
    yellow: float
    red: float
    offset: float
    stop_xy: np.ndarray  # (2,) m, centre of one stop line of the light (drawing only)


@dataclass
class OccluderSpec:
    """A static scenery box of the map (canonical frame): building, wall or parked vehicle."""

    xy: np.ndarray  # (2,) float64, m, box centre
    yaw: float  # rad, direction of the long axis
    extent: tuple[float, float]  # m, half length, half width (> 0)
    kind: int  # OCC_* of lantern_jax.core.constants
    name: str = ""  # what it is in the scene ("corner_SW", "truck", ...), for messages


@dataclass
class RoadMap:
    """Lanes, lights and static occluders of one procedural map (canonical frame)."""

    kind: str  # "straight" or "junction"
    lanes: list[LaneSpec] = field(default_factory=list)
    lights: list[LightSpec] = field(default_factory=list)
    occluders: list[OccluderSpec] = field(default_factory=list)
    arms: tuple[str, ...] = ()  # junction arms present ("S", "E", "N", "W")
    arm_dir: dict[str, np.ndarray] = field(default_factory=dict)  # outward unit vector per arm
    box_dist: dict[str, float] = field(default_factory=dict)  # m, centre to each arm's box edge
    lanes_per_direction: int = 0
    lane_width: float = 0.0  # m
    corners: list = field(default_factory=list)  # junction kerb corners (road_junction.Corner)

    @property
    def half_size(self) -> float:
        """m, the largest distance from the junction centre to an arm's box edge."""
        return max(self.box_dist.values()) if self.box_dist else 0.0

    @property
    def names(self) -> list[str]:
        return [ln.name for ln in self.lanes]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no lane named {name!r}; lanes: {', '.join(self.names)}") from None

    def lane(self, name: str) -> LaneSpec:
        return self.lanes[self.index(name)]

    def add(self, lane: LaneSpec) -> None:
        if lane.name in self.names:
            raise ValueError(f"duplicate lane name {lane.name!r}")
        self.lanes.append(lane)


@dataclass
class RouteSpec:
    """An ego route in the canonical frame with the arcs the family builders need."""

    xy: np.ndarray  # (n, 2) float64, m
    lanes: tuple[str, ...]  # lanes the route follows, in order
    box_in_s: float = math.nan  # m, route arc at the junction-box entry
    box_out_s: float = math.nan  # m, route arc at the junction-box exit
    stop_s: float = BIG  # m, route arc of the ego's stop line (BIG = none)

    @property
    def s(self) -> np.ndarray:
        return arc_length(self.xy)

    @property
    def length(self) -> float:
        return float(self.s[-1])


# ------------------------------------------------------------------------------------------------
# packing into fixed-capacity arrays (float32 / int32 / bool NumPy; rotation applied here)
# ------------------------------------------------------------------------------------------------
def rotation(deg: float) -> np.ndarray:
    """2x2 rotation matrix for a counter-clockwise rotation by ``deg`` degrees."""
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def pack_lanes(road: RoadMap, rot: np.ndarray) -> dict[str, np.ndarray]:
    """Pad the road's lanes to ``(MAX_LANES, LANE_POINTS)``; fields of :class:`Lanes`."""
    if len(road.lanes) > MAX_LANES:
        raise ValueError(f"Lanes.valid: {len(road.lanes)} lanes exceed capacity {MAX_LANES}")
    center = np.zeros((MAX_LANES, LANE_POINTS, 2), np.float32)
    s = np.zeros((MAX_LANES, LANE_POINTS), np.float32)
    pv = np.zeros((MAX_LANES, LANE_POINTS), bool)
    width = np.zeros(MAX_LANES, np.float32)
    valid = np.zeros(MAX_LANES, bool)
    kind = np.zeros(MAX_LANES, np.int32)
    for i, ln in enumerate(road.lanes):
        pts = ln.center if len(ln.center) <= LANE_POINTS else resample(ln.center, LANE_POINTS)
        n = len(pts)
        center[i, :n] = pts @ rot.T
        center[i, n:] = center[i, n - 1]
        s[i, :n] = arc_length(pts)
        s[i, n:] = s[i, n - 1]
        pv[i, :n] = True
        width[i], valid[i], kind[i] = ln.width, True, ln.kind
    return dict(center=center, s=s, point_valid=pv, width=width, valid=valid, kind=kind)


def pack_route(xy: np.ndarray, rot: np.ndarray) -> dict[str, np.ndarray]:
    """Pad a route polyline to ``ROUTE_POINTS``; fields of :class:`Route`."""
    n = len(xy)
    if n > ROUTE_POINTS:
        raise ValueError(f"Route.xy: {n} route points exceed capacity {ROUTE_POINTS}")
    out = np.zeros((ROUTE_POINTS, 2), np.float32)
    s = np.zeros(ROUTE_POINTS, np.float32)
    out[:n] = np.asarray(xy) @ rot.T
    out[n:] = out[n - 1]
    cs = arc_length(xy)
    s[:n] = cs
    s[n:] = cs[-1]
    valid = np.arange(ROUTE_POINTS) < n
    return dict(xy=out, s=s, valid=valid, length=np.float32(cs[-1]))


def pack_occluders(occluders: list[OccluderSpec], rot: np.ndarray) -> dict[str, np.ndarray]:
    """Pad the occluders to ``MAX_OCCLUDERS``; fields of :class:`Occluders` (rotation applied)."""
    if len(occluders) > MAX_OCCLUDERS:
        raise ValueError(f"Occluders.valid: {len(occluders)} occluders exceed {MAX_OCCLUDERS}")
    out = dict(
        center=np.zeros((MAX_OCCLUDERS, 2), np.float32),
        yaw=np.zeros(MAX_OCCLUDERS, np.float32),
        extent=np.zeros((MAX_OCCLUDERS, 2), np.float32),
        kind=np.zeros(MAX_OCCLUDERS, np.int32),
        valid=np.zeros(MAX_OCCLUDERS, bool),
    )
    turn = math.atan2(rot[1, 0], rot[0, 0])
    for i, oc in enumerate(occluders):
        out["center"][i] = rot @ np.asarray(oc.xy, np.float64)
        out["yaw"][i] = math.remainder(oc.yaw + turn, 2 * math.pi)
        out["extent"][i] = oc.extent
        out["kind"][i], out["valid"][i] = oc.kind, True
    return out


def pack_lights(lights: list[LightSpec], rot: np.ndarray) -> dict[str, np.ndarray]:
    """Pad the lights to ``MAX_LIGHTS``; fields of :class:`TrafficLights`."""
    if len(lights) > MAX_LIGHTS:
        raise ValueError(f"TrafficLights.valid: {len(lights)} lights exceed {MAX_LIGHTS}")
    out = dict(
        green=np.zeros(MAX_LIGHTS, np.float32),
        yellow=np.zeros(MAX_LIGHTS, np.float32),
        red=np.zeros(MAX_LIGHTS, np.float32),
        offset=np.zeros(MAX_LIGHTS, np.float32),
        stop_xy=np.zeros((MAX_LIGHTS, 2), np.float32),
        valid=np.zeros(MAX_LIGHTS, bool),
    )
    for i, lt in enumerate(lights):
        out["green"][i], out["yellow"][i], out["red"][i] = lt.green, lt.yellow, lt.red
        out["offset"][i] = lt.offset
        out["stop_xy"][i] = rot @ np.asarray(lt.stop_xy)
        out["valid"][i] = True
    return out


def occluder_intrusions(road_map: RoadMap, route_xy: np.ndarray) -> list[str]:
    """Occluders that intrude on the route corridor or on a driving lane.

    An occluder intrudes on the route corridor when its box comes within ``EGO_HALF_WIDTH +
    CORRIDOR_MARGIN`` of the route polyline, and a building or wall intrudes on a lane (driving
    or connector) when it comes within half the lane's width of its centre line (parked or
    waiting vehicles stand on lanes by design: only the route corridor is checked for them).
    Box-to-polyline distances are measured on the box outline sampled every 0.25 m (exact to
    that resolution; the centre lines are piecewise linear).

    Returns:
        One message per intrusion, naming the occluder, e.g. ``"occluder corner_SW overlaps the
        route corridor (0.42 m from the route, needs 1.56)"``; empty when every occluder is
        clear.
    """
    out = []
    need = EGO_HALF_WIDTH + CORRIDOR_MARGIN
    for oc in road_map.occluders:
        outline = _box_outline(oc)
        d = polyline_distance_below(outline, route_xy, need)
        if d < need:
            out.append(
                f"occluder {oc.name or '?'} overlaps the route corridor ({d:.2f} m from the route,"
                f" needs {need:.2f})"
            )
            continue
        for lane in road_map.lanes:
            if lane.kind == LANE_SHOULDER or oc.kind == OCC_PARKED_VEHICLE:
                continue
            d = polyline_distance_below(outline, lane.center, 0.5 * lane.width)
            if d < 0.5 * lane.width:
                out.append(f"occluder {oc.name or '?'} overlaps lane {lane.name} ({d:.2f} m from "
                           f"its centre line, needs {0.5 * lane.width:.2f})")  # fmt: skip
                break
    return out


def _box_outline(oc: OccluderSpec, step: float = 0.25) -> np.ndarray:
    c, s = math.cos(oc.yaw), math.sin(oc.yaw)
    hl, hw = oc.extent
    corners = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw], [hl, hw]])
    pts = np.concatenate(
        [line_points(a, b, step)[:-1] for a, b in zip(corners[:-1], corners[1:], strict=True)]
    )
    return np.asarray(oc.xy, np.float64) + pts @ np.array([[c, s], [-s, c]])


def _distances_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each of ``points`` (n, 2) to the nearest of the segments ``a[j] -> b[j]``
    ((k, 2) each, k >= 1); (n,) m.  Each point-segment distance is computed on its own, so a
    subset of segments gives the same bits for the segments it keeps."""
    ab = b - a
    ll = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    t = np.clip(np.einsum("nmk,mk->nm", points[:, None, :] - a[None], ab) / ll, 0.0, 1.0)
    r = points[:, None, :] - (a[None] + t[..., None] * ab[None])
    # squared lengths, one square root per point: the same bits as the norm of each (x, y)
    return np.sqrt(np.min(r[..., 0] * r[..., 0] + r[..., 1] * r[..., 1], axis=1))


def distances_to_polyline(points: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Distance of each of ``points`` (n, 2) to the polyline ``xy`` (m, 2); (n,) m."""
    points, xy = np.asarray(points, np.float64), np.asarray(xy, np.float64)
    return _distances_to_segments(points, xy[:-1], xy[1:])


def polyline_distance_below(points: np.ndarray, xy: np.ndarray, limit: float) -> float:
    """Smallest distance from any of ``points`` (n, 2) to the polyline ``xy`` (m, 2), m, when
    it is below ``limit``; ``inf`` otherwise.

    A broad phase keeps only the segments whose bounding box comes within ``limit`` of the
    points' bounding box (a lower bound of every distance to that segment), so the exact
    distance is computed on those alone; a distance below ``limit`` is the same value
    :func:`distances_to_polyline` gives.
    """
    points, xy = np.asarray(points, np.float64), np.asarray(xy, np.float64)
    a, b = xy[:-1], xy[1:]
    gap = np.maximum(0.0, np.maximum(np.minimum(a, b) - points.max(axis=0),
                                     points.min(axis=0) - np.maximum(a, b)))  # fmt: skip
    keep = np.hypot(gap[:, 0], gap[:, 1]) < limit
    if not keep.any():
        return math.inf
    d = float(np.min(_distances_to_segments(points, a[keep], b[keep])))
    return d if d < limit else math.inf


def first_within(points: np.ndarray, xy: np.ndarray, limit: float, spacing: float,
                 block: int = 10) -> int:  # fmt: skip
    """Index of the first of ``points`` within ``limit`` of the polyline ``xy`` (-1: none).

    ``points`` (n, 2) are samples along a curve, consecutive ones at most ``spacing`` m of arc
    apart.  Every ``block``-th sample is measured first; a sample's distance differs from that
    of a sample ``k`` steps away by at most ``k * spacing`` (distance to a set is 1-Lipschitz),
    so only blocks whose first sample lies within ``limit + block * spacing`` are measured
    sample by sample: the same index as measuring every sample, at a fraction of the cost.
    """
    points, xy = np.asarray(points, np.float64), np.asarray(xy, np.float64)
    coarse = distances_to_polyline(points[::block], xy)
    for j in np.flatnonzero(coarse <= limit + block * spacing):
        fine = distances_to_polyline(points[j * block : (j + 1) * block], xy)
        hit = np.flatnonzero(fine <= limit)
        if hit.size:
            return int(j * block + hit[0])
    return -1
