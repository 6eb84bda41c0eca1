"""The planners' route geometry helpers (``policies.planner``) on hand-built routes with
derived values."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import BIG
from lantern_jax.policies.planner import curvature_speed_limit, turn_angles, turn_entry_arc
from lantern_jax.types.observation import NUM_ROUTE_POINTS, ROUTE_STEP


def arc_route(first_straight: int, turn_per_step: float) -> np.ndarray:
    """(NUM_ROUTE_POINTS, 2) points ROUTE_STEP apart: ``first_straight`` straight segments
    along +x, then every segment turns left by ``turn_per_step`` rad."""
    pts, heading = [np.zeros(2)], 0.0
    for k in range(NUM_ROUTE_POINTS - 1):
        if k >= first_straight:
            heading += turn_per_step
        pts.append(pts[-1] + ROUTE_STEP * np.array([math.cos(heading), math.sin(heading)]))
    return np.asarray(pts, np.float32)


@settings(max_examples=200, deadline=None)
@given(st.floats(-3.1, 3.1), st.floats(-3.1, 3.1), st.floats(0.1, 10.0), st.floats(0.1, 10.0))
def test_turn_angle_is_the_wrapped_heading_difference(h1, h2, r1, r2):
    a = np.array([r1 * math.cos(h1), r1 * math.sin(h1)], np.float32)
    b = np.array([r2 * math.cos(h2), r2 * math.sin(h2)], np.float32)
    want = abs(math.remainder(h2 - h1, 2.0 * math.pi))  # in [0, pi]
    got = float(turn_angles(jnp.asarray(b), jnp.asarray(a)))
    assert abs(got - want) < 2e-5


def test_curvature_limit_of_a_constant_curve():
    """A curve of curvature k from the first vertex on: v = sqrt(a_lat / k + 2 b s) is smallest
    at the first turning vertex, s = ROUTE_STEP."""
    turn = 0.1  # rad per 2-m segment: k = 0.05 1/m
    lat, decel = 2.5, 3.0
    got = float(curvature_speed_limit(jnp.asarray(arc_route(0, turn)), lat, decel))
    want = math.sqrt(lat / (turn / ROUTE_STEP) + 2.0 * decel * ROUTE_STEP)
    assert abs(got - want) < 1e-3 * want


def test_curvature_limit_of_a_straight_route_is_the_floor_curvature():
    got = float(curvature_speed_limit(jnp.asarray(arc_route(NUM_ROUTE_POINTS, 0.0)), 2.5, 3.0))
    assert got > 150.0  # sqrt(2.5 / 1e-4): no curve limits the speed


def test_turn_entry_is_the_first_segment_that_leaves_the_first_heading():
    route = jnp.asarray(arc_route(5, 0.1))  # segment k >= 5 turns by 0.1 (k - 4) rad
    # deviations 0.1, 0.2, 0.3, 0.4 ...: the first above 0.3 rad is segment 8
    assert float(turn_entry_arc(route, 0.3 + 1e-3)) == 8 * ROUTE_STEP
    assert float(turn_entry_arc(jnp.asarray(arc_route(NUM_ROUTE_POINTS, 0.0)), 0.3)) == BIG
