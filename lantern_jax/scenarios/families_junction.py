"""Junction families: Left-Turn Wrong-Way (LWW), Right-Turn Wrong-Way (RWW), Right-Turn Yield (RTY).

Canonical frame (rotated afterwards by ``rotation_deg``): a 3- or 4-arm junction with two lanes
per direction centred at the origin (:func:`lantern_jax.scenarios.road.junction`); the ego
approaches from the south arm heading north.  Left turns go from the inner lane into the inner
westbound lane (a 15.75-m-radius quarter circle); right turns from the outer lane into the
outer eastbound lane (8.75 m).  The route is ``approach`` m of straight approach, the connector
lane, and the exit lane until the route is ``route_length`` m long.

The conflict point C is the first route arc at which the ego box would reach the scenario
actor's path corridor: the ego centre within ``EGO_HALF_LENGTH + actor half width + 0.5 m`` of
the actor's path line (the exit lane's centre line for all three families).

Background traffic starts only on *departing* lane sections (beyond the box, moving away from
it) other than the ego's approach and exit lanes, so it can never cross the ego's turn or the
scenario actor's path; approaching cross or oncoming traffic would need junction yielding that
the background IDM does not model.  Lights: signalized junctions get two light groups (N-S and
E-W, :func:`~lantern_jax.scenarios.road.signal_lights`); the ego's light 0 is red for ``red_s``
seconds and then green for the rest of the route.
"""

from __future__ import annotations

import functools

import numpy as np

from lantern_jax.constants import (
    EGO_HALF_LENGTH,
    FAMILIES,
    KIND_VEHICLE,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    TRIGGER_CLOCK,
    TRIGGER_EVENT,
)
from lantern_jax.scenarios import road
from lantern_jax.scenarios.assemble import ActorSpec
from lantern_jax.scenarios.families_common import (
    CAR_EXTENT,
    HAZARD_SLOT,
    LaneSection,
    choose,
    common_fields,
    draw,
    finish_pair,
    static_actor,
    straight_path,
    uniform,
)
from lantern_jax.scenarios.spec import MIN_RECOVERY_M, PARAM_RANGES
from lantern_jax.scoring.thresholds import D_SAFE_LARGE_M

TURN = {"LWW": "left", "RWW": "right", "RTY": "right"}
EGO_LANES = {"left": (0, "W", 0), "right": (1, "E", 1)}  # (lane in, exit arm, lane out)
ALLOWED_MISSING = {"LWW": ("N", "E"), "RWW": ("N", "W"), "RTY": ("N",)}
LEADS = {"LWW": (10.0, 4.0), "RWW": (10.0, 4.0), "RTY": (10.0, 10.0)}  # (warn, event), m
SPAWN_OFFSET = {"LWW": 25.0, "RWW": 20.0}  # m along the wrong-way path before C's nearest point
CLEAR_TARGET = {"LWW": 15.0, "RWW": 20.0}  # m past C's nearest point
RTY_CLEAR_PAST = 5.0  # m the RTY actor's rear must be past its crossing point
SAFETY_LIMIT_S = 12.0  # s after the event (wrong-way and cross-traffic actors)
CORRIDOR_MARGIN = 0.5  # m
APPROACH_MIN = {"left": 12.0, "right": 15.0}  # m (warning point >= ~10 m into the route)
APPROACH_MIN_SIGNALIZED = 20.0  # m, room to stop for the initial red
PATH_TAIL = 10.0  # m of path beyond the clearance point
SIGNALIZED_SHARE = 1.0 / 3.0  # share of sampled junctions with traffic lights


@functools.cache
def turn_layout(turn: str) -> tuple[float, float]:
    """``(connector_length, conflict_offset)`` of the ego's turn, m.

    ``conflict_offset`` is C's distance past the junction-box entry along the route (it does
    not depend on the approach length, the arm count or the lights).
    """
    k_in, arm, k_out = EGO_LANES[turn]
    road_map = road.junction(4, 2, False)
    probe = road.turn_route(road_map, "S", k_in, arm, k_out, 20.0, 100.0)
    conn = float(road.arc_length(road_map.lane(probe.lanes[1]).center)[-1])
    return conn, _conflict_s(road_map, probe, arm, k_out) - probe.box_in_s


def _conflict_s(road_map: road.RoadMap, route: road.RouteSpec, arm: str, k_out: int) -> float:
    name, s_out = road.outbound_lane(road_map, arm, k_out)
    p_line = road.point_at(road_map.lane(name).center, s_out)
    thr = EGO_HALF_LENGTH + CAR_EXTENT[1] + CORRIDOR_MARGIN
    return road.corridor_entry(route.xy, p_line, road.ARM_DIR[arm], thr)


def _approach_min(fam: str, signalized: bool) -> float:
    return APPROACH_MIN_SIGNALIZED if signalized else APPROACH_MIN[TURN[fam]]


def sample_junction(fam: str, rng: np.random.Generator, weather: str) -> dict:
    """Sample LWW / RWW / RTY parameters (about a third signalized)."""
    p = common_fields(rng, fam, weather)
    p["num_arms"] = int(choose(rng, fam, "num_arms"))
    p["missing_arm"] = (
        str(choose(rng, fam, "missing_arm", ALLOWED_MISSING[fam]))
        if p["num_arms"] == 3
        else "none"
    )
    p["signalized"] = bool(rng.random() < SIGNALIZED_SHARE)
    p["red_s"] = draw(rng, fam, "red_s")
    p["v_ref"] = draw(rng, fam, "v_ref")
    p["actor_speed"] = draw(rng, fam, "actor_speed")
    if fam == "RTY":
        p["source_dist"] = draw(rng, fam, "source_dist")
    _, off = turn_layout(TURN[fam])
    a_min = _approach_min(fam, p["signalized"])
    p["route_length"] = draw(rng, fam, "route_length", a_min + off + MIN_RECOVERY_M + 0.5)
    a_hi = p["route_length"] - off - MIN_RECOVERY_M - 0.5
    p["approach"] = uniform(rng, a_min, min(PARAM_RANGES[fam]["approach"].hi, a_hi))
    return p


def check_junction(p: dict) -> None:
    """Cross-field feasibility of a junction-family parameter dict."""
    fam = p["family"]
    if int(p["num_arms"]) == 4 and p["missing_arm"] != "none":
        raise ValueError(f"{fam}.missing_arm: {p['missing_arm']!r} must be 'none' for 4 arms")
    if int(p["num_arms"]) == 3 and p["missing_arm"] not in ALLOWED_MISSING[fam]:
        opts = ", ".join(ALLOWED_MISSING[fam])
        raise ValueError(
            f"{fam}.missing_arm: {p['missing_arm']!r} not one of {{{opts}}} for a 3-arm {fam}"
        )
    a_min = _approach_min(fam, bool(p["signalized"]))
    if p["approach"] < a_min:
        why = "signalized" if p["signalized"] else "unsignalized"
        raise ValueError(
            f"{fam}.approach: {float(p['approach'])!r} below {a_min:g} ({why} junction)"
        )
    _, off = turn_layout(TURN[fam])
    need = float(p["approach"]) + off + MIN_RECOVERY_M
    if p["route_length"] < need:
        raise ValueError(
            f"{fam}.route_length: {float(p['route_length'])!r} too short, needs >= approach + "
            f"{off:.3f} + {MIN_RECOVERY_M:g} = {need:.3f}"
        )


def build_junction(p: dict):
    """Build an LWW / RWW / RTY pair (see :func:`build_wrong_way` and :func:`build_rty`)."""
    fam = p["family"]
    turn = TURN[fam]
    k_in, arm, k_out = EGO_LANES[turn]
    road_map = road.junction(
        int(p["num_arms"]),
        2,
        bool(p["signalized"]),
        missing_arm=p["missing_arm"],
        ego_red_s=float(p["red_s"]),
    )
    approach, length = float(p["approach"]), p["route_length"]
    route = road.turn_route(road_map, "S", k_in, arm, k_out, approach, length)
    s_c = _conflict_s(road_map, route, arm, k_out)
    name, s_out = road.outbound_lane(road_map, arm, k_out)
    exit_lane = road_map.lane(name)
    d_line = np.asarray(road.ARM_DIR[arm])
    p_line = road.point_at(exit_lane.center, s_out)
    c_xy = road.point_at(route.xy, s_c)
    near = p_line + float((c_xy - p_line) @ d_line) * d_line
    v = float(p["actor_speed"])
    if fam == "RTY":
        slots_a, slots_b, rules, spawn = _rty_actors(p, near, d_line, v)
    else:
        slots_a, slots_b, rules, spawn = _wrong_way_actors(
            fam, road_map, exit_lane, near, d_line, v
        )
    warn, event = LEADS[fam]
    markers = (s_c - warn, s_c - event, s_c)
    sections = []
    for x in road_map.arms:
        for k in range(road_map.lanes_per_direction):
            ln_name, s_dep = road.outbound_lane(road_map, x, k)
            if ln_name in route.lanes:
                continue
            lane = road_map.lane(ln_name)
            sections.append(LaneSection(lane, s_dep + 5.0, lane.length - 15.0))
    extra = dict(conflict_xy=c_xy.tolist(), near_xy=near.tolist(), spawn_xy=spawn.tolist(),
                 turn=turn, box_in_s=route.box_in_s, box_out_s=route.box_out_s)  # fmt: skip
    return finish_pair(
        p, FAMILIES.index(fam), road_map, route, slots_a, slots_b, sections, markers, rules, extra
    )


def _event_car(spawn, direction, length: float, v: float) -> ActorSpec:
    """The hazard car: waits at ``spawn``, drives ``length`` m along ``direction`` at ``v`` from
    the event on and despawns at the end of its path."""
    return ActorSpec(
        straight_path(spawn, direction, length),
        CAR_EXTENT,
        KIND_VEHICLE,
        ROLE_HAZARD,
        v_pre=0.0,
        v_post=v,
        trigger=TRIGGER_EVENT,
        despawn_at_end=True,
    )


def _wrong_way_actors(fam, road_map, exit_lane, near, d_line, v):
    """LWW / RWW actors.

    Route A: the wrong-way vehicle waits (v_pre 0) in the ego's exit lane facing the junction,
    ``SPAWN_OFFSET`` m along its path before the point nearest to C; on the event it drives
    against traffic along that lane line at ``actor_speed`` and straight on across the box (it
    does not turn into the ego's approach lane, where a yielding ego could not avoid it).  It
    clears ``CLEAR_TARGET`` m past C's nearest point and despawns.  Route B: the same vehicle at
    the same spawn point, rotated into the legal direction and driving away from the junction
    along its lane at ``actor_speed`` from t = 0 (the paper hands it to Traffic Manager); it
    despawns at the end of the arm.
    """
    dw = -d_line
    off, clear = SPAWN_OFFSET[fam], CLEAR_TARGET[fam]
    spawn = near - off * dw
    if np.max(np.abs(spawn)) < road_map.half_size + CAR_EXTENT[0]:
        raise ValueError(f"{fam}: wrong-way spawn {spawn.tolist()} inside the junction box")
    car = _event_car(spawn, dw, off + clear + PATH_TAIL, v)
    s_sp, _ = road.project(exit_lane.center, spawn)
    legal = ActorSpec(
        straight_path(spawn, d_line, exit_lane.length - s_sp),
        CAR_EXTENT,
        KIND_VEHICLE,
        ROLE_CONTEXT,
        v_pre=v,
        v_post=v,
        trigger=TRIGGER_CLOCK,
        trigger_delay=0.0,
        despawn_at_end=True,
    )
    rules = dict(
        clear_s=off + clear, clear_time_limit=SAFETY_LIMIT_S, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=True, d_safe=D_SAFE_LARGE_M,
    )  # fmt: skip
    return {HAZARD_SLOT: car}, {HAZARD_SLOT: legal}, rules, spawn


def _rty_actors(p, near, d_line, v):
    """RTY actors.

    Route A: one evaluated cross-traffic vehicle from the left, waiting ``source_dist`` m before
    its crossing point (the point of its lane nearest to C) in the lane the ego turns into; on
    the event (= the warning point; no forced trigger) it drives straight through at
    ``actor_speed``.  It clears once its rear is 5 m past the crossing point (or at the 12-s
    safety limit) and despawns.  Route B: a stationary context vehicle at the same pose.
    """
    d = float(p["source_dist"])
    spawn = near - d * d_line
    clear = d + CAR_EXTENT[0] + RTY_CLEAR_PAST
    car = _event_car(spawn, d_line, clear + PATH_TAIL, v)
    yaw = float(np.arctan2(d_line[1], d_line[0]))
    ctx = static_actor(spawn, yaw, CAR_EXTENT, KIND_VEHICLE, ROLE_CONTEXT)
    rules = dict(
        clear_s=clear, clear_time_limit=SAFETY_LIMIT_S, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=False, d_safe=D_SAFE_LARGE_M,
    )  # fmt: skip
    return {HAZARD_SLOT: car}, {HAZARD_SLOT: ctx}, rules, spawn
