"""EMV, the unseen **Emergency Vehicle Crossing** family (:mod:`lantern_jax.scenarios.unseen`
describes it and registers it): an ambulance waiting beside a truck at a junction's stop line
crosses the ego's straight path without stopping.  Public family API only.
"""

from __future__ import annotations

import math

import numpy as np

from lantern_jax.scenarios import registry as fam
from lantern_jax.scenarios.unseen_common import (
    warning_lead,
)

AMB_EXTENT = (3.0, 1.15)  # m, half length / half width of an ambulance (6 m x 2.3 m)
AMB_LANE = 0  # the ambulance passes in the inner lane of the arm on the ego's left
TRUCK_LANE = 1  # the truck waits in the outer lane, nearer the ego's approach
EGO_LANE = 1  # the ego drives the outer (right) lane straight through
AMB_CLEAR_PAST = 7.0  # m past the crossing: the ambulance's rear is clear of the ego's lane
AMB_TAIL = 5.0  # m of path beyond the clearance
AMB_EXTENSION = 60.0  # m the path runs straight on from the arm's box edge (then cut)
EMV_SAFETY_LIMIT_S = 12.0  # s after the event (as the built-in junction families)
EMV_MIN_WARN_S = 8.0  # m, shortest route arc of the warning point
EMV_RECOVERY = 30.0  # m of route after the crossing
INTERSECT_STEP = 0.05  # m, resolution of the crossing search along the route
EMV_SHAPE_TRIES = 20  # junction draws before the sampler gives up

EMV_RANGES = {
    "num_arms": fam.Choice((3, 4)),
    "missing_arm": fam.Choice(("none", "E")),  # the N arm (exit) and the W arm are needed
    "lanes_per_direction": fam.Choice((2,)),  # an inner lane to pass the waiting truck in
    "lane_width": fam.FloatRange(3.0, 3.75),  # m
    "kerb_radius": fam.FloatRange(6.5, 10.0),  # m
    "skew_E": fam.FloatRange(-15.0, 15.0),  # deg
    "skew_N": fam.FloatRange(-15.0, 15.0),  # deg
    "skew_W": fam.FloatRange(-15.0, 15.0),  # deg
    "bend_approach": fam.FloatRange(-1.0 / 30.0, 1.0 / 30.0),  # 1/m
    "bend_exit": fam.FloatRange(-1.0 / 30.0, 1.0 / 30.0),  # 1/m
    "corner_kind": fam.Choice(("building", "wall")),
    "corner_setback": fam.FloatRange(1.0, 4.0),  # m
    "corner_size": fam.FloatRange(10.0, 20.0),  # m
    "approach": fam.FloatRange(25.0, 68.0),  # m, route start to the box edge
    "v_ref": fam.FloatRange(7.0, 9.0),  # m/s
    "route_length": fam.FloatRange(60.0, 130.0),  # m (<= 96 route points)
    "amb_speed": fam.FloatRange(9.0, 12.0),  # m/s
    "truck_length": fam.FloatRange(8.0, 12.0),  # m
    "amb_back": fam.FloatRange(0.0, 4.0),  # m, the ambulance's front behind the truck's front
}


def junction_of(p: dict):
    """The EMV junction (no lights) with its corner buildings or walls and the waiting truck.

    Args:
        p: an EMV parameter dict (its junction and occluder fields).
    """
    missing = None if p["missing_arm"] == "none" else p["missing_arm"]
    shape = fam.junctions.JunctionShape(
        int(p["num_arms"]), missing, int(p["lanes_per_direction"]), float(p["lane_width"]),
        float(p["kerb_radius"]), {a: float(p[f"skew_{a}"]) for a in ("E", "N", "W")},
        {"S": float(p["bend_approach"]), "N": float(p["bend_exit"])},
    )  # fmt: skip
    road_map = fam.junctions.junction(shape)
    near = fam.OCC_WALL if p["corner_kind"] == "wall" else fam.OCC_BUILDING
    occ = []
    for c in road_map.corners:
        kind = near if "S" in (c.a, c.b) else fam.OCC_BUILDING
        occ += fam.junctions.corner_occluders(
            road_map,
            c,
            kind,
            float(p["corner_setback"]),
            float(p["corner_size"]),
            float(p["kerb_radius"]),
        )
    occ.append(fam.junctions.waiting_truck(road_map, "W", TRUCK_LANE, float(p["truck_length"])))
    road_map.occluders = occ
    return road_map


def ambulance_path(road_map, p: dict) -> tuple[np.ndarray, float]:
    """The ambulance's path (its inbound lane up to the box edge, then straight on) from its
    waiting place, and the arc of the box edge along it.

    Args:
        road_map: the junction (:func:`junction_of`).
        p: an EMV parameter dict (its ``amb_back``: where the ambulance waits).
    """
    name, box_in = fam.junctions.inbound_lane(road_map, "W", AMB_LANE)
    lane = road_map.lane(name).center
    truck_front = box_in - fam.junctions.STOP_LINE_SETBACK - fam.junctions.TRUCK_STOP_GAP
    s0 = truck_front - float(p["amb_back"]) - AMB_EXTENT[0]
    approach = fam.segment(lane, s0, box_in)
    end = approach[-1]
    heading = fam.heading_at(lane, box_in)
    ahead = end + np.array([math.cos(heading), math.sin(heading)]) * AMB_EXTENSION
    return np.concatenate([approach, ahead[None]]), box_in - s0


def crossing(route_xy: np.ndarray, path: np.ndarray) -> tuple[float, float]:
    """``(route arc, path arc)`` where the path first crosses the route (m).

    Args:
        route_xy: (n, 2) m, the ego route.
        path: (k, 2) m, the ambulance's path.

    Raises:
        ValueError: when they do not cross.
    """
    s_route = np.arange(0.0, float(fam.arc_length(route_xy)[-1]), INTERSECT_STEP)
    pts = fam.point_at(route_xy, s_route)
    for s, q in zip(s_route, pts, strict=True):
        arc, dist = fam.project(path, q)
        if dist < INTERSECT_STEP:
            return float(s), arc
    raise ValueError("EMV.skew_W: the ambulance's path does not cross the ego route")


def emv_geometry(p: dict, approach: float | None = None) -> dict:
    """The junction, the ego route (for ``approach``, default the pair's) and the crossing: the
    route arc of the conflict point past the box entry (``c_off``), the ambulance's distance to
    it (``d_amb``), the event lead at which a non-reacting ego would meet it there and the
    warning lead.

    Args:
        p: an EMV parameter dict.
        approach: m, the route's approach (default: ``p["approach"]``).
    """
    road_map = junction_of(p)
    approach = float(p["approach"] if approach is None else approach)
    length = min(float(p["route_length"]), approach + _exit_room(road_map))
    route = fam.junctions.through_route(road_map, "S", EGO_LANE, approach, length)
    path, _ = ambulance_path(road_map, p)
    s_c, d_amb = crossing(route.xy, path)
    event_lead = float(p["v_ref"]) * d_amb / float(p["amb_speed"])
    return dict(road_map=road_map, route=route, path=path, s_c=s_c, c_off=s_c - approach,
                d_amb=d_amb, event_lead=event_lead,
                warn_lead=warning_lead(event_lead, p["v_ref"]))  # fmt: skip


def _approach_min(geo: dict) -> float:
    """m, the shortest approach that puts the warning point ``EMV_MIN_WARN_S`` into the
    route."""
    return geo["warn_lead"] - geo["c_off"] + EMV_MIN_WARN_S


def _exit_room(road_map) -> float:
    """m of through lane past the S box edge (box, then the N arm)."""
    name, s_in = fam.junctions.inbound_lane(road_map, "S", EGO_LANE)
    return road_map.lane(name).length - s_in


def _approach_room(road_map) -> float:
    """m of the ego's lane before the S box edge (the longest possible approach)."""
    return fam.junctions.inbound_lane(road_map, "S", EGO_LANE)[1]


def sample_emv(rng: np.random.Generator, common: dict) -> dict:
    """EMV fields: the junction, the actors, then an approach long enough for the warning point
    and a route with 30 m after the crossing that ends on the exit arm.  The junction and actor
    block is redrawn (deterministically from ``rng``) until such an approach exists, at most
    ``EMV_SHAPE_TRIES`` times; the last draw is returned and validation reports its problem."""
    for _ in range(EMV_SHAPE_TRIES):
        p = dict(common)
        p["num_arms"] = int(fam.choose(rng, "EMV", "num_arms"))
        p["missing_arm"] = "none" if p["num_arms"] == 4 else "E"
        p["lanes_per_direction"] = 2
        for key in ("lane_width", "kerb_radius", "skew_E", "skew_N", "skew_W"):
            p[key] = fam.draw(rng, "EMV", key)
        if p["missing_arm"] == "E":
            p["skew_E"] = 0.0
        p["bend_approach"] = fam.draw(rng, "EMV", "bend_approach", nd=6)
        p["bend_exit"] = fam.draw(rng, "EMV", "bend_exit", nd=6)
        p["corner_kind"] = str(fam.choose(rng, "EMV", "corner_kind"))
        for key in ("corner_setback", "corner_size", "v_ref", "amb_speed", "truck_length",
                    "amb_back"):  # fmt: skip
            p[key] = fam.draw(rng, "EMV", key)
        p["approach"], p["route_length"] = EMV_RANGES["approach"].lo, fam.BIG  # a probe
        try:
            geo = emv_geometry(p)
        except ValueError:
            continue
        lo = max(EMV_RANGES["approach"].lo, _approach_min(geo))
        hi = min(EMV_RANGES["approach"].hi, _approach_room(geo["road_map"]))
        if lo > hi:
            continue
        p["approach"] = fam.uniform(rng, lo, hi)
        lo = p["approach"] + geo["c_off"] + EMV_RECOVERY + 0.5
        hi = p["approach"] + _exit_room(geo["road_map"]) - 1.0
        if lo > min(hi, EMV_RANGES["route_length"].hi):
            continue
        p["route_length"] = fam.draw(rng, "EMV", "route_length", lo, hi)
        break
    return {k: v for k, v in p.items() if k not in common}


def check_emv(p: dict) -> None:
    """EMV feasibility: the arm layout, the warning point inside the route, 30 m after the
    crossing, a route that ends on the exit arm."""
    if (int(p["num_arms"]) == 4) != (p["missing_arm"] == "none"):
        raise ValueError(f"EMV.missing_arm: {p['missing_arm']!r} does not fit "
                         f"{int(p['num_arms'])} arms")  # fmt: skip
    try:
        geo = emv_geometry(p, approach=float(p["approach"]))
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if msg.startswith("EMV.") else f"EMV.route_length: {msg}") from None
    if p["approach"] < _approach_min(geo):
        raise ValueError(f"EMV.approach: {float(p['approach'])!r} puts the warning point "
                         f"before the route start; needs >= {_approach_min(geo):.3f}")  # fmt: skip
    if p["route_length"] < geo["s_c"] + EMV_RECOVERY:
        raise ValueError(f"EMV.route_length: {float(p['route_length'])!r} too short, needs >= "
                         f"{geo['s_c'] + EMV_RECOVERY:.3f}")  # fmt: skip


def build_emv(p: dict) -> fam.Scene:
    """EMV: the ego drives the outer lane of the south arm straight through to the north arm.
    The truck (``truck_length``) stands in the outer inbound lane of the west arm at its stop
    line; the ambulance waits beside it in the inner lane, its front ``amb_back`` behind the
    truck's front, hidden by the truck and the corner occluders.  On the event it drives at
    ``amb_speed`` along its lane and straight across the junction; it clears (and is removed)
    once it is 7 m past the ego's lane, or 12 s after the event.  The event lead is where a
    non-reacting ego at ``v_ref`` would meet it at the crossing; the warning lead is one second
    more (:func:`warning_lead`).
    Background traffic starts on departing lanes away from the ego route and the ambulance's
    crossing."""
    geo = emv_geometry(p)
    road_map, route, s_c, d_amb = geo["road_map"], geo["route"], geo["s_c"], geo["d_amb"]
    end = d_amb + AMB_CLEAR_PAST + AMB_TAIL
    path = fam.segment(geo["path"], 0.0, end)
    amb = fam.ActorSpec(path, AMB_EXTENT, fam.KIND_VEHICLE, fam.ROLE_HAZARD, v_pre=0.0,
                        v_post=float(p["amb_speed"]), trigger=fam.TRIGGER_EVENT,
                        despawn_at_end=True)  # fmt: skip
    lead = geo["event_lead"]
    traffic = []
    for arm in road_map.arms:
        if arm == "E":  # the direction the ambulance crosses toward
            continue
        for k in range(road_map.lanes_per_direction):
            name, s_dep = fam.junctions.outbound_lane(road_map, arm, k)
            if name in route.lanes:
                continue
            lane = road_map.lane(name)
            traffic.append(fam.LaneSection(lane, s_dep + 5.0, lane.length - 15.0))
    return fam.Scene(
        road_map=road_map,
        route=route,
        hazard=amb,
        markers=(s_c - geo["warn_lead"], s_c - lead, s_c),
        clearance=fam.Clearance(path_arc=d_amb + AMB_CLEAR_PAST, time_limit=EMV_SAFETY_LIMIT_S),
        conflict_xy=fam.point_at(route.xy, s_c),
        traffic=traffic,
        details=dict(ambulance_xy=path[0].tolist(), ambulance_to_conflict_m=d_amb,
                     event_lead_m=lead, box_in_s=route.box_in_s, box_out_s=route.box_out_s),
    )  # fmt: skip


EMERGENCY = fam.FamilyRecord(
    code="EMV",
    name="Emergency Vehicle Crossing",
    ranges=EMV_RANGES,
    sample=sample_emv,
    build=build_emv,
    check=check_emv,
    # this package's texts (the paper gives none for this event), in the cyclist's style
    warning="An emergency vehicle hidden behind the waiting truck at <FRONT_CAR_POS> is about to "
    "cross the ego path at the intersection.",
    paraphrases={
        "low": (
            "Watch for an ambulance coming out from behind the large vehicle near "
            "<FRONT_CAR_POS>; it will drive across your route.",
        )
    },
    premise=fam.PREMISE_WHOLE_APPROACH,
    knobs={"hazard_speed": (9.0, 12.0), "hazard_delay": (0.0, 1.5)},
    d_safe=fam.D_SAFE_LARGE_M,
    description="an ambulance hidden beside a waiting truck crosses the junction ahead",
)
