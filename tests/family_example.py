"""A scenario family written outside the package, with the public registry only.

``JWK`` — a pedestrian steps out from behind a van parked in the parking lane on the ego's right
and walks slowly across the ego lane.  It is deliberately small (a straight road, one lane each
way, fixed leads) so that tests can register it, build and validate its pairs, write a suite
file of it, and evaluate that file through the Python API and the command line
(``lantern-jax --families tests/family_example.py evaluate --suite FILE``).
"""

from __future__ import annotations

import numpy as np

from lantern_jax.scenarios import registry as fam

WALK_SPEED = 1.5  # m/s
PED_EXTENT = (0.3, 0.3)  # m
WARN_LEAD, EVENT_LEAD = 16.0, 8.0  # m before the crossing line
ROAD_MARGIN = 50.0  # m of road before and after the route
RECOVERY = 30.0  # m of route after the crossing

RANGES = {
    "v_ref": fam.FloatRange(7.0, 9.0),  # m/s
    "route_length": fam.FloatRange(70.0, 100.0),  # m
    "conflict_s": fam.FloatRange(30.0, 40.0),  # m, route arc of the crossing line
    "van_length": fam.FloatRange(6.0, 8.0),  # m
    "lane_width": fam.FloatRange(3.25, 3.5),  # m
}


def sample(rng: np.random.Generator, common: dict) -> dict:
    """The family's own fields (a route with 30 m after the crossing)."""
    p = dict(v_ref=fam.draw(rng, "JWK", "v_ref"), conflict_s=fam.draw(rng, "JWK", "conflict_s"))
    p["route_length"] = fam.draw(rng, "JWK", "route_length", p["conflict_s"] + RECOVERY + 0.5)
    p["van_length"] = fam.draw(rng, "JWK", "van_length")
    p["lane_width"] = fam.draw(rng, "JWK", "lane_width")
    return p


def check(p: dict) -> None:
    """30 m of route after the crossing line."""
    if p["route_length"] < p["conflict_s"] + RECOVERY:
        raise ValueError(f"JWK.route_length: {p['route_length']!r} too short")


def build(p: dict) -> fam.Scene:
    """One lane each way and a 2.6-m parking lane; the van stands 0.1 m from the kerb, the
    pedestrian just past its front beyond the kerb and walks 12 m across on the event."""
    w = float(p["lane_width"])
    layout = fam.StraightLayout(1, 1, w, 0, 2.6)
    line = fam.Centerline.two_piece(0.0, 0.0, 50.0)
    length, sc = float(p["route_length"]), float(p["conflict_s"])
    road_map = fam.straight_road(layout, line, -ROAD_MARGIN, length + ROAD_MARGIN)
    route = fam.ego_route(line, length, "fwd_0")
    kerb, vl = layout.kerb_d, float(p["van_length"])
    van_s = sc - PED_EXTENT[0] - 0.3 - 0.5 * vl
    van_xy = line.to_xy(van_s, kerb + 0.1 + 1.1)
    road_map.occluders = [fam.OccluderSpec(van_xy, 0.0, (0.5 * vl, 1.1), fam.OCC_PARKED_VEHICLE)]
    start, end = line.to_xy(sc, kerb - 0.5), line.to_xy(sc, kerb - 0.5 + 12.0)
    walker = fam.ActorSpec(np.stack([start, end]), PED_EXTENT, fam.KIND_PEDESTRIAN,
                           fam.ROLE_HAZARD, v_post=WALK_SPEED, trigger=fam.TRIGGER_EVENT,
                           despawn_at_end=True)  # fmt: skip
    return fam.Scene(
        road_map=road_map,
        route=route,
        hazard=walker,
        markers=(sc - WARN_LEAD, sc - EVENT_LEAD, sc),
        clearance=fam.Clearance(path_arc=12.0),
        conflict_xy=line.to_xy(sc, 0.0),
    )


RECORD = fam.FamilyRecord(
    code="JWK",
    name="Jaywalker Behind a Van",
    ranges=RANGES,
    sample=sample,
    build=build,
    check=check,
    warning="A pedestrian behind the parked van at <FRONT_CAR_POS> is stepping into the road.",
    paraphrases={"low": ("Someone will walk out from behind the van near <FRONT_CAR_POS>.",)},
    knobs={"hazard_speed": (1.0, 2.0)},
    d_safe=fam.D_SAFE_SMALL_M,  # m, a pedestrian's clearance normaliser (as PE)
)
FAMILY = fam.register_family(RECORD)
