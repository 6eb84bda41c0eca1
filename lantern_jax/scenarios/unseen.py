"""The paper's three unseen hazards (appendix "Protocol Extension to Unseen Hazards") as
scenario families, written with the public family API only (:mod:`lantern_jax.scenarios.registry`;
the worked example of ``docs/families.md``).

Importing this module registers them:

* ``CYC`` — **Occluded Cyclist Crossing**: a cyclist waits beyond the kerb beside the front of a
  bus parked in the parking lane on the ego's right and, on the event, rides out in front of
  the bus and across the road at 4.5 m/s (the paper's speed) to beyond the far lane, where it
  leaves the scene.
* ``EMV`` — **Emergency Vehicle Crossing**: the ego drives straight through an unsignalized
  junction; an ambulance waits on the arm to its left, in the inner lane beside a truck that
  stands at the stop line of the outer lane (the large vehicle that hides it), and on the event
  drives across the junction at 9-12 m/s without stopping; it is removed once it has crossed
  the ego's path.
* ``REV`` — **Reversing Vehicle**: a car parked nose-in in a perpendicular bay beside the ego
  lane, behind a van parked in the bay before it, reverses out on the event: straight back until
  its rear is 1 m into the road, then along a 5-m arc that swings its rear upstream, and stops
  across the ego lane; it drives off (is removed) once the ego has stood still for 1 s after
  seeing it, or 8 s after the event (the Obstacle Reveal rule).

Shared choices (this package's, the paper gives one route per event and no parameters):

* the event lead is where a non-reacting ego at ``v_ref`` and the hazard would meet (CYC and
  EMV: ``v_ref`` times the hazard's time to the crossing, per pair; REV: 10 m, so that such an
  ego's front reaches the car's bay about a second after the event, when the car's rear has
  backed into its corridor); the warning point lies one second at ``v_ref`` before the event
  point (:func:`warning_lead`), as in the six families (Pedestrian Emergence: 9 m at 8-10 m/s),
  so a non-reacting ego reaches the event point inside the protocol's 2-s anti-deadlock window
  and the hazard starts where the scene was laid out for it;
* every hazard waits (speed 0) until the event and nothing that could hide it moves before it,
  so the premise rule is the strict one: hidden from the front camera at the warning point and
  from every route point before it;
* Route B is the same scene without the hazard behaviour (CYC, EMV: no hazard actor; REV: the
  car stays parked);
* **the cyclist is a vehicle-kind actor with a bicycle's extent** (1.8 m x 0.6 m): CARLA spawns
  cyclists as vehicle blueprints, and a new actor kind would widen the kind one-hot that the
  shipped learned models read (their object tokens are ``10 + NUM_ACTOR_KINDS`` = 13 features
  wide, the input width of their checkpoints' first object layer) and renumber the range
  image's occluder classes.  The
  reversing car and the ambulance are vehicles; the bus, the truck and the van are parked
  vehicles of the map (occluders).

Warning texts: the cyclist's are the paper's free-form warning and held-out paraphrase,
verbatim (the warning says "van" although the paper's scene, and this one, has a bus).  The
paper gives no text for the other two events; their exact warnings and paraphrases are this
package's, written in the same style: one sentence naming the actor, its position and what it
is about to do; a paraphrase naming it differently and saying "your path" / "your route".
None of the texts is one of the six canonical templates the reference policies' keyword rule
was written from.
"""

from __future__ import annotations

import math

import numpy as np

from lantern_jax.scenarios import registry as fam

# ================================================================================================
# shared helpers
# ================================================================================================
WARN_GAP_S = 1.0  # s at v_ref from the warning point to the event point
ROAD_MARGIN = 60.0  # m of road before the route start and after the route end
MAX_CURVATURE = 1.0 / 70.0  # 1/m, gentle curves (as the built-in straight-road families)

#: Straight-road geometry shared by CYC and REV.
STRAIGHT_RANGES = {
    "lane_width": fam.FloatRange(3.0, 3.75),  # m
    "lanes_fwd": fam.Choice((1, 2)),  # the ego drives the rightmost one
    "lanes_back": fam.Choice((1, 2)),  # opposing lanes
    "curvature_1": fam.FloatRange(-MAX_CURVATURE, MAX_CURVATURE),  # 1/m before curve_split
    "curvature_2": fam.FloatRange(-MAX_CURVATURE, MAX_CURVATURE),  # 1/m from curve_split on
    "curve_split": fam.FloatRange(20.0, 80.0),  # m, route arc where the curvature changes
}


def warning_lead(event_lead: float, v_ref: float) -> float:
    """m, the warning lead: the event lead plus one second at ``v_ref`` (:data:`WARN_GAP_S`)."""
    return float(event_lead) + WARN_GAP_S * float(v_ref)


def sample_straight(rng: np.random.Generator, code: str) -> dict:
    """The straight-road fields of a CYC or REV pair (drawn first, in this order)."""
    return dict(
        lane_width=fam.draw(rng, code, "lane_width"),
        lanes_fwd=int(fam.choose(rng, code, "lanes_fwd")),
        lanes_back=int(fam.choose(rng, code, "lanes_back")),
        curvature_1=fam.draw(rng, code, "curvature_1", nd=6),
        curvature_2=fam.draw(rng, code, "curvature_2", nd=6),
        curve_split=fam.draw(rng, code, "curve_split"),
    )


def straight_scene(p: dict, parking_width: float = 0.0):
    """The road, ego route, centre line and layout of a straight-road pair: ``lanes_fwd``
    forward lanes (the ego in the rightmost), ``lanes_back`` opposing, an optional parking lane.

    Args:
        p: a CYC or REV parameter dict.
        parking_width: m, the parking lane right of the forward lanes (0: none).

    Returns:
        ``(road_map, route, line, layout)``.
    """
    n = int(p["lanes_fwd"])
    layout = fam.StraightLayout(n, int(p["lanes_back"]), float(p["lane_width"]), n - 1,
                                parking_width)  # fmt: skip
    line = fam.Centerline.two_piece(p["curvature_1"], p["curvature_2"], p["curve_split"])
    length = float(p["route_length"])
    road_map = fam.straight_road(layout, line, -ROAD_MARGIN, length + ROAD_MARGIN)
    route = fam.ego_route(line, length, f"fwd_{layout.ego_lane}")
    return road_map, route, line, layout


def road_path(line, s, d) -> np.ndarray:
    """(n, 2) canonical-frame points of road coordinates.

    Args:
        line: the ego lane's centre line.
        s: (n,) m, arcs along it.
        d: (n,) m, lateral offsets, + = left.
    """
    return line.to_xy(np.asarray(s, np.float64), np.asarray(d, np.float64))


# ================================================================================================
# CYC: occluded cyclist crossing from behind a parked bus
# ================================================================================================
CYCLIST_SPEED = 4.5  # m/s, the paper's
BIKE_EXTENT = (0.9, 0.3)  # m, half length / half width of a bicycle with its rider
BIKE_TURN_RADIUS = 3.0  # m, of the cyclist's turn onto the crossing
BIKE_CLEAR_FRONT = 0.5  # m the cyclist's rear passes the bus front before it turns
CYC_FAR_MARGIN = 2.0  # m the crossing runs beyond the road's far edge
KERB_GAP = 0.1  # m between a parked vehicle and the kerb
CURVE_SAG = 0.3  # m, room for a straight 12.5-m box on a curve of radius 70 m (12.5^2 / 560)
CYC_RECOVERY = 30.0  # m of route after the crossing (as Pedestrian Emergence)
CYC_MIN_WARN_S = 5.0  # m, shortest route arc of the warning point
CYC_ARC_POINTS = 8

CYC_RANGES = {
    **STRAIGHT_RANGES,
    "v_ref": fam.FloatRange(8.0, 10.0),  # m/s
    "route_length": fam.FloatRange(75.0, 140.0),  # m
    "conflict_s": fam.FloatRange(40.0, 65.0),  # m, route arc of the cyclist's crossing line
    "parking_width": fam.FloatRange(2.7, 3.4),  # m, parking lane (bus bay) right of the ego
    "bus_length": fam.FloatRange(10.0, 12.5),  # m
    "bus_width": fam.FloatRange(2.45, 2.55),  # m
    "bike_gap": fam.FloatRange(0.2, 0.8),  # m, the cyclist's front behind the bus front
    "bike_offset": fam.FloatRange(0.2, 0.8),  # m, the cyclist's road-side edge beyond the kerb
}


def _bus_room(p: dict) -> float:
    """m, how much wider the parking lane must be than the bus so that the bus keeps the ego's
    corridor (half width + margin) clear: lane_width / 2 + parking_width - kerb gap - bus_width
    >= EGO_HALF_WIDTH + CORRIDOR_MARGIN + CURVE_SAG."""
    need = fam.EGO_HALF_WIDTH + fam.CORRIDOR_MARGIN + CURVE_SAG + KERB_GAP
    return need - 0.5 * float(p["lane_width"])


def cyclist_path(p: dict, kerb: float, far: float) -> dict:
    """The cyclist's ride in road coordinates: it waits beyond the kerb beside the bus front,
    heading along the road; on the event it rides on until its rear is 0.5 m past the bus
    front, turns left onto the crossing line (radius 3 m) and rides straight across to 2 m
    beyond the road's far edge.

    Args:
        p: a CYC parameter dict.
        kerb: m, the right kerb's offset from the ego lane's centre (negative).
        far: m, the road's far (left) edge's offset.

    Returns:
        ``s``, ``d`` (n,) m, the path; ``length`` m; ``to_ego_lane`` m, the path arc at which
        its centre reaches the ego lane's centre line (``d = 0``); ``s0`` m, where it waits.
    """
    sc, r = float(p["conflict_s"]), BIKE_TURN_RADIUS
    d0 = kerb - float(p["bike_offset"]) - BIKE_EXTENT[1]
    run = float(p["bike_gap"]) + 2.0 * BIKE_EXTENT[0] + BIKE_CLEAR_FRONT
    s0 = sc - r - run
    a = np.linspace(0.0, 0.5 * math.pi, CYC_ARC_POINTS)
    s = np.concatenate([[s0], s0 + run + r * np.sin(a), [sc]])
    d = np.concatenate([[d0], d0 + r * (1.0 - np.cos(a)), [far + CYC_FAR_MARGIN]])
    straight = far + CYC_FAR_MARGIN - (d0 + r)
    to_lane = run + 0.5 * math.pi * r - (d0 + r)
    return dict(s=s, d=d, s0=s0, length=run + 0.5 * math.pi * r + straight, to_ego_lane=to_lane)


def _cyc_layout(p: dict) -> tuple[float, float]:
    """``(kerb, far)``: m, the right kerb's and the road's far edge's offsets from the ego lane
    (the ego in the rightmost forward lane, the parking lane beyond it)."""
    w = float(p["lane_width"])
    kerb = -0.5 * w - float(p["parking_width"])
    far = (int(p["lanes_back"]) + 0.5) * w + (int(p["lanes_fwd"]) - 1) * w
    return kerb, far


def cyc_event_lead(p: dict) -> float:
    """m, the event lead: where a non-reacting ego at ``v_ref`` meets the cyclist on the ego
    lane's centre line."""
    kerb, far = _cyc_layout(p)
    return float(p["v_ref"]) * cyclist_path(p, kerb, far)["to_ego_lane"] / CYCLIST_SPEED


def sample_cyc(rng: np.random.Generator, common: dict) -> dict:
    """CYC fields: the road, the bus and the cyclist's place, then a crossing far enough along
    the route for the warning point and a route with 30 m after it."""
    p = {**common, **sample_straight(rng, "CYC")}
    p["v_ref"] = fam.draw(rng, "CYC", "v_ref")
    p["bus_length"] = fam.draw(rng, "CYC", "bus_length")
    p["bus_width"] = fam.draw(rng, "CYC", "bus_width")
    p["parking_width"] = fam.draw(rng, "CYC", "parking_width", p["bus_width"] + _bus_room(p))
    p["bike_gap"] = fam.draw(rng, "CYC", "bike_gap")
    p["bike_offset"] = fam.draw(rng, "CYC", "bike_offset")
    p["conflict_s"] = CYC_RANGES["conflict_s"].lo
    warn = warning_lead(cyc_event_lead(p), p["v_ref"])
    p["conflict_s"] = fam.draw(rng, "CYC", "conflict_s", warn + CYC_MIN_WARN_S)
    p["route_length"] = fam.draw(rng, "CYC", "route_length", p["conflict_s"] + CYC_RECOVERY + 0.5)
    return {k: v for k, v in p.items() if k not in common}


def check_cyc(p: dict) -> None:
    """CYC feasibility: the warning point inside the route, 30 m of route after the crossing, a
    parking lane wide enough for the bus."""
    if p["conflict_s"] < warning_lead(cyc_event_lead(p), p["v_ref"]) + CYC_MIN_WARN_S:
        raise ValueError(f"CYC.conflict_s: {float(p['conflict_s'])!r} puts the warning point "
                         f"before the route start")  # fmt: skip
    need = p["conflict_s"] + CYC_RECOVERY
    if p["route_length"] < need:
        raise ValueError(f"CYC.route_length: {float(p['route_length'])!r} too short, needs >= "
                         f"conflict_s + {CYC_RECOVERY:g} = {need:g}")  # fmt: skip
    room = _bus_room(p)
    if p["parking_width"] < p["bus_width"] + room:
        raise ValueError(f"CYC.parking_width: {float(p['parking_width'])!r} leaves the bus in "
                         f"the ego's corridor; needs >= bus_width + {room:.3f}")  # fmt: skip


def build_cyc(p: dict) -> fam.Scene:
    """CYC: the bus (``bus_length`` x ``bus_width``, a parked vehicle of the map) stands in the
    parking lane 0.1 m from the kerb; the cyclist (vehicle kind, a bicycle's extent) waits beyond
    the kerb beside the bus's front, heading along the road, its front ``bike_gap`` behind the
    bus front and its road-side edge ``bike_offset`` beyond the kerb.  On the event it rides at
    4.5 m/s along :func:`cyclist_path` across the road and leaves at its end (the clearance).
    The crossing line is the conflict point; the event lead is where a non-reacting ego at
    ``v_ref`` meets it (:func:`cyc_event_lead`), the warning lead one second more
    (:func:`warning_lead`).  Background traffic starts on the opposing
    lanes before the crossing and drives away from it."""
    road_map, route, line, layout = straight_scene(p, float(p["parking_width"]))
    kerb, far = _cyc_layout(p)
    sc = float(p["conflict_s"])
    ride = cyclist_path(p, kerb, far)
    bl, bw = float(p["bus_length"]), float(p["bus_width"])
    bus_front = ride["s0"] + BIKE_EXTENT[0] + float(p["bike_gap"])
    bus_s, bus_d = bus_front - 0.5 * bl, kerb + KERB_GAP + 0.5 * bw
    road_map.occluders = [fam.OccluderSpec(road_path(line, [bus_s], [bus_d])[0],
                                           float(line.heading(bus_s)), (0.5 * bl, 0.5 * bw),
                                           fam.OCC_PARKED_VEHICLE, "bus")]  # fmt: skip
    path = road_path(line, ride["s"], ride["d"])
    cyclist = fam.ActorSpec(
        path, BIKE_EXTENT, fam.KIND_VEHICLE, fam.ROLE_HAZARD, v_pre=0.0, v_post=CYCLIST_SPEED,
        s_end=ride["length"], trigger=fam.TRIGGER_EVENT, despawn_at_end=True,
    )  # fmt: skip
    lead = cyc_event_lead(p)
    return fam.Scene(
        road_map=road_map,
        route=route,
        hazard=cyclist,
        markers=(sc - warning_lead(lead, p["v_ref"]), sc - lead, sc),
        clearance=fam.Clearance(path_arc=ride["length"], despawn=True),
        conflict_xy=road_path(line, [sc], [0.0])[0],
        traffic=fam.opposing_sections(road_map, line, layout, -ROAD_MARGIN + 10.0, sc - 10.0),
        d_safe=fam.D_SAFE_SMALL_M,
        details=dict(cyclist_xy=path[0].tolist(), ride_m=ride["length"], event_lead_m=lead),
    )


CYCLIST = fam.FamilyRecord(
    code="CYC",
    name="Occluded Cyclist Crossing",
    ranges=CYC_RANGES,
    sample=sample_cyc,
    build=build_cyc,
    check=check_cyc,
    # the paper's free-form warning and held-out paraphrase, verbatim
    warning="A cyclist hidden behind the parked van at <FRONT_CAR_POS> is about to cross the "
    "ego lane",
    paraphrases={
        "low": (
            "Watch for a bicycle rider emerging from behind the roadside vehicle near "
            "<FRONT_CAR_POS>; the rider will enter your path.",
        )
    },
    premise=fam.PREMISE_WHOLE_APPROACH,
    knobs={"hazard_speed": (3.0, 6.0), "hazard_delay": (0.0, 1.5)},
    description="a cyclist hidden behind a parked bus crosses the road at 4.5 m/s",
)


# ================================================================================================
# EMV: emergency vehicle crossing a junction from behind a waiting truck
# ================================================================================================
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
        d_safe=fam.D_SAFE_LARGE_M,
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
    description="an ambulance hidden beside a waiting truck crosses the junction ahead",
)


# ================================================================================================
# REV: a parked car reversing into the ego lane
# ================================================================================================
REV_EVENT_LEAD = 10.0  # m before the conflict point
REV_TURN_RADIUS = 5.0  # m, of the car centre's path while it swings out
REV_STRAIGHT_OUT = 1.0  # m the car's rear is in the road when it starts to turn
REV_STOP_LIMIT_S = 8.0  # s after the event: the car drives off (as Obstacle Reveal's object)
VAN_HALF_WIDTH = 1.1  # m
VAN_KERB_GAP = 0.2  # m, the van's rear behind the kerb line
REV_RECOVERY = 30.0  # m of route after the conflict point
REV_ARC_POINTS = 16

REV_RANGES = {
    **STRAIGHT_RANGES,
    "v_ref": fam.FloatRange(8.0, 10.0),  # m/s
    "route_length": fam.FloatRange(70.0, 140.0),  # m
    "bay_s": fam.FloatRange(35.0, 55.0),  # m, route arc of the car's bay (its centre line)
    "bay_width": fam.FloatRange(2.5, 3.0),  # m, perpendicular bays beyond the kerb
    "van_length": fam.FloatRange(5.0, 6.5),  # m, van parked in the bay before the car's
    "car_setback": fam.FloatRange(0.5, 1.5),  # m, the car's rear behind the kerb line
    "reverse_speed": fam.FloatRange(1.5, 2.5),  # m/s
    "end_offset": fam.FloatRange(-1.0, -0.2),  # m, the car's final centre from the ego lane's
    "parked_count": fam.Choice((0, 1, 2)),  # further parked cars in the bays after the car's
}


def sample_rev(rng: np.random.Generator, common: dict) -> dict:
    """REV fields: the road, the bay, a route with 30 m after the conflict point, the van and
    the car's manoeuvre."""
    p = {**common, **sample_straight(rng, "REV")}
    p["v_ref"] = fam.draw(rng, "REV", "v_ref")
    p["bay_s"] = fam.draw(rng, "REV", "bay_s")
    p["route_length"] = fam.draw(rng, "REV", "route_length", p["bay_s"] + REV_RECOVERY + 0.5)
    for key in ("bay_width", "van_length", "car_setback", "reverse_speed", "end_offset"):
        p[key] = fam.draw(rng, "REV", key)
    p["parked_count"] = int(fam.choose(rng, "REV", "parked_count"))
    return {k: v for k, v in p.items() if k not in common}


def reverse_manoeuvre(p: dict, kerb: float) -> dict:
    """The reversing car's path in road coordinates (rear first: straight back out of the bay
    until its rear is 1 m into the road, then a 5-m arc swinging the rear upstream until its
    centre is ``end_offset`` from the ego lane's centre) and its final pose.

    Args:
        p: a REV parameter dict.
        kerb: m, the kerb's offset from the ego lane's centre (negative: right).

    Returns:
        ``s``, ``d`` (n,) m, the path; ``turn`` rad, the final turn from the bay's axis;
        ``conflict_s`` m, the most upstream arc of the car's final box (where an ego must stop).
    """
    s_bay = float(p["bay_s"])
    d_bay = kerb - float(p["car_setback"]) - fam.CAR_EXTENT[0]
    d_turn = kerb + REV_STRAIGHT_OUT - fam.CAR_EXTENT[0]
    rise = float(p["end_offset"]) - d_turn
    turn = math.asin(min(max(rise / REV_TURN_RADIUS, 0.0), 1.0))
    a = np.linspace(0.0, turn, REV_ARC_POINTS)
    s = np.concatenate([[s_bay], s_bay - REV_TURN_RADIUS * (1.0 - np.cos(a))])
    d = np.concatenate([[d_bay], d_turn + REV_TURN_RADIUS * np.sin(a)])
    along = fam.CAR_EXTENT[0] * math.sin(turn) + fam.CAR_EXTENT[1] * math.cos(turn)
    return dict(s=s, d=d, turn=turn, conflict_s=float(s[-1] - along))


def check_rev(p: dict) -> None:
    """REV feasibility: 30 m of route after the conflict point, a manoeuvre that ends in the
    ego lane."""
    w = float(p["lane_width"])
    man = reverse_manoeuvre(p, -0.5 * w)
    if not man["turn"] > 0.0:
        raise ValueError("REV.end_offset: the car would not reach the ego lane")
    need = man["conflict_s"] + REV_RECOVERY
    if p["route_length"] < need:
        raise ValueError(f"REV.route_length: {float(p['route_length'])!r} too short, needs >= "
                         f"{need:.3f}")  # fmt: skip
    if man["conflict_s"] - warning_lead(REV_EVENT_LEAD, p["v_ref"]) < 5.0:
        raise ValueError(f"REV.bay_s: {float(p['bay_s'])!r} puts the warning point before the "
                         "route start")  # fmt: skip


def _bay_box(line, s: float, kerb: float, length: float, half_width: float, name: str,
             gap: float = VAN_KERB_GAP):  # fmt: skip
    """A parked vehicle of the map nose-in in the perpendicular bay at arc ``s``."""
    centre = road_path(line, [s], [kerb - gap - 0.5 * length])[0]
    yaw = float(line.heading(s)) - 0.5 * math.pi
    return fam.OccluderSpec(centre, yaw, (0.5 * length, half_width), fam.OCC_PARKED_VEHICLE, name)


def build_rev(p: dict) -> fam.Scene:
    """REV: perpendicular parking bays of ``bay_width`` line the kerb of the ego's lane (no
    parking lane).  The van (``van_length``, a parked vehicle of the map) stands nose-in in the
    bay before the car's, its rear 0.2 m behind the kerb line; ``parked_count`` further cars
    stand in the bays after it.  The car (vehicle kind, role hazard) stands nose-in in its bay
    with its rear ``car_setback`` behind the kerb line.  On the event it reverses at
    ``reverse_speed`` along :func:`reverse_manoeuvre` and stops across the ego lane; it clears
    (drives off, is removed) once the ego has stood still for 1 s after seeing it, or 8 s after
    the event.  The conflict point is the upstream end of its final box.  Route B: the car stays
    parked.  Background traffic starts on the opposing lanes before the bay."""
    road_map, route, line, layout = straight_scene(p)
    kerb = layout.kerb_d
    s_bay, bay_w = float(p["bay_s"]), float(p["bay_width"])
    occ = [_bay_box(line, s_bay - bay_w, kerb, float(p["van_length"]), VAN_HALF_WIDTH, "van")]
    for k in range(int(p["parked_count"])):
        occ.append(_bay_box(line, s_bay + (k + 1) * bay_w, kerb, 2.0 * fam.CAR_EXTENT[0],
                            fam.CAR_EXTENT[1], f"parked_{k}", float(p["car_setback"])))  # fmt: skip
    road_map.occluders = occ
    man = reverse_manoeuvre(p, kerb)
    path = road_path(line, man["s"], man["d"])
    car = fam.ActorSpec(path, fam.CAR_EXTENT, fam.KIND_VEHICLE, fam.ROLE_HAZARD, v_pre=0.0,
                        v_post=float(p["reverse_speed"]), trigger=fam.TRIGGER_EVENT)  # fmt: skip
    parked = fam.ActorSpec(path, fam.CAR_EXTENT, fam.KIND_VEHICLE, fam.ROLE_CONTEXT)
    sc = man["conflict_s"]
    return fam.Scene(
        road_map=road_map,
        route=route,
        hazard=car,
        hazard_b=parked,
        markers=(sc - warning_lead(REV_EVENT_LEAD, p["v_ref"]), sc - REV_EVENT_LEAD, sc),
        clearance=fam.Clearance(time_limit=REV_STOP_LIMIT_S, on_ego_stop=True, despawn=True),
        conflict_xy=road_path(line, [sc], [0.0])[0],
        traffic=fam.opposing_sections(road_map, line, layout, -ROAD_MARGIN + 10.0, sc - 10.0),
        d_safe=fam.D_SAFE_SMALL_M,
        details=dict(car_xy=path[0].tolist(), end_xy=path[-1].tolist(),
                     turn_deg=math.degrees(man["turn"])),
    )  # fmt: skip


REVERSING = fam.FamilyRecord(
    code="REV",
    name="Reversing Vehicle",
    ranges=REV_RANGES,
    sample=sample_rev,
    build=build_rev,
    check=check_rev,
    # this package's texts (the paper gives none for this event), in the cyclist's style
    warning="The parked vehicle at <FRONT_CAR_POS> is about to reverse into the ego lane.",
    paraphrases={
        "low": (
            "Watch for a car backing out of its parking space near <FRONT_CAR_POS>; it will "
            "move into your path.",
        )
    },
    premise=fam.PREMISE_WHOLE_APPROACH,
    knobs={"hazard_speed": (1.0, 3.0), "hazard_delay": (0.0, 1.5)},
    description="a car parked beside the ego lane reverses out across it",
)

#: The three unseen families, registered on import (paper order: cyclist, emergency vehicle,
#: reversing vehicle).
UNSEEN = tuple(fam.register_family(r) for r in (CYCLIST, EMERGENCY, REVERSING))
UNSEEN_CODES = tuple(f.code for f in UNSEEN)
