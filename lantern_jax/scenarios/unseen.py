"""The paper's three unseen hazards (appendix "Protocol Extension to Unseen Hazards") as
scenario families, written with the public family API only (:mod:`lantern_jax.scenarios.registry`;
the worked example of ``docs/families.md``).

Importing this module registers them (CYC is defined here, EMV in
:mod:`~lantern_jax.scenarios.unseen_emergency`, REV in
:mod:`~lantern_jax.scenarios.unseen_reversing`, their shared road in
:mod:`~lantern_jax.scenarios.unseen_common`):

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
from lantern_jax.scenarios.unseen_common import (
    STRAIGHT_RANGES,
    road_path,
    sample_straight,
    straight_scene,
    warning_lead,
)
from lantern_jax.scenarios.unseen_emergency import EMERGENCY
from lantern_jax.scenarios.unseen_reversing import REVERSING

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
        traffic=fam.opposing_sections(road_map, line, layout, -fam.ROAD_MARGIN + 10.0, sc - 10.0),
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
    d_safe=fam.D_SAFE_SMALL_M,
    description="a cyclist hidden behind a parked bus crosses the road at 4.5 m/s",
)


#: The three unseen families, registered on import (paper order: cyclist, emergency vehicle,
#: reversing vehicle).
UNSEEN = tuple(fam.register_family(r) for r in (CYCLIST, EMERGENCY, REVERSING))
UNSEEN_CODES = tuple(f.code for f in UNSEEN)
