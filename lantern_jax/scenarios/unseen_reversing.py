"""REV, the unseen **Reversing Vehicle** family (:mod:`lantern_jax.scenarios.unseen` describes it
and registers it): a car parked nose-in beside the ego lane reverses out across it.  Public
family API only.
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

REV_EVENT_LEAD = 10.0  # m before the conflict point
REV_TURN_RADIUS = 5.0  # m, of the car centre's path while it swings out
REV_STRAIGHT_OUT = 1.0  # m the car's rear is in the road when it starts to turn
REV_STOP_LIMIT_S = 8.0  # s after the event: the car drives off (as Obstacle Reveal's object)
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
    occ = [_bay_box(line, s_bay - bay_w, kerb, float(p["van_length"]), fam.VAN_HALF_WIDTH, "van")]
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
        traffic=fam.opposing_sections(road_map, line, layout, -fam.ROAD_MARGIN + 10.0, sc - 10.0),
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
    d_safe=fam.D_SAFE_SMALL_M,
    description="a car parked beside the ego lane reverses out across it",
)
