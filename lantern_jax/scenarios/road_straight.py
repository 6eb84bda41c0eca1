"""Gently curved multi-lane roads for the straight-road families (NumPy, build time).

A straight-family scene is laid out in **road coordinates** ``(s, d)``: ``s`` is the arc length
along the ego lane's centre line (the route runs from ``s = 0`` to ``s = route_length``), ``d``
the lateral offset from it, positive to the left.  :class:`Centerline` maps road coordinates to
the canonical frame: the ego lane's centre starts at the origin heading +x and has
piecewise-constant curvature (1/m, + = turning left) — typically ``curvature_1`` before the arc
``curve_split`` and ``curvature_2`` after it, so a road is a straight line, one arc, or an
S-bend or tightening curve.  With curvatures below 1/70 m the roads stay gentle (lateral
acceleration below 1.5 m/s^2 at 10 m/s) and, because the ego lane is the reference line, route
arc equals ``s`` along it (to the chord error of 2-m route points, below 1 mm per 100 m).

Lane layout across the road (``w`` = lane width, ``d`` relative to the road's centre line, which
lies ``ego_offset`` to the left of the ego lane): forward lanes ``fwd_k`` (travelling with ``s``)
at ``d = -(k + 0.5) w``, ``k = 0`` next to the centre line; backward lanes ``back_k`` at
``d = +(k + 0.5) w``; an optional parking lane ``shoulder`` (width ``parking_width``, kind 1) to
the right of the forward lanes, with the kerb at its right edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lantern_jax.scenarios.road import (
    LANE_DRIVING,
    LANE_POINTS,
    LANE_SHOULDER,
    ROUTE_SPACING,
    LaneSpec,
    RoadMap,
    RouteSpec,
)

CURVE_EPS = 1e-9  # 1/m, curvatures below this are straight lines


def _advance(x: np.ndarray, y: np.ndarray, th: np.ndarray, kappa: float, ds: np.ndarray):
    """Pose after driving ``ds`` (may be negative) on a constant-curvature arc."""
    if abs(kappa) < CURVE_EPS:
        return x + ds * np.cos(th), y + ds * np.sin(th), th + 0.0 * ds
    th1 = th + kappa * ds
    return (
        x + (np.sin(th1) - np.sin(th)) / kappa,
        y - (np.cos(th1) - np.cos(th)) / kappa,
        th1,
    )


@dataclass(frozen=True)
class Centerline:
    """The ego lane's centre line: constant-curvature pieces joined at ``breaks``.

    Attributes:
        breaks: m, increasing positive arcs where the curvature changes.
        kappas: 1/m, ``len(breaks) + 1`` curvatures, + = turning left; ``kappas[0]`` also
            extends backwards before s = 0.
    """

    breaks: tuple[float, ...]
    kappas: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.kappas) != len(self.breaks) + 1:
            raise ValueError("Centerline: need one more curvature than breaks")
        if any(b <= 0 for b in self.breaks) or any(
            b1 <= b0 for b0, b1 in zip(self.breaks[:-1], self.breaks[1:], strict=True)
        ):
            raise ValueError(f"Centerline: breaks must be positive and increasing, got "
                             f"{self.breaks}")  # fmt: skip

    @staticmethod
    def two_piece(curvature_1: float, curvature_2: float, split: float) -> Centerline:
        """``curvature_1`` before the arc ``split``, ``curvature_2`` after it."""
        return Centerline((float(split),), (float(curvature_1), float(curvature_2)))

    def pose(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Centre-line points and headings at arcs ``s``.

        Args:
            s: (...) float, m, arcs (any sign).

        Returns:
            (``(..., 2)`` points, m, canonical frame; ``(...)`` headings, rad).
        """
        s = np.asarray(s, np.float64)
        z = np.zeros_like(s)
        x, y, th = _advance(z, z, z, self.kappas[0], np.minimum(s, self.breaks[0]))
        x0, y0, th0, s0 = 0.0, 0.0, 0.0, 0.0
        for i, b in enumerate(self.breaks):
            x0, y0, th0 = _advance(x0, y0, th0, self.kappas[i], b - s0)
            s0 = b
            hi = self.breaks[i + 1] if i + 1 < len(self.breaks) else np.inf
            xi, yi, thi = _advance(x0 + z, y0 + z, th0 + z, self.kappas[i + 1],
                                   np.minimum(s, hi) - b)  # fmt: skip
            on = s >= b
            x, y, th = np.where(on, xi, x), np.where(on, yi, y), np.where(on, thi, th)
        return np.stack([x, y], axis=-1), th

    def to_xy(self, s, d) -> np.ndarray:
        """Canonical-frame points of road coordinates ``(s, d)`` (``d`` to the left), (..., 2)."""
        p, th = self.pose(s)
        d = np.asarray(d, np.float64)
        normal = np.stack([-np.sin(th), np.cos(th)], axis=-1)
        return p + d[..., None] * normal

    def heading(self, s) -> np.ndarray:
        """Road heading at arcs ``s``, rad."""
        return self.pose(s)[1]

    def line(self, s0: float, s1: float, d: float, spacing: float) -> np.ndarray:
        """Points of the offset line ``d`` from arc ``s0`` to ``s1`` (either order), spacing in
        ``s`` at most ``spacing``; ``(n, 2)`` with ``n >= 2``."""
        n = max(1, int(math.ceil(abs(s1 - s0) / spacing - 1e-9)))
        s = np.linspace(s0, s1, n + 1)
        return self.to_xy(s, np.full_like(s, d))


@dataclass(frozen=True)
class StraightLayout:
    """Across-road layout of a straight-family road (all widths in m).

    Attributes:
        lanes_fwd: lanes travelling with the ego (>= 1).
        lanes_back: opposing lanes (>= 0).
        lane_width: m.
        ego_lane: index ``k`` of the ego's forward lane ``fwd_k``.
        parking_width: m, width of the parking lane right of the forward lanes (0 = none).
    """

    lanes_fwd: int
    lanes_back: int
    lane_width: float
    ego_lane: int
    parking_width: float = 0.0

    def fwd_d(self, k: int) -> float:
        """Lateral offset of lane ``fwd_k`` from the ego lane, m (+ = left)."""
        return (self.ego_lane - k) * self.lane_width

    def back_d(self, k: int) -> float:
        """Lateral offset of lane ``back_k`` from the ego lane, m."""
        return (self.ego_lane + 1 + k) * self.lane_width

    @property
    def right_edge_d(self) -> float:
        """Offset of the right edge of the forward lanes (the parking lane's left edge), m."""
        return self.fwd_d(self.lanes_fwd - 1) - 0.5 * self.lane_width

    @property
    def kerb_d(self) -> float:
        """Offset of the right kerb (beyond the parking lane, if any), m."""
        return self.right_edge_d - self.parking_width


def straight_road(
    layout: StraightLayout, line: Centerline, s_start: float, s_end: float
) -> RoadMap:
    """The lanes of a (gently curved) straight road between arcs ``s_start`` and ``s_end``.

    Args:
        layout: lanes and widths across the road.
        line: the ego lane's centre line.
        s_start, s_end: m, arcs of the road's ends along the ego lane.

    Returns:
        A :class:`~lantern_jax.scenarios.road.RoadMap` with lanes ``fwd_k``, ``back_k`` and (when
        ``parking_width > 0``) ``shoulder``; no lights, no occluders.
    """
    if layout.lanes_fwd < 1 or layout.lanes_back < 0:
        raise ValueError("straight_road: need >= 1 forward lane and >= 0 backward lanes")
    if not 0 <= layout.ego_lane < layout.lanes_fwd:
        raise ValueError(f"straight_road: ego lane {layout.ego_lane} not a forward lane")
    road = RoadMap(kind="straight")
    spacing = (s_end - s_start) / (LANE_POINTS - 1) + 1e-9
    w = layout.lane_width
    for k in range(layout.lanes_fwd):
        pts = line.line(s_start, s_end, layout.fwd_d(k), spacing)
        road.add(LaneSpec(f"fwd_{k}", pts, w, LANE_DRIVING))
    for k in range(layout.lanes_back):
        pts = line.line(s_end, s_start, layout.back_d(k), spacing)
        road.add(LaneSpec(f"back_{k}", pts, w, LANE_DRIVING))
    if layout.parking_width > 0:
        d = layout.right_edge_d - 0.5 * layout.parking_width
        pts = line.line(s_start, s_end, d, spacing)
        road.add(LaneSpec("shoulder", pts, layout.parking_width, LANE_SHOULDER))
    return road


def ego_route(line: Centerline, length: float, lane_name: str) -> RouteSpec:
    """The ego route along lane ``lane_name``: the ego lane's centre from arc 0 to ``length``,
    points <= 2 m apart."""
    return RouteSpec(line.line(0.0, length, 0.0, ROUTE_SPACING), (lane_name,))


def lane_path(line: Centerline, s0: float, s1: float, d: float, max_points: int) -> np.ndarray:
    """A path along the offset line ``d`` from arc ``s0`` to ``s1`` with at most ``max_points``
    points (an actor path: its arc length is the distance travelled)."""
    spacing = max(abs(s1 - s0) / (max_points - 1), 1e-6) + 1e-9
    return line.line(s0, s1, d, spacing)
