"""Straight-road families: Pedestrian Emergence (PE), Vehicle Cut-In (VC), Obstacle Reveal (OR).

Every pair is laid out on its own gently curved multi-lane road in road coordinates ``(s, d)``
(:mod:`lantern_jax.scenarios.road_straight`: ``s`` = arc along the ego lane's centre = route arc,
``d`` = lateral offset, + left), with its own lane count and width and rotated afterwards by
``rotation_deg``.  PE and VC roads have a two-piece curvature (``curvature_1`` before
``curve_split``, ``curvature_2`` after, at most 1/70 m); the OR road is straight up to just past
the object and then turns a street corner (:func:`or_centerline`).  The ego starts at
``s = 0``.  Background traffic uses only the opposing lanes (it never shares a lane with the ego
or the scenario actors, which keeps the 55-m ego-lane corridor, the VC 25-m interaction region
and the OR 14-m van zone free by construction).
"""

from __future__ import annotations

import numpy as np

from lantern_jax.core.constants import (
    BIG,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    INF_TIME,
    KIND_PEDESTRIAN,
    KIND_STATIC,
    KIND_VEHICLE,
    MOTION_IDM,
    OCC_PARKED_VEHICLE,
    OR,
    PE,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    ROLE_OCCLUDER,
    TRIGGER_EVENT,
    TRIGGER_NEVER,
    VC,
)
from lantern_jax.scenarios import road
from lantern_jax.scenarios.assemble import ActorSpec
from lantern_jax.scenarios.families_common import (
    CAR_EXTENT,
    HAZARD_SLOT,
    SCENE_SLOT,
    LaneSection,
    check_occluders,
    choose,
    common_fields,
    draw,
    finish_pair,
    with_changes,
)
from lantern_jax.scenarios.road import ROAD_MARGIN, VAN_HALF_WIDTH
from lantern_jax.scenarios.road_straight import (
    Centerline,
    StraightLayout,
    ego_route,
    lane_path,
    straight_road,
)
from lantern_jax.scenarios.spec import MIN_RECOVERY_M, PARAM_RANGES

# --- PE geometry -------------------------------------------------------------------------------
PE_WARN_LEAD, PE_EVENT_LEAD = 18.0, 9.0
PED_EXTENT = (0.3, 0.3)
PED_SPEED = 3.0  # m/s
PED_CROSSING = 22.0  # m
PE_RECOVERY = 30.0  # m of route after the conflict point (paper: PE has a 30-m recovery)
TRUCK_KERB_GAP = 0.1  # m between the parked truck and the kerb
PARKED_CAR_GAP = 2.5  # m between consecutive parked vehicles
PARKED_FIRST_GAP = 6.0  # m from the crossing line to the first further parked car

# --- VC geometry -------------------------------------------------------------------------------
VC_START_GAP = 21.0  # m, cut-in vehicle ahead of the ego at t = 0 (centre to centre)
VC_EVENT_LEAD = 4.0
VC_MIN_SPEED = 6.5  # m/s
VC_LANE_CHANGE_S = 2.0
VC_MIN_WARN_S = 15.0  # m, minimum route arc of the warning point (normal approach)

# --- OR geometry -------------------------------------------------------------------------------
OR_WARN_LEAD, OR_EVENT_LEAD = 12.0, 6.0
OBJECT_HALF_LENGTH = 1.0  # m
OR_LANE_CHANGE_S = 2.5
OR_STOP_LIMIT_S = 8.0
OR_VAN_TRAVEL_MIN = 10.0  # m the van drives before its lane change
OR_VAN_ZONE = 14.0  # m, no background vehicle starts this close to the van
OR_REVEAL_SAMPLED = (30.0, 50.0)  # m, where the sampler puts the reveal point (in range; the
# straight approach stays a small enough share of the route for routes to differ)
OR_MIN_CLEARANCE = 0.3  # m, the van passes the object at least this far apart
PREMISE_SAMPLES = 5  # van positions at which the OR premise is checked


# ================================================================================================
# shared road
# ================================================================================================
def sample_straight(rng: np.random.Generator, fam: str, p: dict) -> None:
    """Draw the road geometry fields every straight family shares, into ``p``."""
    p["lane_width"] = draw(rng, fam, "lane_width")
    p["lanes_back"] = int(choose(rng, fam, "lanes_back"))
    p["curvature_1"] = draw(rng, fam, "curvature_1", nd=6)
    p["curvature_2"] = draw(rng, fam, "curvature_2", nd=6)
    if "curve_split" in PARAM_RANGES[fam]:
        p["curve_split"] = draw(rng, fam, "curve_split")


def centerline(p: dict) -> Centerline:
    """The ego lane's centre line of a straight-family pair: ``curvature_1`` before
    ``curve_split`` and ``curvature_2`` after it, except Obstacle Reveal, whose road is straight
    from 20 m before the warning point to 10 m past the object (:func:`or_centerline`)."""
    if p["family"] == "OR":
        return or_centerline(p)
    return Centerline.two_piece(p["curvature_1"], p["curvature_2"], p["curve_split"])


def _road(p: dict, layout: StraightLayout):
    line = centerline(p)
    length = float(p["route_length"])
    road_map = straight_road(layout, line, -ROAD_MARGIN, length + ROAD_MARGIN)
    route = ego_route(line, length, f"fwd_{layout.ego_lane}")
    return road_map, route, line


def opposing_sections(road_map: road.RoadMap, line: Centerline, layout: StraightLayout,
                       s_lo: float, s_hi: float) -> list[LaneSection]:  # fmt: skip
    """Sections of the backward lanes between road arcs ``s_lo`` and ``s_hi`` (they run from the
    high-``s`` end, so lane arcs count backwards)."""
    out = []
    for k in range(layout.lanes_back):
        lane = road_map.lane(f"back_{k}")
        d = layout.back_d(k)
        a_lo, _ = road.project(lane.center, line.to_xy(s_hi, d))
        a_hi, _ = road.project(lane.center, line.to_xy(s_lo, d))
        out.append(LaneSection(lane, a_lo, a_hi))
    return out


def _occluder(line: Centerline, s: float, d: float, extent, kind: int, name: str):
    return road.OccluderSpec(line.to_xy(s, d), float(line.heading(s)), tuple(extent), kind, name)


def _static_on_road(line: Centerline, s: float, d: float, extent, kind: int, role: int):
    """A motionless actor at road coordinates ``(s, d)`` facing along the road."""
    path = line.line(s, s + 1.0, d, 1.0)
    return ActorSpec(path, tuple(extent), kind, role)


# ================================================================================================
# PE
# ================================================================================================
def sample_pe(rng: np.random.Generator, weather: str) -> dict:
    """Sample PE parameters (conflict first, then a route with >= 30 m of recovery)."""
    p = common_fields(rng, "PE", weather)
    sample_straight(rng, "PE", p)
    p["v_ref"] = draw(rng, "PE", "v_ref")
    p["conflict_s"] = draw(rng, "PE", "conflict_s")
    p["route_length"] = draw(rng, "PE", "route_length", p["conflict_s"] + PE_RECOVERY + 0.5)
    p["lanes_fwd"] = int(choose(rng, "PE", "lanes_fwd"))
    # the truck keeps the route corridor clear: lane_width / 2 + parking_width - kerb gap -
    # truck_width >= EGO_HALF_WIDTH + CORRIDOR_MARGIN, plus the sag of a straight 10-m box on
    # the curved kerb (10^2 / 70 / 8 = 0.18 m)
    room = EGO_HALF_WIDTH + road.CORRIDOR_MARGIN + 0.2 + TRUCK_KERB_GAP - 0.5 * p["lane_width"]
    w_min = PARAM_RANGES["PE"]["truck_width"].lo
    p["parking_width"] = draw(rng, "PE", "parking_width", at_least=w_min + room)
    p["truck_length"] = draw(rng, "PE", "truck_length")
    p["truck_width"] = draw(rng, "PE", "truck_width", at_most=p["parking_width"] - room)
    p["ped_gap"] = draw(rng, "PE", "ped_gap")
    p["ped_offset"] = draw(rng, "PE", "ped_offset")
    p["parked_count"] = int(choose(rng, "PE", "parked_count"))
    return p


def check_pe(p: dict) -> None:
    need = p["conflict_s"] + PE_RECOVERY
    if p["route_length"] < need:
        raise ValueError(
            f"PE.route_length: {float(p['route_length'])!r} too short, needs >= conflict_s + "
            f"{PE_RECOVERY:g} = {need:g}"
        )
    check_occluders("PE", p, build_pe_scene(p))


def _pe_layout(p: dict) -> StraightLayout:
    n = int(p["lanes_fwd"])
    return StraightLayout(n, int(p["lanes_back"]), float(p["lane_width"]), n - 1,
                          float(p["parking_width"]))  # fmt: skip


def build_pe_scene(p: dict):
    """The PE road, route, centre line and occluders (no actors): ``(road_map, route, line,
    pedestrian (s, d))``."""
    layout = _pe_layout(p)
    road_map, route, line = _road(p, layout)
    sc = float(p["conflict_s"])
    kerb = layout.kerb_d
    tl, tw = float(p["truck_length"]), float(p["truck_width"])
    truck_s = sc - PED_EXTENT[0] - float(p["ped_gap"]) - 0.5 * tl
    truck_d = kerb + TRUCK_KERB_GAP + 0.5 * tw
    occ = [_occluder(line, truck_s, truck_d, (0.5 * tl, 0.5 * tw), OCC_PARKED_VEHICLE, "truck")]
    park_d = kerb + TRUCK_KERB_GAP + CAR_EXTENT[1]
    s_car = sc + PARKED_FIRST_GAP + CAR_EXTENT[0]
    for k in range(int(p["parked_count"])):
        occ.append(_occluder(line, s_car, park_d, CAR_EXTENT, OCC_PARKED_VEHICLE, f"parked_{k}"))
        s_car += 2.0 * CAR_EXTENT[0] + PARKED_CAR_GAP
    road_map.occluders = occ
    return road_map, route, line, (sc, kerb - float(p["ped_offset"]))


def build_pe(p: dict):
    """PE: a pedestrian hidden behind a parked truck crosses the ego lane.

    ``lanes_fwd`` lanes in the ego direction (the ego in the rightmost one), ``lanes_back``
    opposing, and a parking lane of ``parking_width`` on the ego's right with the kerb beyond.
    The truck or van (``truck_length`` x ``truck_width``, a static occluder of the map, kind
    parked vehicle) is parked 0.1 m from the kerb with its front ``ped_gap`` short of the
    pedestrian's box; the pedestrian stands on the sidewalk at the conflict arc, ``ped_offset``
    beyond the kerb, so the truck hides it on the approach (checked by the premise rule of the
    static validation, :mod:`lantern_jax.scenarios.premise`).  ``parked_count`` further cars are
    parked beyond the crossing.  On the event the pedestrian walks a straight 22-m crossing at
    3 m/s across the road and despawns at its end; the crossing done is the clearance.  Route B
    keeps the truck (it is part of the map), without the pedestrian.
    """
    road_map, route, line, (sc, ped_d) = build_pe_scene(p)
    start = line.to_xy(sc, ped_d)
    end = line.to_xy(sc, ped_d + PED_CROSSING)
    ped = ActorSpec(
        np.stack([start + (end - start) * t for t in np.linspace(0.0, 1.0, 12)]),
        PED_EXTENT,
        KIND_PEDESTRIAN,
        ROLE_HAZARD,
        v_pre=0.0,
        v_post=PED_SPEED,
        s_end=PED_CROSSING,
        trigger=TRIGGER_EVENT,
        despawn_at_end=True,
    )
    markers = (sc - PE_WARN_LEAD, sc - PE_EVENT_LEAD, sc)
    sections = opposing_sections(road_map, line, _pe_layout(p), -ROAD_MARGIN + 10.0, sc - 10.0)
    rules = dict(
        clear_s=PED_CROSSING, clear_time_limit=BIG, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=True,
    )  # fmt: skip
    extra = dict(
        conflict_xy=line.to_xy(sc, 0.0).tolist(), ped_xy=start.tolist(), premise_times=[0.0]
    )
    return finish_pair(p, PE, road_map, route, {HAZARD_SLOT: ped}, {}, sections, markers,
                       rules, extra)  # fmt: skip


# ================================================================================================
# VC
# ================================================================================================
def vc_cut_speed(v_ref: float, cut_frac: float) -> float:
    """Cut-in speed: ``max(6.5, cut_frac * v_ref)`` m/s."""
    return max(VC_MIN_SPEED, cut_frac * v_ref)


def vc_conflict_s(v_ref: float, cut_frac: float, gap_event: float) -> float:
    """Route arc of the VC conflict point from nominal kinematics.

    With the ego at ``v_ref`` and the cut-in vehicle at ``v_cut`` starting 21 m ahead, the centre
    gap is ``21 - (v_ref - v_cut) t``; it equals ``gap_event`` at the event, when the ego is at
    ``s_event = v_ref t``.  Hence ``s_conflict = 4 + v_ref (21 - gap_event) / (v_ref - v_cut)``.
    """
    v_cut = vc_cut_speed(v_ref, cut_frac)
    return VC_EVENT_LEAD + v_ref * (VC_START_GAP - gap_event) / (v_ref - v_cut)


def sample_vc(rng: np.random.Generator, weather: str) -> dict:
    """Sample VC parameters (route long enough for 29 m of recovery)."""
    p = common_fields(rng, "VC", weather)
    sample_straight(rng, "VC", p)
    p["v_ref"] = draw(rng, "VC", "v_ref")
    p["cut_frac"] = draw(rng, "VC", "cut_frac")
    p["gap_event"] = draw(rng, "VC", "gap_event")
    p["warn_lead"] = float(choose(rng, "VC", "warn_lead"))
    p["lanes_fwd"] = int(choose(rng, "VC", "lanes_fwd"))
    sc = vc_conflict_s(p["v_ref"], p["cut_frac"], p["gap_event"])
    p["route_length"] = draw(rng, "VC", "route_length", sc + MIN_RECOVERY_M + 0.5)
    return p


def check_vc(p: dict) -> None:
    sc = vc_conflict_s(p["v_ref"], p["cut_frac"], p["gap_event"])
    if sc - p["warn_lead"] < VC_MIN_WARN_S:
        raise ValueError(
            f"VC.gap_event: warning point at {sc - p['warn_lead']:.2f} m, needs >= "
            f"{VC_MIN_WARN_S:g}"
        )
    if p["route_length"] < sc + MIN_RECOVERY_M:
        raise ValueError(
            f"VC.route_length: {float(p['route_length'])!r} too short, needs >= s_conflict + "
            f"{MIN_RECOVERY_M:g} = {sc + MIN_RECOVERY_M:.3f}"
        )


def build_vc(p: dict):
    """VC: a vehicle 21 m ahead in the adjacent lane merges into the ego lane.

    ``lanes_fwd`` lanes in the ego direction: the ego drives the second from the right, the
    cut-in vehicle starts 21 m ahead in the rightmost one and drives at ``v_cut`` from t = 0; on
    the event it shifts one lane left over 2 s and is then handed over to the IDM
    (``handover_after``): it continues as ordinary traffic in the ego lane, following whatever is
    ahead of it.  Clearance is the merge completion (the 2-s time limit after the event; no
    geometric clearance), which the protocol records as a limit clearance.  Route B: the same
    vehicle as IDM traffic in its own lane from t = 0 (role context), never merging.
    """
    n = int(p["lanes_fwd"])
    layout = StraightLayout(n, int(p["lanes_back"]), float(p["lane_width"]), n - 2)
    road_map, route, line = _road(p, layout)
    v_cut = vc_cut_speed(p["v_ref"], p["cut_frac"])
    w = float(p["lane_width"])
    car = ActorSpec(
        lane_path(line, VC_START_GAP, p["route_length"] + ROAD_MARGIN, -w, road.PATH_POINTS),
        CAR_EXTENT,
        KIND_VEHICLE,
        ROLE_HAZARD,
        v_pre=v_cut,
        v_post=v_cut,
        trigger=TRIGGER_EVENT,
        lat_shift=w,
        lat_duration=VC_LANE_CHANGE_S,
        despawn_at_end=True,
        handover_after=VC_LANE_CHANGE_S,
    )
    car_b = with_changes(car, role=ROLE_CONTEXT, trigger=TRIGGER_NEVER, lat_shift=0.0,
                         motion=MOTION_IDM, handover_after=INF_TIME)  # fmt: skip
    sc = vc_conflict_s(p["v_ref"], p["cut_frac"], p["gap_event"])
    markers = (sc - float(p["warn_lead"]), sc - VC_EVENT_LEAD, sc)
    sections = opposing_sections(
        road_map, line, layout, -ROAD_MARGIN + 10.0, p["route_length"] + 50.0
    )
    rules = dict(
        clear_s=BIG, clear_time_limit=VC_LANE_CHANGE_S, clear_on_ego_stop=False,
        despawn_on_clear=False, force_event=True,
    )  # fmt: skip
    extra = dict(conflict_xy=line.to_xy(sc, 0.0).tolist(), v_cut=v_cut)
    return finish_pair(
        p, VC, road_map, route, {HAZARD_SLOT: car}, {HAZARD_SLOT: car_b}, sections, markers,
        rules, extra,
    )  # fmt: skip


# ================================================================================================
# OR
# ================================================================================================
OR_STRAIGHT_AFTER = 2.0  # m of straight road past the object, before the turn
OR_ROUTE_SAMPLED_MIN = 90.0  # m, the sampler's shortest route (the turn's share of the route)
OR_INNER_KERB_MIN_R = 8.0  # m, smallest radius of the inner kerb of a left turn


def or_centerline(p: dict) -> Centerline:
    """The OR road: straight from before the route start to 2 m past the object, then a turn of
    ``turn_angle`` degrees to ``turn_side`` at the ego lane's radius ``turn_radius``, then
    ``curvature_2``.

    A lead van hides an object only while ego, van and object are lined up, so the approach is
    straight; the routes differ by what follows the object (a street corner), which is what keeps
    twenty of them apart under the near-duplicate rule
    (``docs/investigations/or_route_diversity.py``).
    """
    s_b = float(p["reveal_s"]) + float(p["object_ahead"]) + OR_STRAIGHT_AFTER
    radius = float(p["turn_radius"])
    sign = 1.0 if p["turn_side"] == "left" else -1.0
    arc = np.deg2rad(float(p["turn_angle"])) * radius
    return Centerline((s_b, s_b + arc), (0.0, sign / radius, float(p["curvature_2"])))


def or_left_kerb(p: dict) -> float:
    """m, from the ego lane's centre to the road's left kerb (the inner kerb of a left turn)."""
    return (int(p["lanes_fwd"]) - 1 + int(p["lanes_back"]) + 0.5) * float(p["lane_width"])


def or_conflict_s(p: dict) -> float:
    """Route arc of the OR conflict point: where the ego's front would touch the van's rear at
    the moment the van starts its lane change at ``reveal_s`` (see :func:`build_or`)."""
    return float(p["reveal_s"]) - 0.5 * float(p["van_length"]) - EGO_HALF_LENGTH


def sample_or(rng: np.random.Generator, weather: str) -> dict:
    """Sample OR parameters (reveal point after a >= 10 m van drive, route >= object + 29 m).

    The reveal point is drawn in ``OR_REVEAL_SAMPLED`` (30-50 m of the documented 30-104 m) and
    the route from ``OR_ROUTE_SAMPLED_MIN`` (90 m of 66-133 m), so that the straight approach is
    at most about two thirds of the route and the corner after the object sets routes apart
    under the near-duplicate rule; the corner's side, angle and radius last (a left turn's radius
    leaves its inner kerb ``OR_INNER_KERB_MIN_R``).
    """
    p = common_fields(rng, "OR", weather)
    p["lane_width"] = draw(rng, "OR", "lane_width")
    p["lanes_back"] = int(choose(rng, "OR", "lanes_back"))
    p["curvature_2"] = draw(rng, "OR", "curvature_2", nd=6)
    p["v_ref"] = draw(rng, "OR", "v_ref")
    p["lead_speed_kmh"] = draw(rng, "OR", "lead_speed_kmh")
    p["lead_gap"] = draw(rng, "OR", "lead_gap")
    p["van_length"] = draw(rng, "OR", "van_length")
    # the van's guard must leave room to pass the narrowest object: shift >= 1.1 + 0.7 + 0.3
    narrow = PARAM_RANGES["OR"]["object_width"].lo
    p["object_ahead"] = draw(rng, "OR", "object_ahead", _min_object_ahead(p, narrow))
    shift = or_van_object_clearance({**p, "object_width": 0.0})
    p["object_width"] = draw(rng, "OR", "object_width", at_most=2.0 * (shift - OR_MIN_CLEARANCE))
    p["lanes_fwd"] = int(choose(rng, "OR", "lanes_fwd"))
    reveal_lo = max(OR_REVEAL_SAMPLED[0], p["lead_gap"] + OR_VAN_TRAVEL_MIN)
    p["reveal_s"] = draw(rng, "OR", "reveal_s", reveal_lo, OR_REVEAL_SAMPLED[1])
    need = p["reveal_s"] + p["object_ahead"] + MIN_RECOVERY_M + 0.5
    p["route_length"] = draw(rng, "OR", "route_length", max(need, OR_ROUTE_SAMPLED_MIN))
    p["turn_side"] = str(choose(rng, "OR", "turn_side"))
    p["turn_angle"] = draw(rng, "OR", "turn_angle")
    inner = or_left_kerb(p) + OR_INNER_KERB_MIN_R if p["turn_side"] == "left" else None
    p["turn_radius"] = draw(rng, "OR", "turn_radius", inner)
    return p


def check_or(p: dict) -> None:
    if p["reveal_s"] < p["lead_gap"] + OR_VAN_TRAVEL_MIN:
        raise ValueError(
            f"OR.reveal_s: {float(p['reveal_s'])!r} must be >= lead_gap + {OR_VAN_TRAVEL_MIN:g} "
            f"= {p['lead_gap'] + OR_VAN_TRAVEL_MIN:g}"
        )
    obj = p["reveal_s"] + p["object_ahead"]
    if p["route_length"] < obj + MIN_RECOVERY_M:
        raise ValueError(
            f"OR.route_length: {float(p['route_length'])!r} too short, needs >= reveal_s + "
            f"object_ahead + {MIN_RECOVERY_M:g} = {obj + MIN_RECOVERY_M:g}"
        )
    gap = or_van_object_clearance(p)
    if gap < OR_MIN_CLEARANCE:
        raise ValueError(
            f"OR.object_ahead: the van would pass the object {gap:.2f} m apart (needs >= "
            f"{OR_MIN_CLEARANCE:g}); reveal further before it"
        )
    inner = float(p["turn_radius"]) - or_left_kerb(p)
    if p["turn_side"] == "left" and inner < OR_INNER_KERB_MIN_R:
        raise ValueError(
            f"OR.turn_radius: {float(p['turn_radius'])!r} leaves the left turn's inner kerb a "
            f"radius of {inner:.2f} m (needs >= {OR_INNER_KERB_MIN_R:g}: turn_radius >= "
            f"{or_left_kerb(p) + OR_INNER_KERB_MIN_R:.2f} for this road)"
        )


def or_van_object_clearance(p: dict) -> float:
    """m, the smallest lateral gap between the van's and the object's boxes while the van
    overtakes the object, for a lane change that starts at the reveal point (the latest the
    van's guard lets it start; an earlier event only widens the gap).  In road coordinates:
    lateral offset of the van ``w * smoothstep(x / (v * T))`` after travelling ``x``."""
    v = float(p["lead_speed_kmh"]) / 3.6
    w, ahead = float(p["lane_width"]), float(p["object_ahead"])
    x_reach = ahead - OBJECT_HALF_LENGTH - 0.5 * float(p["van_length"])  # van front at object
    u = np.clip(x_reach / (v * OR_LANE_CHANGE_S), 0.0, 1.0)
    lat = w * u * u * (3.0 - 2.0 * u)
    return float(lat - VAN_HALF_WIDTH - 0.5 * float(p["object_width"]))


def _min_object_ahead(p: dict, object_width: float) -> float:
    """m, the smallest ``object_ahead`` for which the van clears an object of ``object_width``
    (bisection on :func:`or_van_object_clearance`, which grows with ``object_ahead``)."""
    lo, hi = 0.0, 40.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        q = {**p, "object_ahead": mid, "object_width": object_width}
        lo, hi = (lo, mid) if or_van_object_clearance(q) >= OR_MIN_CLEARANCE + 1e-3 else (mid, hi)
    return hi


def build_or(p: dict):
    """OR: a lead van changes lane and reveals a stopped object in the ego lane.

    ``lanes_fwd`` lanes in the ego direction (the ego in the rightmost one), straight from before
    the route start to 2 m past the object, then a street corner (:func:`or_centerline`).  The van
    (``van_length`` x 2.2 m, role occluder) starts ``lead_gap`` ahead in the ego lane and drives
    at ``lead_speed_kmh`` without ever stopping.  It starts its lane change (one lane left over
    2.5 s) at the event, or at the latest when it reaches the reveal point ``reveal_s`` — its own
    guard (a trigger deadline), so that it never drives into the object: the object (static,
    ``object_width`` wide, narrower than the van, role hazard) stands in the ego lane
    ``object_ahead`` m beyond the reveal point, and the guard keeps the van at least 0.3 m clear
    of it (:func:`or_van_object_clearance`, a feasibility rule).  The van hides the object from
    the ego's camera until it moves aside: on the straight approach ego, van and object stay lined
    up (across a bend the camera would see the object past the van).

    The conflict point C is **not** the object: with a lead vehicle between the ego and the
    object, an ego 12 m before the object (the paper's warning lead) would have the van's
    position — so the van would already have moved aside and the warning would carry nothing the
    camera lacks.  C is where the ego's front would touch the van's rear when the van starts its
    lane change at the reveal point (``reveal_s - van_length / 2 - ego half length``); the
    warning (C - 12) and event (C - 6) points are measured from it, so a following ego reaches
    the warning point while the van still hides the object, and the van's lane change (the
    event or its guard, whichever is first) reveals it 12-16 m ahead of the van.  Clearance: the
    object despawns once the ego has stopped after seeing it, or at the 8-s stop limit.  Route
    B: the same van, never changing lane, and no object.
    """
    n = int(p["lanes_fwd"])
    layout = StraightLayout(n, int(p["lanes_back"]), float(p["lane_width"]), n - 1)
    road_map, route, line = _road(p, layout)
    g0, v_lead = float(p["lead_gap"]), float(p["lead_speed_kmh"]) / 3.6
    reveal = float(p["reveal_s"])
    van_ext = (0.5 * float(p["van_length"]), VAN_HALF_WIDTH)
    van = ActorSpec(
        lane_path(line, g0, p["route_length"] + ROAD_MARGIN, 0.0, road.PATH_POINTS),
        van_ext,
        KIND_VEHICLE,
        ROLE_OCCLUDER,
        v_pre=v_lead,
        v_post=v_lead,
        trigger=TRIGGER_EVENT,
        trigger_deadline=(reveal - g0) / v_lead,
        lat_shift=float(p["lane_width"]),
        lat_duration=OR_LANE_CHANGE_S,
        despawn_at_end=True,
    )
    van_b = with_changes(van, lat_shift=0.0, trigger=TRIGGER_NEVER, trigger_deadline=INF_TIME)
    s_obj = reveal + float(p["object_ahead"])
    obj_ext = (OBJECT_HALF_LENGTH, 0.5 * float(p["object_width"]))
    obj = _static_on_road(line, s_obj, 0.0, obj_ext, KIND_STATIC, ROLE_HAZARD)
    c = or_conflict_s(p)
    markers = (c - OR_WARN_LEAD, c - OR_EVENT_LEAD, c)
    sections = opposing_sections(
        road_map, line, layout, -ROAD_MARGIN + 10.0, p["route_length"] + 50.0
    )
    exclusion = [(line.to_xy(g0, 0.0), OR_VAN_ZONE)]
    rules = dict(
        clear_s=BIG, clear_time_limit=OR_STOP_LIMIT_S, clear_on_ego_stop=True,
        despawn_on_clear=True, force_event=True,
    )  # fmt: skip
    # premise: the van anywhere between touching the ego (at the warning point) and its reveal
    t_touch = (markers[0] + EGO_HALF_LENGTH + van_ext[0] - g0) / v_lead
    t_reveal = (reveal - g0) / v_lead
    times = np.linspace(max(0.0, t_touch), t_reveal, PREMISE_SAMPLES).tolist()
    extra = dict(conflict_xy=line.to_xy(c, 0.0).tolist(), object_xy=line.to_xy(s_obj, 0.0).tolist(),
                 v_lead=v_lead, premise_times=times)  # fmt: skip
    return finish_pair(
        p, OR, road_map, route, {HAZARD_SLOT: obj, SCENE_SLOT: van}, {SCENE_SLOT: van_b},
        sections, markers, rules, extra, exclusion=exclusion,
    )  # fmt: skip
