"""Junction families: Left-Turn Wrong-Way (LWW), Right-Turn Wrong-Way (RWW), Right-Turn Yield (RTY).

Every pair builds its own junction (:mod:`lantern_jax.scenarios.road_junction`): 3 or 4 arms,
one or two lanes per direction of ``lane_width``, kerb fillets of ``kerb_radius`` (which set the
junction's size), the E, N and W arms skewed by up to 15 degrees, the approach and exit arms
bending gently (``bend_approach``, ``bend_exit``, up to 1/70 m from 10 m beyond the box edge),
and occluders at every
rounded corner — a building or a wall (``corner_kind``) at the two corners beside the ego's
approach, buildings at the far ones — ``corner_setback`` inside the kerb arc and
``corner_size`` long; rotated afterwards by ``rotation_deg``.  The ego approaches from the
south arm heading north; left turns go from the inner lane into the inner lane of the W arm,
right turns from the outer lane into the outer lane of the E arm.  The route is ``approach`` m
of straight approach, the connector lane, and the exit lane until the route is
``route_length`` m long.

Conflict points: for the wrong-way families C lies ``conflict_offset`` m past the junction-box
entry along the route (inside the turn); for Right-Turn Yield it is the first route arc at
which the ego box would reach the cross-traffic lane's corridor (the ego centre within
``EGO_HALF_LENGTH + car half width + 0.5 m`` of the lane's centre line).

Background traffic starts only on *departing* lane sections (beyond the box, moving away from
it) other than the ego's approach and exit lanes, so it can never cross the ego's turn or the
scenario actors' paths.  Lights: signalized junctions get two light groups (N-S and E-W,
:func:`~lantern_jax.scenarios.road_junction.signal_lights`); the ego's light 0 is red for
``red_s`` seconds and then green for the rest of the route.
"""

from __future__ import annotations

import numpy as np

from lantern_jax.core.constants import (
    EGO_HALF_LENGTH,
    FAMILIES,
    KIND_VEHICLE,
    MOTION_IDM,
    OCC_BUILDING,
    OCC_WALL,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    TRIGGER_EVENT,
)
from lantern_jax.scenarios import road
from lantern_jax.scenarios import road_junction as rj
from lantern_jax.scenarios.assemble import ActorSpec
from lantern_jax.scenarios.families_common import (
    CAR_EXTENT,
    FLOW_SLOTS,
    HAZARD_SLOT,
    LaneSection,
    check_occluders,
    choose,
    common_fields,
    draw,
    finish_pair,
    fit_path,
    static_actor,
    uniform,
    with_changes,
)
from lantern_jax.scenarios.spec import MIN_RECOVERY_M, PARAM_RANGES

TURN = {"LWW": "left", "RWW": "right", "RTY": "right"}
EXIT_ARM = {"left": "W", "right": "E"}
ALLOWED_MISSING = {"LWW": ("N", "E"), "RWW": ("N", "W"), "RTY": ("N",)}
LEADS = {"LWW": (10.0, 4.0), "RWW": (10.0, 4.0), "RTY": (10.0, 10.0)}  # (warn, event), m
SPAWN_OFFSET = {"LWW": 25.0, "RWW": 20.0}  # m along the reversed route before C
CLEAR_TARGET = {"LWW": 15.0, "RWW": 20.0}  # m past C where the wrong-way path ends
RTY_CLEAR_PAST = 5.0  # m the RTY actor's rear must be past its crossing point
SAFETY_LIMIT_S = 12.0  # s after the event (wrong-way and cross-traffic actors)
APPROACH_MIN = {"left": 12.0, "right": 15.0}  # m (warning point >= ~10 m into the route)
APPROACH_MIN_SIGNALIZED = 20.0  # m, room to stop for the initial red
PATH_TAIL = 10.0  # m of path beyond the clearance point
SIGNALIZED_SHARE = 1.0 / 3.0  # share of sampled junctions with traffic lights
MIN_TURN_RADIUS = 8.0  # m, tightest connector the ego can follow (min radius ~7.4 m)
SHAPE_TRIES = 20  # skew draws before falling back to an unskewed junction
SKEW_ARMS = ("E", "N", "W")
RTY_SPAWN_MARGIN = 1.0  # m between a waiting flow vehicle and the junction box
RTY_CONFLICT_STEP = 0.05  # m, arc resolution of the search for the RTY conflict point
RTY_CONTEXT_HANDOVER_S = 0.1  # s after the event: the context flow continues as IDM traffic


def ego_lanes(turn: str, lanes: int) -> tuple[int, str, int]:
    """``(lane in, exit arm, lane out)`` of the ego's turn."""
    k = 0 if turn == "left" else lanes - 1
    return k, EXIT_ARM[turn], k


def junction_shape(p: dict) -> rj.JunctionShape:
    """The junction of a pair (arms, lanes, kerb radius, skews)."""
    missing = None if p["missing_arm"] == "none" else p["missing_arm"]
    exit_arm = EXIT_ARM[TURN[p["family"]]]
    return rj.JunctionShape(
        int(p["num_arms"]), missing, int(p["lanes_per_direction"]), float(p["lane_width"]),
        float(p["kerb_radius"]), {a: float(p[f"skew_{a}"]) for a in SKEW_ARMS},
        {"S": float(p["bend_approach"]), exit_arm: float(p["bend_exit"])},
    )  # fmt: skip


def _turn_probe(fam: str, p: dict) -> tuple[rj.RoadMap, road.RouteSpec]:
    """The pair's junction with a long probe route (for geometry before the route is sampled)."""
    road_map = rj.junction(junction_shape(p), bool(p["signalized"]), float(p["red_s"]))
    k_in, arm, k_out = ego_lanes(TURN[fam], int(p["lanes_per_direction"]))
    approach = _approach_min(fam, bool(p["signalized"]))
    c_len = float(road.arc_length(road_map.lane(rj.add_connector(
        road_map, "S", k_in, arm, k_out)).center)[-1])  # fmt: skip
    route = rj.turn_route(road_map, "S", k_in, arm, k_out, approach, approach + c_len + 40.0)
    return road_map, route


def turn_geometry(fam: str, p: dict) -> dict:
    """Geometry the sampler and the feasibility rules need, from the junction fields of ``p``:
    connector length and smallest radius, conflict offset past the box entry (m), and for RTY
    the flow lane's arc of the crossing point and of the box entry."""
    road_map, route = _turn_probe(fam, p)
    conn = road_map.lane(route.lanes[1]).center
    out = dict(c_len=float(road.arc_length(conn)[-1]), radius=rj.min_turn_radius(conn))
    if fam == "RTY":
        s_c, s_x, lane = _rty_conflict(road_map, route)
        out.update(c_off=s_c - route.box_in_s, cross_s=s_x, lane_box_in=lane.box_in_s)
    else:
        out["c_off"] = float(p["conflict_offset"])
    return out


def _approach_min(fam: str, signalized: bool) -> float:
    return APPROACH_MIN_SIGNALIZED if signalized else APPROACH_MIN[TURN[fam]]


def _rty_conflict(road_map: rj.RoadMap, route: road.RouteSpec):
    """RTY conflict arc, the flow lane's arc of the crossing point, and the flow lane."""
    _, arm, k_out = ego_lanes("right", road_map.lanes_per_direction)
    lane = road_map.lane(rj.outbound_lane(road_map, arm, k_out)[0])
    thr = EGO_HALF_LENGTH + CAR_EXTENT[1] + road.CORRIDOR_MARGIN
    s_route = np.arange(0.0, route.length, RTY_CONFLICT_STEP)
    first = road.first_within(road.point_at(route.xy, s_route), lane.center, thr,
                              RTY_CONFLICT_STEP)  # fmt: skip
    if first < 0:
        raise ValueError("RTY.approach: the route never reaches the cross lane's corridor")
    s_c = float(s_route[first])
    s_x, _ = road.project(lane.center, road.point_at(route.xy, s_c))
    return s_c, s_x, lane


# ------------------------------------------------------------------------------------------------
# sampling and feasibility
# ------------------------------------------------------------------------------------------------
def _sample_shape(fam: str, rng: np.random.Generator, p: dict) -> None:
    """Draw lanes, widths, kerb radius and admissible skews into ``p``."""
    p["lanes_per_direction"] = int(choose(rng, fam, "lanes_per_direction"))
    p["lane_width"] = draw(rng, fam, "lane_width")
    p["kerb_radius"] = draw(rng, fam, "kerb_radius")
    p["bend_approach"] = draw(rng, fam, "bend_approach", nd=6)
    p["bend_exit"] = draw(rng, fam, "bend_exit", nd=6)
    for _ in range(SHAPE_TRIES):
        for a in SKEW_ARMS:
            p[f"skew_{a}"] = 0.0 if a == p["missing_arm"] else draw(rng, fam, f"skew_{a}")
        try:
            if turn_geometry(fam, p)["radius"] >= MIN_TURN_RADIUS:
                return
        except ValueError:
            continue
    for a in SKEW_ARMS:
        p[f"skew_{a}"] = 0.0


def sample_junction(fam: str, rng: np.random.Generator, weather: str) -> dict:
    """Sample LWW / RWW / RTY parameters (about a third signalized).

    The geometry block (lanes, kerb, skews, bends, occluders, approach, route length, flow) is
    redrawn, deterministically from ``rng``, until the pair passes :func:`check_junction` (an
    arm bending into a corner building, say); after ``SHAPE_TRIES`` draws the last one is
    returned and validation reports its problem.
    """
    p = common_fields(rng, fam, weather)
    p["num_arms"] = int(choose(rng, fam, "num_arms"))
    p["missing_arm"] = (
        str(choose(rng, fam, "missing_arm", ALLOWED_MISSING[fam])) if p["num_arms"] == 3 else "none"
    )
    p["signalized"] = bool(rng.random() < SIGNALIZED_SHARE)
    p["red_s"] = draw(rng, fam, "red_s")
    p["v_ref"] = draw(rng, fam, "v_ref")
    p["actor_speed"] = draw(rng, fam, "actor_speed")
    for _ in range(SHAPE_TRIES):
        _sample_geometry(fam, rng, p)
        try:
            check_junction(p)
            return p
        except ValueError:
            continue
    return p


def _sample_geometry(fam: str, rng: np.random.Generator, p: dict) -> None:
    """Draw the junction geometry, occluders, route and (RTY) flow fields into ``p``."""
    p["corner_kind"] = str(choose(rng, fam, "corner_kind"))
    p["corner_setback"] = draw(rng, fam, "corner_setback")
    p["corner_size"] = draw(rng, fam, "corner_size")
    if fam in SPAWN_OFFSET:
        p["conflict_offset"] = draw(rng, fam, "conflict_offset")
    if fam == "LWW":
        p["truck_length"] = draw(rng, fam, "truck_length")
    _sample_shape(fam, rng, p)
    geo = turn_geometry(fam, p)
    a_min = _approach_min(fam, p["signalized"])
    hi = PARAM_RANGES[fam]["route_length"].hi
    p["approach"] = uniform(rng, a_min, min(PARAM_RANGES[fam]["approach"].hi,
                                            hi - geo["c_off"] - MIN_RECOVERY_M - 0.5))  # fmt: skip
    need = max(p["approach"] + geo["c_off"] + MIN_RECOVERY_M, p["approach"] + geo["c_len"] + 1.0)
    p["route_length"] = draw(rng, fam, "route_length", need + 0.5)
    if fam == "RTY":
        _sample_flow(rng, p, geo)


def _sample_flow(rng: np.random.Generator, p: dict, geo: dict) -> None:
    """Draw the RTY flow: first vehicle's distance, spacing and size, all waiting outside the
    box and on the cross lane."""
    lo = geo["cross_s"] - geo["lane_box_in"] + CAR_EXTENT[0] + RTY_SPAWN_MARGIN
    gap_lo = PARAM_RANGES["RTY"]["source_interval"].lo
    p["source_dist"] = draw(rng, "RTY", "source_dist", lo, geo["cross_s"] - CAR_EXTENT[0] - gap_lo)
    room = geo["cross_s"] - p["source_dist"] - CAR_EXTENT[0]
    p["source_interval"] = draw(rng, "RTY", "source_interval", at_most=room)
    fits = 1 + int(room // p["source_interval"])
    p["flow_size"] = int(choose(rng, "RTY", "flow_size", tuple(n for n in (2, 3, 4) if n <= fits)))


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
    try:
        geo = turn_geometry(fam, p)
    except ValueError as e:
        msg = str(e)
        if msg.startswith(("skew_", "RTY.")):
            raise ValueError(msg if msg.startswith("RTY.") else f"{fam}.{msg}") from None
        raise ValueError(f"{fam}.kerb_radius: {msg}") from None
    if geo["radius"] < MIN_TURN_RADIUS:
        raise ValueError(f"{fam}.kerb_radius: the ego's turn has a {geo['radius']:.2f}-m radius, "
                         f"needs >= {MIN_TURN_RADIUS:g} (kerb radius or skews)")  # fmt: skip
    a_min = _approach_min(fam, bool(p["signalized"]))
    if p["approach"] < a_min:
        why = "signalized" if p["signalized"] else "unsignalized"
        raise ValueError(
            f"{fam}.approach: {float(p['approach'])!r} below {a_min:g} ({why} junction)"
        )
    need = float(p["approach"]) + max(geo["c_off"] + MIN_RECOVERY_M, geo["c_len"] + 1.0)
    if p["route_length"] < need:
        raise ValueError(
            f"{fam}.route_length: {float(p['route_length'])!r} too short, needs >= approach + "
            f"conflict offset {geo['c_off']:.3f} + {MIN_RECOVERY_M:g} = {need:.3f}"
        )
    if fam == "RTY":
        _check_flow(p, geo)
    check_occluders(fam, p, build_junction_scene(p))


def _check_flow(p: dict, geo: dict) -> None:
    lo = geo["cross_s"] - geo["lane_box_in"] + CAR_EXTENT[0] + RTY_SPAWN_MARGIN
    if p["source_dist"] < lo:
        raise ValueError(f"RTY.source_dist: {float(p['source_dist'])!r} puts the first flow "
                         f"vehicle inside the junction; needs >= {lo:.3f}")  # fmt: skip
    last = geo["cross_s"] - p["source_dist"] - (int(p["flow_size"]) - 1) * p["source_interval"]
    if last < CAR_EXTENT[0]:
        raise ValueError(f"RTY.flow_size: {int(p['flow_size'])} vehicles spaced "
                         f"{float(p['source_interval'])!r} m do not fit on the cross "
                         "arm")  # fmt: skip


# ------------------------------------------------------------------------------------------------
# building
# ------------------------------------------------------------------------------------------------
def build_junction_scene(p: dict):
    """The junction, the ego route, the occluders and the conflict arc of a pair:
    ``(road_map, route, s_conflict)``."""
    fam = p["family"]
    road_map = rj.junction(junction_shape(p), bool(p["signalized"]), float(p["red_s"]))
    k_in, arm, k_out = ego_lanes(TURN[fam], int(p["lanes_per_direction"]))
    route = rj.turn_route(road_map, "S", k_in, arm, k_out, float(p["approach"]),
                          float(p["route_length"]))  # fmt: skip
    near_kind = OCC_WALL if p["corner_kind"] == "wall" else OCC_BUILDING
    occ = []
    for c in road_map.corners:
        kind = near_kind if "S" in (c.a, c.b) else OCC_BUILDING
        occ += rj.corner_occluders(road_map, c, kind, float(p["corner_setback"]),
                                   float(p["corner_size"]), float(p["kerb_radius"]))  # fmt: skip
    if fam == "LWW":
        occ.append(rj.waiting_truck(road_map, "W", 0, float(p["truck_length"])))
    road_map.occluders = occ
    if fam == "RTY":
        s_c = _rty_conflict(road_map, route)[0]
    else:
        s_c = route.box_in_s + float(p["conflict_offset"])
    return road_map, route, s_c


def build_junction(p: dict):
    """Build an LWW / RWW / RTY pair (see :func:`_wrong_way_actors` and :func:`_rty_actors`)."""
    fam = p["family"]
    road_map, route, s_c = build_junction_scene(p)
    v = float(p["actor_speed"])
    if fam == "RTY":
        slots_a, slots_b, rules, spawn = _rty_actors(p, road_map, route, s_c, v)
    else:
        slots_a, slots_b, rules, spawn = _wrong_way_actors(fam, road_map, route, s_c, v)
    warn, event = LEADS[fam]
    markers = (s_c - warn, s_c - event, s_c)
    sections = []
    for x in road_map.arms:
        for k in range(road_map.lanes_per_direction):
            ln_name, s_dep = rj.outbound_lane(road_map, x, k)
            if ln_name in route.lanes:
                continue
            lane = road_map.lane(ln_name)
            sections.append(LaneSection(lane, s_dep + 5.0, lane.length - 15.0))
    extra = dict(conflict_xy=road.point_at(route.xy, s_c).tolist(), spawn_xy=spawn.tolist(),
                 turn=TURN[fam], box_in_s=route.box_in_s, box_out_s=route.box_out_s,
                 premise_times=[0.0])  # fmt: skip
    return finish_pair(
        p, FAMILIES.index(fam), road_map, route, slots_a, slots_b, sections, markers, rules, extra
    )


def wrong_way_path(route_xy: np.ndarray, s_c: float, fam: str) -> np.ndarray:
    """The wrong-way vehicle's path: the ego route reversed, from ``SPAWN_OFFSET`` m past the
    conflict arc ``s_c`` back to ``CLEAR_TARGET`` m before it (clipped to the route start)."""
    return road.segment(route_xy, s_c - CLEAR_TARGET[fam], s_c + SPAWN_OFFSET[fam])[::-1]


def _wrong_way_actors(fam, road_map, route, s_c, v):
    """LWW / RWW actors.

    Route A: the wrong-way vehicle waits (v_pre 0) on the ego route, ``SPAWN_OFFSET`` m (25 m
    LWW, 20 m RWW) beyond the conflict point — in the ego's exit lane or turn, facing against
    the ego's direction — hidden from the approaching ego by the corner occluders (and, LWW, by
    the truck waiting on the W arm).  On the event it follows the **reversed ego route** at
    ``actor_speed`` (7-9 m/s), head-on through the turn.  It is removed once it has passed the
    conflict point (it has then travelled the spawn offset, more than the paper's 5 m); its path
    continues to the paper's clearance target (15 m LWW, 20 m RWW past C), but a wrong-way car
    that kept driving down the ego's own lane would hit every ego that yielded before the turn,
    so the removal at C is the clearance (with the 12-s safety limit).  Route B: the same
    vehicle at the same place turned into the legal direction, handed to the IDM from t = 0: it
    drives away from the junction along the rest of the route and the exit lane.
    """
    off = SPAWN_OFFSET[fam]
    path = wrong_way_path(route.xy, s_c, fam)
    spawn = path[0]
    car = ActorSpec(path, CAR_EXTENT, KIND_VEHICLE, ROLE_HAZARD, v_pre=0.0, v_post=v,
                    trigger=TRIGGER_EVENT, despawn_at_end=True)  # fmt: skip
    exit_lane = road_map.lane(route.lanes[-1]).center
    end_s, _ = road.project(exit_lane, route.xy[-1])
    rest = road.segment(route.xy, s_c + off, route.length)
    beyond = road.segment(exit_lane, end_s, float(road.arc_length(exit_lane)[-1]))
    # the rest of the route exactly (so the car starts exactly reversed), then the exit lane
    legal_path = np.concatenate([rest, beyond[1:]])[: road.PATH_POINTS]
    legal = ActorSpec(legal_path, CAR_EXTENT, KIND_VEHICLE, ROLE_CONTEXT, motion=MOTION_IDM,
                      v_pre=v, v_post=v, despawn_at_end=True)  # fmt: skip
    rules = dict(
        clear_s=off, clear_time_limit=SAFETY_LIMIT_S, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=True,
    )  # fmt: skip
    return {HAZARD_SLOT: car}, {HAZARD_SLOT: legal}, rules, spawn


def _rty_actors(p, road_map, route, s_c, v):
    """RTY actors: a finite cross-traffic flow from the left.

    Route A: ``flow_size`` vehicles wait in the cross lane that the ego turns into (the W->E
    lane), the first ``source_dist`` m before its crossing point (the lane point nearest to C),
    the others ``source_interval`` m apart behind it.  On the event (= the warning point; no
    forced trigger) they all drive through at ``actor_speed``.  The first vehicle is the
    evaluated passage (the hazard, scripted): it clears once its rear is 5 m past the crossing
    point (or at the 12-s safety limit), which ends the flow, and despawns; the others (role
    context) are handed to the IDM right after they start (``handover_after`` 0.1 s, at flow
    speed): ordinary traffic that keeps its spacing behind the first vehicle but brakes for
    whatever is ahead of it — an ego that merged into a gap included — and despawns at the far
    end of the lane.  Route B: one stationary context vehicle at the first vehicle's place.
    """
    _, s_x, lane = _rty_conflict(road_map, route)
    d, gap = float(p["source_dist"]), float(p["source_interval"])
    clear = d + CAR_EXTENT[0] + RTY_CLEAR_PAST
    slots_a = {}
    spawn = None
    for i in range(int(p["flow_size"])):
        s0 = s_x - d - i * gap
        end = s0 + (clear + PATH_TAIL if i == 0 else lane.length - s0)
        path = fit_path(road.segment(lane.center, s0, end))
        role = ROLE_HAZARD if i == 0 else ROLE_CONTEXT
        spec = ActorSpec(path, CAR_EXTENT, KIND_VEHICLE, role, v_pre=0.0, v_post=v,
                         trigger=TRIGGER_EVENT, despawn_at_end=True)  # fmt: skip
        if i > 0:
            spec = with_changes(spec, handover_after=RTY_CONTEXT_HANDOVER_S)
        slots_a[HAZARD_SLOT if i == 0 else FLOW_SLOTS[i - 1]] = spec
        if i == 0:
            spawn = path[0]
            yaw = road.heading_at(path, 0.0)
    ctx = static_actor(spawn, yaw, CAR_EXTENT, KIND_VEHICLE, ROLE_CONTEXT)
    rules = dict(
        clear_s=clear, clear_time_limit=SAFETY_LIMIT_S, clear_on_ego_stop=False,
        despawn_on_clear=True, force_event=False,
    )  # fmt: skip
    return slots_a, {HAZARD_SLOT: ctx}, rules, spawn
