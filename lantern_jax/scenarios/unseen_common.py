"""What the unseen-hazard families (:mod:`lantern_jax.scenarios.unseen`) share: the warning
lead one second before the event point and the straight road of the cyclist and the reversing
car, written with the public family API only (:mod:`lantern_jax.scenarios.registry`).
"""

from __future__ import annotations

import numpy as np

from lantern_jax.scenarios import registry as fam

WARN_GAP_S = 1.0  # s at v_ref from the warning point to the event point

#: Straight-road geometry shared by CYC and REV.
STRAIGHT_RANGES = {
    "lane_width": fam.FloatRange(3.0, 3.75),  # m
    "lanes_fwd": fam.Choice((1, 2)),  # the ego drives the rightmost one
    "lanes_back": fam.Choice((1, 2)),  # opposing lanes
    "curvature_1": fam.FloatRange(-fam.MAX_CURVATURE, fam.MAX_CURVATURE),  # 1/m before curve_split
    "curvature_2": fam.FloatRange(-fam.MAX_CURVATURE, fam.MAX_CURVATURE),  # 1/m from curve_split on
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
    road_map = fam.straight_road(layout, line, -fam.ROAD_MARGIN, length + fam.ROAD_MARGIN)
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
