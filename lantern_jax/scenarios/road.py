"""Procedural roads for the scenario families: straight segments and junctions (NumPy, build time).

Everything here runs once per scenario, outside ``jit``, on float64 NumPy arrays; the packing
helpers at the bottom turn a :class:`RoadMap` and a route polyline into the fixed-capacity
float32 pytrees of :mod:`lantern_jax.world`.

Canonical frames (the family builders rotate the finished scene afterwards):

* **Straight road** along +x.  Forward lanes (``fwd_k``) travel +x, ``k = 0`` next to the centre
  line (y = -1.75, -5.25, ...); backward lanes (``back_k``) travel -x at y = +1.75, +5.25, ...;
  the optional shoulder/parking lane (``shoulder``, width 2.5 m, kind 1) lies right of the
  forward lanes.
* **Junction** centred at the origin with arms ``S, E, N, W`` (unit vectors (0,-1), (1,0), (0,1),
  (-1,0)).  Right-hand traffic: the lanes travelling *toward* the centre from arm X lie on the
  right of that travel direction.  Where the opposite arm exists, an inbound lane continues
  straight through the junction box as one polyline (``SN_0``: from S to N, lane 0); otherwise
  the arm has stem lanes ``S_in_k`` (ending at the box edge) and ``S_out_k`` (starting there).
  Lane ``k = 0`` is the inner (left) lane.  Turning movements get connector lanes (kind 2,
  ``S0>W0``) built by :func:`add_connector`.

Junction box: the square ``|x|, |y| <= half_size``.  The default half size is 14 m rather than
the 7 m of the bare carriageways (2 lanes x 3.5 m per direction): the extra 7 m are the rounded
kerb fillets.  With a 7-m box a right turn from the outer lane would be a 1.75-m-radius arc, far
below the ego's ~7.5 m minimum turning radius (wheelbase 2.85 m, max wheel angle 0.3685 rad);
with 14 m the outer right turn has radius 8.75 m and the inner left turn 15.75 m.  Stop lines lie
2 m before the box edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lantern_jax.constants import BIG

# --- geometry defaults -------------------------------------------------------------------------
LANE_WIDTH = 3.5  # m
PARKING_WIDTH = 2.5  # m, shoulder / parking lane
JUNCTION_HALF_SIZE = 14.0  # m, half size of the junction box (kerb fillets included)
ARM_LENGTH = 70.0  # m, length of each junction arm beyond the box edge
STOP_LINE_SETBACK = 2.0  # m, stop line distance before the junction box edge
ROUTE_SPACING = 2.0  # m, maximum spacing of route points
LANE_SPACING = 4.0  # m, preferred spacing of straight-lane points

# --- fixed capacities (static shapes shared by every scenario, so they batch) -------------------
MAX_ACTORS = 16  # A
PATH_POINTS = 32  # P
MAX_LANES = 16  # L
LANE_POINTS = 48  # Q
ROUTE_POINTS = 96  # R
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

ARMS = ("S", "E", "N", "W")
ARM_DIR = {"S": (0.0, -1.0), "E": (1.0, 0.0), "N": (0.0, 1.0), "W": (-1.0, 0.0)}
OPPOSITE = {"S": "N", "N": "S", "E": "W", "W": "E"}
LIGHT_GROUP = {"S": 0, "N": 0, "E": 1, "W": 1}  # N-S approaches share light 0, E-W light 1


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
    if len(xy) < 2:
        return np.zeros(len(xy))
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def point_at(xy: np.ndarray, s) -> np.ndarray:
    """Point(s) at arc length ``s`` (clipped to the polyline), shape ``s.shape + (2,)``, m."""
    xy = np.asarray(xy, np.float64)
    cs = arc_length(xy)
    s = np.clip(np.asarray(s, np.float64), 0.0, cs[-1])
    return np.stack([np.interp(s, cs, xy[:, 0]), np.interp(s, cs, xy[:, 1])], axis=-1)


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


def fillet(p0, h0, p1, h1, spacing: float = ROUTE_SPACING) -> np.ndarray:
    """Tangent-continuous path from ``p0`` (heading ``h0``) to ``p1`` (heading ``h1``).

    Straight, circular arc, straight: the arc is tangent to both lines and as large as the
    shorter leg to their intersection allows (a pure arc when both legs are equal).

    Args:
        p0, p1: (2,) start and end points, m.
        h0, h1: (2,) start and end directions.
        spacing: maximum point spacing, m.

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
    kind: int  # OCC_* of lantern_jax.constants
    name: str = ""  # what it is in the scene ("corner_SW", "truck", ...), for messages


@dataclass
class RoadMap:
    """Lanes, lights and static occluders of one procedural map (canonical frame)."""

    kind: str  # "straight" or "junction"
    lanes: list[LaneSpec] = field(default_factory=list)
    lights: list[LightSpec] = field(default_factory=list)
    occluders: list[OccluderSpec] = field(default_factory=list)
    arms: tuple[str, ...] = ()
    half_size: float = 0.0
    lanes_per_direction: int = 0

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


def _right(d) -> np.ndarray:
    return np.array([d[1], -d[0]], np.float64)


def straight_road(
    num_lanes_fwd: int,
    num_lanes_back: int,
    length: float,
    shoulder: bool,
    x_start: float = 0.0,
) -> RoadMap:
    """A straight carriageway along +x from ``x_start`` to ``x_start + length``.

    Args:
        num_lanes_fwd: lanes travelling +x (``fwd_0`` next to the centre line, y = -1.75).
        num_lanes_back: lanes travelling -x (``back_0`` at y = +1.75).
        length: m.
        shoulder: add a 2.5-m shoulder/parking lane (kind 1) right of the forward lanes.
        x_start: m, x of the road start.
    """
    if num_lanes_fwd < 1 or num_lanes_back < 0:
        raise ValueError("straight_road: need >= 1 forward lane and >= 0 backward lanes")
    road = RoadMap(kind="straight")
    x0, x1 = float(x_start), float(x_start) + float(length)
    n = min(LANE_POINTS, int(math.ceil(length / LANE_SPACING)) + 1)
    for k in range(num_lanes_fwd):
        y = -(k + 0.5) * LANE_WIDTH
        road.add(LaneSpec(f"fwd_{k}", resample(np.array([[x0, y], [x1, y]]), n), LANE_WIDTH, 0))
    for k in range(num_lanes_back):
        y = (k + 0.5) * LANE_WIDTH
        road.add(LaneSpec(f"back_{k}", resample(np.array([[x1, y], [x0, y]]), n), LANE_WIDTH, 0))
    if shoulder:
        y = -num_lanes_fwd * LANE_WIDTH - 0.5 * PARKING_WIDTH
        pts = resample(np.array([[x0, y], [x1, y]]), n)
        road.add(LaneSpec("shoulder", pts, PARKING_WIDTH, LANE_SHOULDER))
    return road


def signal_lights(ego_red_s: float, arms: tuple[str, ...], half_size: float, lanes: int):
    """The two light groups of a signalized junction (ego approach = arm S).

    Light 0 (N-S approaches, the ego's) is red for ``ego_red_s`` seconds from t = 0, then green
    for 90 s.  Light 1 (E-W approaches) is its complement: green (or yellow) until
    ``ego_red_s`` and red from then on, so the ego's green never overlaps the cross green.
    """
    cycle = LIGHT_GREEN_S + LIGHT_YELLOW_S + LIGHT_RED_S
    off0 = cycle - ego_red_s  # phase at t = 0: inside red with ego_red_s remaining
    off1 = LIGHT_GREEN_S + LIGHT_YELLOW_S - ego_red_s  # red starts exactly at t = ego_red_s
    out = []
    probe = RoadMap(kind="junction", arms=arms, half_size=half_size, lanes_per_direction=lanes)
    for group, off in ((0, off0), (1, off1)):
        arm = "S" if group == 0 else ("W" if "W" in arms else "E")
        stop = stop_line_xy(probe, arm)
        out.append(LightSpec(LIGHT_GREEN_S, LIGHT_YELLOW_S, LIGHT_RED_S, off % cycle, stop))
    return out


def junction(
    num_arms: int,
    lanes_per_direction: int = 2,
    signalized: bool = False,
    *,
    missing_arm: str | None = None,
    half_size: float = JUNCTION_HALF_SIZE,
    arm_length: float = ARM_LENGTH,
    ego_red_s: float = 5.0,
) -> RoadMap:
    """A 3- or 4-arm junction centred at the origin (see the module docstring for names).

    Args:
        num_arms: 3 or 4.
        lanes_per_direction: lanes in each direction on every arm.
        signalized: add the two light groups (:func:`signal_lights`) and mark approach lanes.
        missing_arm: the absent arm of a 3-arm junction (not ``"S"``, the ego's approach).
        half_size: m, junction box half size.
        arm_length: m, arm length beyond the box edge.
        ego_red_s: s, initial red of the ego's light (signalized only).
    """
    if num_arms == 4:
        if missing_arm not in (None, "none"):
            raise ValueError("junction: a 4-arm junction has no missing arm")
        arms = ARMS
    elif num_arms == 3:
        if missing_arm not in ("E", "N", "W"):
            raise ValueError(f"junction: missing_arm must be E, N or W, got {missing_arm!r}")
        arms = tuple(a for a in ARMS if a != missing_arm)
    else:
        raise ValueError(f"junction: num_arms must be 3 or 4, got {num_arms}")
    road = RoadMap(
        kind="junction", arms=arms, half_size=half_size, lanes_per_direction=lanes_per_direction
    )
    far = half_size + arm_length
    for x in arms:
        u = np.array(ARM_DIR[x])
        y = OPPOSITE[x]
        group = LIGHT_GROUP[x] if signalized else -1
        for k in range(lanes_per_direction):
            o_in = _right(-u) * (k + 0.5) * LANE_WIDTH
            if y in arms:  # through lane X -> Y
                pts = np.array([far * u + o_in, -far * u + o_in])
                n = min(LANE_POINTS, int(math.ceil(2 * far / LANE_SPACING)) + 1)
                name, box_out = f"{x}{y}_{k}", arm_length + 2 * half_size
            else:  # stem: inbound lane ends at the box
                pts = np.array([far * u + o_in, half_size * u + o_in])
                n = min(LANE_POINTS, int(math.ceil(arm_length / LANE_SPACING)) + 1)
                name, box_out = f"{x}_in_{k}", math.nan
                o_out = _right(u) * (k + 0.5) * LANE_WIDTH
                out_pts = resample(np.array([half_size * u + o_out, far * u + o_out]), n)
                road.add(LaneSpec(f"{x}_out_{k}", out_pts, LANE_WIDTH, 0, box_out_s=0.0))
            stop = arm_length - STOP_LINE_SETBACK if signalized else BIG
            lane = LaneSpec(name, resample(pts, n), LANE_WIDTH, 0, group, stop, arm_length, box_out)
            road.add(lane)
    if signalized:
        road.lights = signal_lights(ego_red_s, arms, half_size, lanes_per_direction)
    return road


def inbound_lane(road: RoadMap, arm: str, k: int) -> tuple[str, float]:
    """Lane carrying traffic from ``arm`` toward the box, lane ``k``: ``(name, box_in_s)``."""
    if arm not in road.arms:
        raise KeyError(f"arm {arm!r} not in junction arms {road.arms}")
    y = OPPOSITE[arm]
    name = f"{arm}{y}_{k}" if y in road.arms else f"{arm}_in_{k}"
    return name, road.lane(name).box_in_s


def outbound_lane(road: RoadMap, arm: str, k: int) -> tuple[str, float]:
    """Lane carrying traffic away from the box into ``arm``, lane ``k``: ``(name, box_out_s)``."""
    if arm not in road.arms:
        raise KeyError(f"arm {arm!r} not in junction arms {road.arms}")
    y = OPPOSITE[arm]
    name = f"{y}{arm}_{k}" if y in road.arms else f"{arm}_out_{k}"
    return name, road.lane(name).box_out_s


def add_connector(road: RoadMap, from_arm: str, k_in: int, to_arm: str, k_out: int) -> str:
    """Add (once) the connector lane for a turn from ``from_arm`` into ``to_arm``; return its name.

    The connector runs from the box-entry point of the inbound lane to the box-exit point of the
    outbound lane (a :func:`fillet`, a pure quarter circle when ``k_in == k_out``).
    """
    name = f"{from_arm}{k_in}>{to_arm}{k_out}"
    if name in road.names:
        return name
    if to_arm in (from_arm, OPPOSITE[from_arm]):
        raise ValueError(f"add_connector: {from_arm}->{to_arm} is not a turn")
    lin, s_in = inbound_lane(road, from_arm, k_in)
    lout, s_out = outbound_lane(road, to_arm, k_out)
    a = road.lane(lin)
    b = road.lane(lout)
    p0 = point_at(a.center, s_in)
    p1 = point_at(b.center, s_out)
    h0 = -np.array(ARM_DIR[from_arm])
    h1 = np.array(ARM_DIR[to_arm])
    pts = fillet(p0, h0, p1, h1, ROUTE_SPACING)
    if len(pts) > LANE_POINTS:
        pts = resample(pts, LANE_POINTS)
    road.add(LaneSpec(name, pts, LANE_WIDTH, LANE_CONNECTOR, box_in_s=0.0, box_out_s=0.0))
    return name


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


def turn_direction(from_arm: str, to_arm: str) -> str:
    """``"left"``, ``"right"`` or ``"straight"``: the movement from ``from_arm`` to ``to_arm``."""
    if to_arm == OPPOSITE[from_arm]:
        return "straight"
    h0, h1 = -np.array(ARM_DIR[from_arm]), np.array(ARM_DIR[to_arm])
    cross = h0[0] * h1[1] - h0[1] * h1[0]
    if cross == 0:
        raise ValueError(f"turn_direction: {from_arm}->{to_arm} is a U-turn")
    return "left" if cross > 0 else "right"


def stop_line_xy(road: RoadMap, arm: str) -> np.ndarray:
    """(2,) centre of the stop line across the inbound lanes of ``arm``, m (canonical frame)."""
    u = np.array(ARM_DIR[arm])
    across = road.lanes_per_direction * LANE_WIDTH / 2.0
    return (road.half_size + STOP_LINE_SETBACK) * u + _right(-u) * across


def lane_route(road: RoadMap, lane_name: str, s_start: float, length: float) -> RouteSpec:
    """A route along one (straight) lane from arc ``s_start`` for ``length`` metres."""
    lane = road.lane(lane_name)
    if s_start < 0 or s_start + length > lane.length + 1e-9:
        raise ValueError(f"lane_route: [{s_start}, {s_start + length}] outside lane {lane_name}")
    p0, p1 = point_at(lane.center, s_start), point_at(lane.center, s_start + length)
    return RouteSpec(line_points(p0, p1, ROUTE_SPACING), (lane_name,))


def turn_route(
    road: RoadMap,
    from_arm: str,
    k_in: int,
    to_arm: str,
    k_out: int,
    approach: float,
    length: float,
) -> RouteSpec:
    """Ego route through a junction: ``approach`` m straight to the box, the connector lane of
    the turn (a circular arc between the lane ends), then straight along the exit lane until
    the route is ``length`` m long.  A straight movement uses :func:`through_route`.

    Raises:
        ValueError: when the lanes are too short or ``length`` leaves no exit segment.
    """
    if to_arm == OPPOSITE[from_arm]:
        return through_route(road, from_arm, k_in, approach, length)
    conn = add_connector(road, from_arm, k_in, to_arm, k_out)
    lin, s_in = inbound_lane(road, from_arm, k_in)
    lout, s_out = outbound_lane(road, to_arm, k_out)
    cpts = road.lane(conn).center
    c_len = float(arc_length(cpts)[-1])
    exit_len = length - approach - c_len
    if approach <= 0 or approach > s_in:
        raise ValueError(f"turn_route: approach {approach} outside (0, {s_in}]")
    if exit_len <= 0 or s_out + exit_len > road.lane(lout).length:
        raise ValueError(f"turn_route: route length {length} leaves an exit of {exit_len:.2f} m")
    a = line_points(point_at(road.lane(lin).center, s_in - approach), cpts[0], ROUTE_SPACING)
    e = line_points(cpts[-1], point_at(road.lane(lout).center, s_out + exit_len), ROUTE_SPACING)
    xy = np.concatenate([a[:-1], cpts, e[1:]])
    stop = road.lane(lin).stop_s
    stop_s = approach - (s_in - stop) if stop < BIG else BIG
    return RouteSpec(xy, (lin, conn, lout), approach, approach + c_len, stop_s)


def through_route(road: RoadMap, from_arm: str, k: int, approach: float, length: float):
    """Ego route straight through the junction along the through lane ``k`` from ``from_arm``.

    Raises:
        ValueError: when the opposite arm is missing or the lane is too short.
    """
    if OPPOSITE[from_arm] not in road.arms:
        raise ValueError(f"through_route: no arm opposite {from_arm!r} in {road.arms}")
    lane, s_in = inbound_lane(road, from_arm, k)
    spec = lane_route(road, lane, s_in - approach, length)
    box = 2.0 * road.half_size
    stop = road.lane(lane).stop_s
    stop_s = approach - (s_in - stop) if stop < BIG else BIG
    return RouteSpec(spec.xy, (lane,), approach, approach + box, stop_s)


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
