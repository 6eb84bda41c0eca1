"""Procedural 3- and 4-arm junctions with skewed arms, kerb fillets and corner occluders
(NumPy, build time).

Canonical frame: the junction is centred at the origin; arm ``S`` points south (the ego's
approach, never skewed), arms ``E``, ``N``, ``W`` point east, north and west rotated by their
``skew`` (degrees, counter-clockwise).  Right-hand traffic: the lanes travelling *toward* the
centre from arm X lie on the right of that travel direction.  Lane ``k = 0`` is the inner (left)
lane of each direction.  Where the opposite arm exists, an inbound lane continues through the
junction as one polyline (``SN_0``: from S to N, lane 0; kinked in the box when the arms are not
collinear); otherwise the arm has stem lanes ``S_in_k`` (ending at the box edge) and ``S_out_k``
(starting there).  Turning movements get connector lanes (kind 2, ``S0>W0``) built by
:func:`add_connector`: tangent arcs between the lane ends.

Arms may **bend**: an arm with a nonzero ``bend`` curvature (1/m, + = counter-clockwise seen
from the junction looking outward) runs straight for ``BEND_START_M`` beyond its box edge and
then curves gently, so approaches and exits are not all straight lines.

Kerbs and the box: every arm's carriageway has half width ``W = lanes_per_direction x
lane_width``.  Between two neighbouring arms whose directions differ by less than
``STRAIGHT_KERB_DEG`` the kerb lines meet at a **corner**, rounded by a fillet arc of radius
``kerb_radius`` tangent to both kerb lines; the corner's off-road region beyond the fillet is
where buildings and walls stand.  Each arm's **box edge** (where its lanes start and the
junction box begins) is the farther of its two fillet tangent points (``W + kerb_radius`` for
perpendicular arms); stop lines lie 2 m before it.  Neighbours ~180 degrees apart (the side
opposite a missing arm) share a straight kerb and no corner.

Corner occluders (:func:`corner_occluders`): a building (one box aligned with one of the two
arms) or a wall (two thin boxes along both kerbs), whose nearest point to the junction lies
``setback`` metres inside the fillet arc, so it keeps at least that distance from every kerb.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lantern_jax.core.constants import BIG, OCC_BUILDING, OCC_PARKED_VEHICLE, OCC_WALL
from lantern_jax.scenarios.road import (
    LANE_CONNECTOR,
    LANE_DRIVING,
    LANE_POINTS,
    LANE_SPACING,
    LIGHT_GREEN_S,
    LIGHT_RED_S,
    LIGHT_YELLOW_S,
    ROUTE_SPACING,
    LaneSpec,
    LightSpec,
    OccluderSpec,
    RoadMap,
    RouteSpec,
    arc_length,
    densify,
    fillet,
    heading_at,
    point_at,
    resample,
    segment,
)
from lantern_jax.scenarios.road_straight import Centerline

ARMS = ("S", "E", "N", "W")
NOMINAL_ANGLE_DEG = {"S": 270.0, "E": 0.0, "N": 90.0, "W": 180.0}  # outward directions
OPPOSITE = {"S": "N", "N": "S", "E": "W", "W": "E"}
LIGHT_GROUP = {"S": 0, "N": 0, "E": 1, "W": 1}  # N-S approaches share light 0, E-W light 1

ARM_LENGTH = 70.0  # m, length of each arm beyond its box edge
STOP_LINE_SETBACK = 2.0  # m, stop line distance before the box edge
STRAIGHT_KERB_DEG = 150.0  # neighbours at least this far apart share a straight kerb
CORNER_MIN_DEG, CORNER_MAX_DEG = 60.0, 120.0  # admissible angles of a rounded corner
WALL_THICKNESS = 0.3  # m
TRUCK_HALF_WIDTH = 1.2  # m
TRUCK_STOP_GAP = 0.5  # m between a waiting truck's front and the stop line
BEND_START_M = 4.0  # m beyond the box edge where a bending arm starts to curve


def _rot90(v: np.ndarray) -> np.ndarray:
    return np.array([-v[1], v[0]], np.float64)


def _unit(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([math.cos(a), math.sin(a)])


@dataclass(frozen=True)
class JunctionShape:
    """What a junction looks like (all lengths in m, angles in degrees).

    Attributes:
        num_arms: 3 or 4.
        missing_arm: the absent arm of a 3-arm junction (``"E"``, ``"N"`` or ``"W"``), else None.
        lanes_per_direction: lanes in each direction on every arm (1 or 2).
        lane_width: m.
        kerb_radius: m, radius of the kerb fillets at the corners.
        skew: arm -> counter-clockwise rotation from the nominal direction (S is never skewed).
        bend: arm -> curvature (1/m) of the arm beyond ``BEND_START_M`` from its box edge.
    """

    num_arms: int
    missing_arm: str | None
    lanes_per_direction: int
    lane_width: float
    kerb_radius: float
    skew: dict = field(default_factory=dict)
    bend: dict = field(default_factory=dict)

    @property
    def arms(self) -> tuple[str, ...]:
        if self.num_arms == 4:
            return ARMS
        return tuple(a for a in ARMS if a != self.missing_arm)

    @property
    def half_width(self) -> float:
        """m, half width of every arm's carriageway."""
        return self.lanes_per_direction * self.lane_width

    def angle(self, arm: str) -> float:
        """Outward direction of ``arm``, degrees counter-clockwise from +x."""
        return NOMINAL_ANGLE_DEG[arm] + (0.0 if arm == "S" else float(self.skew.get(arm, 0.0)))


@dataclass(frozen=True)
class Corner:
    """The rounded kerb corner between arm ``a`` and its counter-clockwise neighbour ``b``."""

    a: str
    b: str
    angle_deg: float  # angle between the two arms' outward directions
    kerb_point: np.ndarray  # (2,) where the two kerb lines meet
    fillet_centre: np.ndarray  # (2,) centre of the fillet arc
    tangent_a: float  # m, distance from the centre to the fillet's tangent point on a's kerb
    tangent_b: float  # m, same on b's kerb


def _kerb_meet(ua, ub, w: float) -> tuple[np.ndarray, float, float]:
    """Intersection of a's kerb line offset ``w`` toward b and b's kerb line offset ``w`` toward a;
    returns (point, distance along a, distance along b)."""
    na, nb = _rot90(ua), _rot90(ub)
    m = np.stack([ua, -ub], axis=1)
    ta, tb = np.linalg.solve(m, -w * na - w * nb)
    return ta * ua + w * na, float(ta), float(tb)


def corners(shape: JunctionShape) -> list[Corner]:
    """The rounded corners of a junction, counter-clockwise.

    Raises:
        ValueError: naming the arm whose skew makes a corner sharper than 60 or wider than 120
            degrees without being a straight kerb.
    """
    arms = sorted(shape.arms, key=lambda a: shape.angle(a) % 360.0)
    w, r = shape.half_width, shape.kerb_radius
    out = []
    for i, a in enumerate(arms):
        b = arms[(i + 1) % len(arms)]
        phi = (shape.angle(b) - shape.angle(a)) % 360.0
        if phi >= STRAIGHT_KERB_DEG:
            continue
        if not CORNER_MIN_DEG <= phi <= CORNER_MAX_DEG:
            bad = b if b != "S" else a
            raise ValueError(f"skew_{bad}: corner {a}-{b} of {phi:.1f} deg outside "
                             f"[{CORNER_MIN_DEG:g}, {CORNER_MAX_DEG:g}]")  # fmt: skip
        ua, ub = _unit(shape.angle(a)), _unit(shape.angle(b))
        k, _, _ = _kerb_meet(ua, ub, w)
        f, ta, tb = _kerb_meet(ua, ub, w + r)
        out.append(Corner(a, b, phi, k, f, ta, tb))
    return out


def box_distances(shape: JunctionShape, corner_list: list[Corner]) -> dict[str, float]:
    """Distance from the centre to each arm's box edge: its farther fillet tangent point (at
    least the carriageway half width, for an arm with straight kerbs on both sides)."""
    dist = {a: shape.half_width for a in shape.arms}
    for c in corner_list:
        dist[c.a] = max(dist[c.a], c.tangent_a)
        dist[c.b] = max(dist[c.b], c.tangent_b)
    return dist


def _arm_points(u: np.ndarray, edge: float, kappa: float, d: float, s0: float, s1: float):
    """Points along an arm at lateral offset ``d`` (+ = left looking outward) from ``s0`` to
    ``s1`` m beyond its box edge (either order), <= LANE_SPACING apart."""
    line = Centerline((BEND_START_M,), (0.0, float(kappa)))
    local = line.line(s0, s1, d, LANE_SPACING)
    return edge * u + local[:, 0:1] * u + local[:, 1:2] * _rot90(u)


def _fit(pts: np.ndarray) -> np.ndarray:
    return pts if len(pts) <= LANE_POINTS else resample(pts, LANE_POINTS)


def junction(shape: JunctionShape, signalized: bool = False, ego_red_s: float = 5.0) -> RoadMap:
    """A junction's lanes, lights and kerb geometry (see the module docstring for names).

    Args:
        shape: arms, lanes, widths, kerb radius and skews.
        signalized: add the two light groups (:func:`signal_lights`) and mark approach lanes.
        ego_red_s: s, initial red of the ego's light (signalized only).

    Raises:
        ValueError: for an arm count / missing arm that is not a junction, or a corner angle
            outside the admissible range.
    """
    if shape.num_arms == 4 and shape.missing_arm not in (None, "none"):
        raise ValueError("junction: a 4-arm junction has no missing arm")
    if shape.num_arms == 3 and shape.missing_arm not in ("E", "N", "W"):
        raise ValueError(f"junction: missing_arm must be E, N or W, got {shape.missing_arm!r}")
    if shape.num_arms not in (3, 4):
        raise ValueError(f"junction: num_arms must be 3 or 4, got {shape.num_arms}")
    arms, w = shape.arms, shape.lane_width
    corner_list = corners(shape)
    dirs = {a: _unit(shape.angle(a)) for a in arms}
    edge = box_distances(shape, corner_list)
    road = RoadMap(kind="junction", arms=arms, arm_dir=dirs, box_dist=edge,
                   lanes_per_direction=shape.lanes_per_direction, lane_width=w,
                   corners=corner_list)  # fmt: skip
    for x in arms:
        u, y, bend = dirs[x], OPPOSITE[x], float(shape.bend.get(x, 0.0))
        group = LIGHT_GROUP[x] if signalized else -1
        for k in range(shape.lanes_per_direction):
            off = (k + 0.5) * w
            inbound = _arm_points(u, edge[x], bend, off, ARM_LENGTH, 0.0)
            box_in = float(arc_length(inbound)[-1])
            stop = box_in - STOP_LINE_SETBACK if signalized else BIG
            if y in arms:  # through lane X -> Y
                out = _arm_points(dirs[y], edge[y], float(shape.bend.get(y, 0.0)), -off, 0.0,
                                  ARM_LENGTH)  # fmt: skip
                pts = _fit(np.concatenate([inbound, out]))
                box_out = box_in + float(np.linalg.norm(out[0] - inbound[-1]))
                name = f"{x}{y}_{k}"
            else:  # stems: inbound lane ends at the box, outbound lane starts there
                pts, name, box_out = inbound, f"{x}_in_{k}", math.nan
                out = _arm_points(u, edge[x], bend, -off, 0.0, ARM_LENGTH)
                road.add(LaneSpec(f"{x}_out_{k}", _fit(out), w, LANE_DRIVING, box_out_s=0.0))
            road.add(LaneSpec(name, pts, w, LANE_DRIVING, group, stop, box_in, box_out))
    if signalized:
        road.lights = signal_lights(road, ego_red_s)
    return road


def stop_line_xy(road: RoadMap, arm: str) -> np.ndarray:
    """(2,) centre of the stop line across the inbound lanes of ``arm``, m (canonical frame)."""
    u = road.arm_dir[arm]
    across = road.lanes_per_direction * road.lane_width / 2.0
    return (road.box_dist[arm] + STOP_LINE_SETBACK) * u + _rot90(u) * across


def signal_lights(road: RoadMap, ego_red_s: float) -> list[LightSpec]:
    """The two light groups of a signalized junction (ego approach = arm S).

    Light 0 (N-S approaches, the ego's) is red for ``ego_red_s`` seconds from t = 0, then green
    for 90 s.  Light 1 (E-W approaches) is its complement: green (or yellow) until
    ``ego_red_s`` and red from then on, so the ego's green never overlaps the cross green.
    """
    cycle = LIGHT_GREEN_S + LIGHT_YELLOW_S + LIGHT_RED_S
    off0 = cycle - ego_red_s  # phase at t = 0: inside red with ego_red_s remaining
    off1 = LIGHT_GREEN_S + LIGHT_YELLOW_S - ego_red_s  # red starts exactly at t = ego_red_s
    out = []
    for group, off in ((0, off0), (1, off1)):
        arm = "S" if group == 0 else ("W" if "W" in road.arms else "E")
        stop = stop_line_xy(road, arm)
        out.append(LightSpec(LIGHT_GREEN_S, LIGHT_YELLOW_S, LIGHT_RED_S, off % cycle, stop))
    return out


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
    outbound lane (a :func:`~lantern_jax.scenarios.road.fillet`: straight, tangent arc,
    straight).  Its arc is concentric with the kerb fillet of the corner the turn goes round
    (the corner between the two arms), as real lane markings are, so it keeps its distance
    from the kerb (``kerb_radius + lane_width / 2`` for a turn between the kerb-side lanes).
    """
    name = f"{from_arm}{k_in}>{to_arm}{k_out}"
    if name in road.names:
        return name
    if to_arm in (from_arm, OPPOSITE[from_arm]):
        raise ValueError(f"add_connector: {from_arm}->{to_arm} is not a turn")
    lin, s_in = inbound_lane(road, from_arm, k_in)
    lout, s_out = outbound_lane(road, to_arm, k_out)
    p0 = point_at(road.lane(lin).center, s_in)
    p1 = point_at(road.lane(lout).center, s_out)
    corner = corner_between(road, from_arm, to_arm)
    radius = None
    if corner is not None:  # distance from the fillet centre to the inbound lane line
        u = road.arm_dir[from_arm]
        radius = abs(float((corner.fillet_centre - p0) @ _rot90(u)))
    pts = fillet(p0, -road.arm_dir[from_arm], p1, road.arm_dir[to_arm], ROUTE_SPACING, radius)
    if len(pts) > LANE_POINTS:
        pts = resample(pts, LANE_POINTS)
    road.add(LaneSpec(name, pts, road.lane_width, LANE_CONNECTOR, box_in_s=0.0, box_out_s=0.0))
    return name


def min_turn_radius(xy: np.ndarray) -> float:
    """m, the smallest radius of the circle through three consecutive points of a polyline
    (BIG for a straight one)."""
    a, b, c = xy[:-2], xy[1:-1], xy[2:]
    ab, bc, ca = (np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                  np.linalg.norm(a - c, axis=1))  # fmt: skip
    cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    r = np.where(cross > 1e-9, ab * bc * ca / np.maximum(2.0 * cross, 1e-12), BIG)
    return float(np.min(r)) if len(r) else BIG


def turn_direction(from_arm: str, to_arm: str) -> str:
    """``"left"``, ``"right"`` or ``"straight"``: the nominal movement from ``from_arm`` to
    ``to_arm``."""
    if to_arm == OPPOSITE[from_arm]:
        return "straight"
    h0, h1 = -_unit(NOMINAL_ANGLE_DEG[from_arm]), _unit(NOMINAL_ANGLE_DEG[to_arm])
    cross = h0[0] * h1[1] - h0[1] * h1[0]
    if abs(cross) < 1e-9:
        raise ValueError(f"turn_direction: {from_arm}->{to_arm} is a U-turn")
    return "left" if cross > 0 else "right"


def turn_route(
    road: RoadMap, from_arm: str, k_in: int, to_arm: str, k_out: int, approach: float,
    length: float,
) -> RouteSpec:  # fmt: skip
    """Ego route through a junction: ``approach`` m straight to the box, the connector lane of
    the turn, then along the exit lane until the route is ``length`` m long.

    Raises:
        ValueError: when the lanes are too short or ``length`` leaves no exit segment, or for a
            straight movement.
    """
    if to_arm == OPPOSITE[from_arm]:
        raise ValueError(f"turn_route: {from_arm}->{to_arm} is not a turn")
    conn = add_connector(road, from_arm, k_in, to_arm, k_out)
    lin, s_in = inbound_lane(road, from_arm, k_in)
    lout, s_out = outbound_lane(road, to_arm, k_out)
    cpts = road.lane(conn).center
    c_len = float(arc_length(cpts)[-1])
    exit_len = length - approach - c_len
    if approach <= 0 or approach > s_in:
        raise ValueError(f"turn_route: approach {approach} outside (0, {s_in}]")
    out_lane = road.lane(lout).center
    if exit_len <= 0 or s_out + exit_len > float(arc_length(out_lane)[-1]):
        raise ValueError(f"turn_route: route length {length} leaves an exit of {exit_len:.2f} m")
    a = densify(segment(road.lane(lin).center, s_in - approach, s_in), ROUTE_SPACING)
    e = densify(segment(out_lane, s_out, s_out + exit_len), ROUTE_SPACING)
    xy = np.concatenate([a[:-1], cpts, e[1:]])
    stop = road.lane(lin).stop_s
    stop_s = approach - (s_in - stop) if stop < BIG else BIG
    return RouteSpec(xy, (lin, conn, lout), approach, approach + c_len, stop_s)


def through_route(
    road: RoadMap, from_arm: str, k: int, approach: float, length: float
) -> RouteSpec:  # fmt: skip
    """Ego route straight through a junction along the through lane from ``from_arm`` to the
    opposite arm, lane ``k``: ``approach`` m before the box, then on until the route is
    ``length`` m long.

    Raises:
        ValueError: when the opposite arm is missing or the lane is too short.
    """
    to_arm = OPPOSITE[from_arm]
    if to_arm not in road.arms or from_arm not in road.arms:
        raise ValueError(f"through_route: no straight movement {from_arm}->{to_arm}")
    name, s_in = inbound_lane(road, from_arm, k)
    lane = road.lane(name)
    if approach <= 0 or approach > s_in or s_in - approach + length > lane.length:
        raise ValueError(
            f"through_route: approach {approach} and length {length} do not fit lane {name} "
            f"({lane.length:.1f} m, box entry at {s_in:.1f} m)"
        )
    xy = densify(segment(lane.center, s_in - approach, s_in - approach + length), ROUTE_SPACING)
    stop_s = approach - (s_in - lane.stop_s) if lane.stop_s < BIG else BIG
    box_out = approach + lane.box_out_s - s_in
    return RouteSpec(xy, (name,), approach, box_out, stop_s)


# ------------------------------------------------------------------------------------------------
# occluders
# ------------------------------------------------------------------------------------------------
def _corner_anchor(c: Corner, kerb_radius: float, setback: float) -> np.ndarray:
    """The corner occluder's point nearest the junction: ``setback`` inside the fillet arc."""
    b = c.kerb_point - c.fillet_centre
    return c.fillet_centre + (kerb_radius - setback) * b / np.linalg.norm(b)


def corner_occluders(
    road: RoadMap, c: Corner, kind: int, setback: float, size: float, kerb_radius: float
) -> list[OccluderSpec]:
    """A building (one ``size`` x ``size`` box) or a wall (two thin boxes, ``size`` long, along
    both kerbs) at corner ``c``, ``setback`` m inside the fillet arc.

    The building is aligned with arm ``a``; at a corner sharper than 90 degrees it is slid out
    along arm ``a`` until its far side clears arm ``b``'s kerb by ``setback`` as well.
    """
    if not 0.0 < setback < kerb_radius:
        raise ValueError(f"corner_setback: {setback:g} must lie in (0, kerb radius "
                         f"{kerb_radius:g})")  # fmt: skip
    q = _corner_anchor(c, kerb_radius, setback)
    ua, ub = road.arm_dir[c.a], road.arm_dir[c.b]
    na, nb = _rot90(ua), _rot90(ub)
    yaw_a, yaw_b = math.atan2(ua[1], ua[0]), math.atan2(ub[1], ub[0])
    tag = f"corner_{c.a}{c.b}"
    if kind == OCC_WALL:
        t = WALL_THICKNESS
        return [
            OccluderSpec(q + 0.5 * size * ua + 0.5 * t * na, yaw_a, (0.5 * size, 0.5 * t),
                         OCC_WALL, f"{tag}_wall_{c.a}"),
            OccluderSpec(q + 0.5 * size * ub - 0.5 * t * nb, yaw_b, (0.5 * size, 0.5 * t),
                         OCC_WALL, f"{tag}_wall_{c.b}"),
        ]  # fmt: skip
    # building: Q + [a0, a0 + size] ua + [0, size] na; its far corner must stay on b's off-road
    # side: (P - Q).(-nb) >= 0  ->  a0 (ua.-nb) + size (na.-nb) >= 0
    alpha, beta = float(ua @ -nb), float(na @ -nb)
    a0 = max(0.0, -size * beta / max(alpha, 1e-6))
    centre = q + (a0 + 0.5 * size) * ua + 0.5 * size * na
    return [OccluderSpec(centre, yaw_a, (0.5 * size, 0.5 * size), OCC_BUILDING, tag)]


def waiting_truck(road: RoadMap, arm: str, k: int, length: float) -> OccluderSpec:
    """A truck standing in inbound lane ``k`` of ``arm`` with its front just short of the stop
    line, aligned with the lane there (kind parked vehicle)."""
    name, box_in = inbound_lane(road, arm, k)
    lane = road.lane(name).center
    s = box_in - STOP_LINE_SETBACK - TRUCK_STOP_GAP - 0.5 * length
    return OccluderSpec(point_at(lane, s), heading_at(lane, s), (0.5 * length, TRUCK_HALF_WIDTH),
                        OCC_PARKED_VEHICLE, f"truck_{arm}")  # fmt: skip


def corner_between(road: RoadMap, a: str, b: str) -> Corner | None:
    """The corner between arms ``a`` and ``b`` (either order), or None when they share none."""
    for c in road.corners:
        if {c.a, c.b} == {a, b}:
            return c
    return None
