"""Straight-road families: Pedestrian Emergence (PE), Vehicle Cut-In (VC), Obstacle Reveal (OR).

All three are built on a straight carriageway along +x (canonical frame, rotated afterwards by
``rotation_deg``); the ego starts at x = 0 on its lane centre, so route arc = x.  Background
traffic uses only the opposing lanes (it never shares a lane with the ego or the scenario
actors, which keeps the 55-m ego-lane corridor, the VC 25-m interaction region and the OR 14-m
van zone free by construction).
"""

from __future__ import annotations

import numpy as np

from lantern_jax.constants import (
    BIG,
    KIND_PEDESTRIAN,
    KIND_STATIC,
    KIND_VEHICLE,
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
    choose,
    common_fields,
    draw,
    finish_pair,
    static_actor,
    straight_path,
    with_changes,
)
from lantern_jax.scenarios.spec import MIN_RECOVERY_M
from lantern_jax.scoring.thresholds import D_SAFE_LARGE_M, D_SAFE_SMALL_M

ROAD_MARGIN = 60.0  # m of road before the route start and after the route end

# --- PE geometry -------------------------------------------------------------------------------
PE_WARN_LEAD, PE_EVENT_LEAD = 18.0, 9.0
PED_EXTENT = (0.3, 0.3)
PED_SPEED = 3.0  # m/s
PED_CROSSING = 22.0  # m
PED_BEYOND_TRUCK = 0.5  # m, pedestrian centre beyond the truck's far (kerb-side) face
TRUCK_EXTENT = (4.0, 1.25)
TRUCK_FRONT_GAP = 0.3  # m, between the truck's front face and the pedestrian's box
PE_RECOVERY = 30.0  # m of route after the conflict point (paper: PE has a 30-m recovery)

# --- VC geometry -------------------------------------------------------------------------------
VC_START_GAP = 21.0  # m, cut-in vehicle ahead of the ego at t = 0 (centre to centre)
VC_EVENT_LEAD = 4.0
VC_MIN_SPEED = 6.5  # m/s
VC_LANE_CHANGE_S = 2.0
VC_MIN_WARN_S = 15.0  # m, minimum route arc of the warning point (normal approach)

# --- OR geometry -------------------------------------------------------------------------------
OR_WARN_LEAD, OR_EVENT_LEAD = 12.0, 6.0
VAN_EXTENT = (2.6, 1.1)
OBJECT_EXTENT = (1.0, 0.9)
OR_LANE_CHANGE_S = 2.5
OR_STOP_LIMIT_S = 8.0
OR_VAN_TRAVEL_MIN = 10.0  # m the van drives before reaching C
OR_VAN_ZONE = 14.0  # m, no background vehicle starts this close to the van
OR_REVEAL_SAMPLED = (35.0, 80.0)  # m, where the sampler puts C (a part of the admissible range)



def _road_and_route(p: dict, fwd: int, back: int, shoulder: bool, ego_lane: str):
    length = float(p["route_length"])
    road_map = road.straight_road(fwd, back, length + 2 * ROAD_MARGIN, shoulder, -ROAD_MARGIN)
    route = road.lane_route(road_map, ego_lane, ROAD_MARGIN, length)
    return road_map, route


def _opposing_sections(road_map: road.RoadMap, x_lo: float, x_hi: float) -> list[LaneSection]:
    """Sections of the backward lanes with x in ``[x_lo, x_hi]`` (lanes run from high x)."""
    out = []
    for ln in road_map.lanes:
        if ln.name.startswith("back_"):
            x_start = ln.center[0, 0]
            out.append(LaneSection(ln, x_start - x_hi, x_start - x_lo))
    return out


# ================================================================================================
# PE
# ================================================================================================
def sample_pe(rng: np.random.Generator, weather: str) -> dict:
    """Sample PE parameters (conflict first, then a route with >= 30 m of recovery)."""
    p = common_fields(rng, "PE", weather)
    p["v_ref"] = draw(rng, "PE", "v_ref")
    p["conflict_s"] = draw(rng, "PE", "conflict_s")
    p["route_length"] = draw(rng, "PE", "route_length", p["conflict_s"] + PE_RECOVERY + 0.5)
    return p


def check_pe(p: dict) -> None:
    need = p["conflict_s"] + PE_RECOVERY
    if p["route_length"] < need:
        raise ValueError(
            f"PE.route_length: {float(p['route_length'])!r} too short, needs >= conflict_s + "
            f"{PE_RECOVERY:g} = {need:g}"
        )


def pe_geometry(conflict_s: float) -> dict:
    """Canonical PE actor poses: pedestrian centre, truck centre and the sidewalk edge (m)."""
    kerb = -(road.LANE_WIDTH + road.PARKING_WIDTH)  # far edge of the parking lane
    ped = np.array([conflict_s, kerb - PED_BEYOND_TRUCK])
    truck_x = conflict_s - PED_EXTENT[0] - TRUCK_FRONT_GAP - TRUCK_EXTENT[0]
    truck = np.array([truck_x, -road.LANE_WIDTH - 0.5 * road.PARKING_WIDTH])
    return dict(ped=ped, truck=truck, kerb=kerb)


def build_pe(p: dict):
    """PE: a pedestrian hidden behind a parked truck crosses the ego lane.

    One lane each way plus a 2.5-m parking lane on the ego's right, sidewalk beyond.  The truck
    (half extents 4.0 x 1.25) is parked in the parking lane with its front 0.3 m short of the
    pedestrian; the pedestrian stands on the sidewalk at the conflict x, 0.5 m beyond the
    truck's kerb-side face, so every camera ray to it crosses the truck during the approach.
    ``conflict_s <= 48`` keeps this true from the route start with ~0.5 m to spare (from farther
    away a ray to the pedestrian's rear corner passes behind the truck's rear).  On the event it
    walks a straight 22-m crossing at 3 m/s perpendicular to the road and despawns at its end; the
    crossing done is the clearance.  Route B keeps the truck, without the pedestrian.
    """
    road_map, route = _road_and_route(p, 1, 1, True, "fwd_0")
    g = pe_geometry(p["conflict_s"])
    truck = static_actor(g["truck"], 0.0, TRUCK_EXTENT, KIND_VEHICLE, ROLE_OCCLUDER)
    ped = ActorSpec(
        straight_path(g["ped"], (0.0, 1.0), PED_CROSSING),
        PED_EXTENT,
        KIND_PEDESTRIAN,
        ROLE_HAZARD,
        v_pre=0.0,
        v_post=PED_SPEED,
        s_end=PED_CROSSING,
        trigger=TRIGGER_EVENT,
        despawn_at_end=True,
    )
    sc = float(p["conflict_s"])
    markers = (sc - PE_WARN_LEAD, sc - PE_EVENT_LEAD, sc)
    sections = _opposing_sections(road_map, -ROAD_MARGIN + 10.0, sc - 10.0)
    slots_a = {HAZARD_SLOT: ped, SCENE_SLOT: truck}
    slots_b = {SCENE_SLOT: truck}
    rules = dict(
        clear_s=PED_CROSSING, clear_time_limit=BIG, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=True, d_safe=D_SAFE_SMALL_M,
    )  # fmt: skip
    extra = dict(conflict_xy=[sc, -0.5 * road.LANE_WIDTH], ped_xy=g["ped"].tolist())
    return finish_pair(p, PE, road_map, route, slots_a, slots_b, sections, markers, rules, extra)


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
    p["v_ref"] = draw(rng, "VC", "v_ref")
    p["cut_frac"] = draw(rng, "VC", "cut_frac")
    p["gap_event"] = draw(rng, "VC", "gap_event")
    p["warn_lead"] = float(choose(rng, "VC", "warn_lead"))
    p["num_opposing"] = int(choose(rng, "VC", "num_opposing"))
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

    Two lanes in the ego direction (ego in the left one, ``fwd_0``) and one or two opposing.
    The cut-in vehicle starts in ``fwd_1`` 21 m ahead and drives at ``v_cut`` from t = 0; on the
    event it shifts 3.5 m left over 2 s and then simply keeps its lane and speed.  That constant
    speed after the merge stands in for the paper's hand-over to Traffic Manager.  Clearance is
    the merge completion: the 2-s time limit after the event (no geometric clearance), so the
    protocol records it as a limit clearance.  Route B: the same vehicle at the same speed,
    never merging (role context).
    """
    road_map, route = _road_and_route(p, 2, int(p["num_opposing"]), False, "fwd_0")
    v_cut = vc_cut_speed(p["v_ref"], p["cut_frac"])
    start = np.array([VC_START_GAP, -1.5 * road.LANE_WIDTH])
    length = p["route_length"] + ROAD_MARGIN - VC_START_GAP
    car = ActorSpec(
        straight_path(start, (1.0, 0.0), length),
        CAR_EXTENT,
        KIND_VEHICLE,
        ROLE_HAZARD,
        v_pre=v_cut,
        v_post=v_cut,
        trigger=TRIGGER_EVENT,
        lat_shift=road.LANE_WIDTH,
        lat_duration=VC_LANE_CHANGE_S,
        despawn_at_end=True,
    )
    car_b = with_changes(car, role=ROLE_CONTEXT, trigger=TRIGGER_NEVER, lat_shift=0.0)
    sc = vc_conflict_s(p["v_ref"], p["cut_frac"], p["gap_event"])
    markers = (sc - float(p["warn_lead"]), sc - VC_EVENT_LEAD, sc)
    sections = _opposing_sections(road_map, -ROAD_MARGIN + 10.0, p["route_length"] + 50.0)
    rules = dict(
        clear_s=BIG, clear_time_limit=VC_LANE_CHANGE_S, clear_on_ego_stop=False,
        despawn_on_clear=False, force_event=True, d_safe=D_SAFE_LARGE_M,
    )  # fmt: skip
    extra = dict(conflict_xy=[sc, -0.5 * road.LANE_WIDTH], v_cut=v_cut)
    return finish_pair(
        p, VC, road_map, route, {HAZARD_SLOT: car}, {HAZARD_SLOT: car_b}, sections, markers,
        rules, extra,
    )  # fmt: skip


# ================================================================================================
# OR
# ================================================================================================
def sample_or(rng: np.random.Generator, weather: str) -> dict:
    """Sample OR parameters (C after a >= 10 m van drive, route >= C + 29 m)."""
    p = common_fields(rng, "OR", weather)
    p["v_ref"] = draw(rng, "OR", "v_ref")
    p["lead_speed_kmh"] = draw(rng, "OR", "lead_speed_kmh")
    p["lead_gap"] = draw(rng, "OR", "lead_gap")
    p["object_ahead"] = draw(rng, "OR", "object_ahead")
    p["num_opposing"] = int(choose(rng, "OR", "num_opposing"))
    reveal_lo = max(OR_REVEAL_SAMPLED[0], p["lead_gap"] + OR_VAN_TRAVEL_MIN)
    p["reveal_s"] = draw(rng, "OR", "reveal_s", reveal_lo, OR_REVEAL_SAMPLED[1])
    p["route_length"] = draw(rng, "OR", "route_length", p["reveal_s"] + MIN_RECOVERY_M + 0.5)
    return p


def check_or(p: dict) -> None:
    if p["reveal_s"] < p["lead_gap"] + OR_VAN_TRAVEL_MIN:
        raise ValueError(
            f"OR.reveal_s: {float(p['reveal_s'])!r} must be >= lead_gap + {OR_VAN_TRAVEL_MIN:g} "
            f"= {p['lead_gap'] + OR_VAN_TRAVEL_MIN:g}"
        )
    if p["route_length"] < p["reveal_s"] + MIN_RECOVERY_M:
        raise ValueError(
            f"OR.route_length: {float(p['route_length'])!r} too short, needs >= reveal_s + "
            f"{MIN_RECOVERY_M:g} = {p['reveal_s'] + MIN_RECOVERY_M:g}"
        )


def build_or(p: dict):
    """OR: a lead van changes lane and reveals a stopped object in the ego lane.

    Two lanes in the ego direction (ego in the right one, ``fwd_1``) plus one or two opposing.
    The van (half extents 2.6 x 1.1, role occluder) starts ``lead_gap`` ahead in the ego lane at
    ``lead_speed_kmh`` and holds at the reveal point C until the event, then moves 3.5 m left
    over 2.5 s and drives on.  The object (static, role hazard) sits in the ego lane
    ``object_ahead`` m beyond C; the van is wider and on the same lane line, so it hides the
    object from the ego's camera until it moves aside.

    The conflict point is C itself, not the object: a lead vehicle between the ego and the
    object means the ego could never reach a warning point measured from the object.  The ego
    following the held van usually cannot reach ``C - 6``; the anti-deadlock rule then starts
    the event 2 s after the warning point (intended).  Clearance: the object despawns once the
    ego has stopped after the event, or at the 8-s stop limit.  Route B: no object, and the van
    neither holds nor changes lane; it stays the lead vehicle.
    """
    road_map, route = _road_and_route(p, 2, int(p["num_opposing"]), False, "fwd_1")
    y = -1.5 * road.LANE_WIDTH
    c, g0 = float(p["reveal_s"]), float(p["lead_gap"])
    v_lead = float(p["lead_speed_kmh"]) / 3.6
    van = ActorSpec(
        straight_path((g0, y), (1.0, 0.0), p["route_length"] + ROAD_MARGIN - g0),
        VAN_EXTENT,
        KIND_VEHICLE,
        ROLE_OCCLUDER,
        v_pre=v_lead,
        v_post=v_lead,
        s_hold=c - g0,
        trigger=TRIGGER_EVENT,
        lat_shift=road.LANE_WIDTH,
        lat_duration=OR_LANE_CHANGE_S,
        despawn_at_end=True,
    )
    van_b = with_changes(van, s_hold=BIG, lat_shift=0.0, trigger=TRIGGER_NEVER)
    obj_xy = np.array([c + float(p["object_ahead"]), y])
    obj = static_actor(obj_xy, 0.0, OBJECT_EXTENT, KIND_STATIC, ROLE_HAZARD)
    markers = (c - OR_WARN_LEAD, c - OR_EVENT_LEAD, c)
    sections = _opposing_sections(road_map, -ROAD_MARGIN + 10.0, p["route_length"] + 50.0)
    exclusion = [(np.array([g0, y]), OR_VAN_ZONE)]
    rules = dict(
        clear_s=BIG, clear_time_limit=OR_STOP_LIMIT_S, clear_on_ego_stop=True,
        despawn_on_clear=True, force_event=True, d_safe=D_SAFE_SMALL_M,
    )  # fmt: skip
    extra = dict(conflict_xy=[c, y], object_xy=obj_xy.tolist(), v_lead=v_lead)
    return finish_pair(
        p, OR, road_map, route, {HAZARD_SLOT: obj, SCENE_SLOT: van}, {SCENE_SLOT: van_b},
        sections, markers, rules, extra, exclusion=exclusion,
    )  # fmt: skip
