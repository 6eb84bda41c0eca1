"""Tests of lantern_jax.maths.polyline and lantern_jax.dynamics (bicycle, controller, lights, IDM,
scripted actors, actor stepping).

Goldens are derived in comments; geometry and the bicycle are also compared step by step with the
slow float64 NumPy reference in ``reference_numpy_dynamics.py``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import (
    BIG,
    DT,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    EGO_MAX_BRAKE,
    EGO_MAX_STEER,
    EGO_WHEELBASE,
    GRAVITY,
    INF_TIME,
    KIND_PEDESTRIAN,
    KIND_VEHICLE,
    LIGHT_GREEN,
    LIGHT_RED,
    LIGHT_YELLOW,
    MOTION_IDM,
    MOTION_SCRIPTED,
    ROLE_BACKGROUND,
    TRIGGER_CLOCK,
    TRIGGER_EVENT,
    TRIGGER_NEVER,
)
from lantern_jax.dynamics.actors import (
    EGO_BOX_MARGIN,
    LEADER_LATERAL,
    ActorSettings,
    step_actors,
)
from lantern_jax.dynamics.bicycle import (
    bicycle_step,
    longitudinal_step,
    sanitize_controls,
    turning_radius,
)
from lantern_jax.dynamics.controller import track_waypoints, waypoints_fault
from lantern_jax.dynamics.idm import IDMParams, idm_accel
from lantern_jax.dynamics.lights import light_states
from lantern_jax.dynamics.scripted import ScriptedMotion, scripted_pose, trigger_time
from lantern_jax.maths import polyline as pl
from lantern_jax.types.world import (
    ActorScript,
    ActorState,
    EgoState,
    TrafficLights,
    tree_index,
    tree_stack,
)

try:  # tests/ as a rootdir-relative folder or as a package
    import reference_numpy_dynamics as ref
except ImportError:  # pragma: no cover
    from tests import reference_numpy_dynamics as ref

F32 = jnp.float32
P = 8  # path capacity used in the actor scenes


def _f(x):
    return jnp.asarray(x, F32)


def _finite(tree) -> bool:
    return all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree.leaves(tree) if x.dtype != bool)


def make_ego(x=0.0, y=0.0, yaw=0.0, speed=0.0, steer=0.0) -> EgoState:
    return EgoState(xy=_f([x, y]), yaw=_f(yaw), speed=_f(speed), steer=_f(steer), accel=_f(0.0))


# ---------------------------------------------------------------------------------------------
# polyline
# ---------------------------------------------------------------------------------------------
# An L-shaped polyline (0,0) -> (10,0) -> (10,10) plus two padding points.
L_PTS = _f([[0, 0], [10, 0], [10, 10], [0, 0], [7, 7]])
L_VALID = jnp.array([True, True, True, False, False])


def test_arc_length_padding_holds_last_value():
    s = pl.arc_length(L_PTS, L_VALID)
    np.testing.assert_allclose(s, [0, 10, 20, 20, 20], atol=1e-6)


def test_interpolate_goldens_and_extrapolation():
    s = pl.arc_length(L_PTS, L_VALID)
    cases = {
        5.0: ([5, 0], 0.0),  # on the first segment
        15.0: ([10, 5], math.pi / 2),  # on the second
        25.0: ([10, 15], math.pi / 2),  # 5 m beyond the end, along the last segment
        -3.0: ([-3, 0], 0.0),  # 3 m before the start, along the first segment
    }
    for sq, (xy, hd) in cases.items():
        p, h = pl.interpolate(L_PTS, s, L_VALID, _f(sq))
        np.testing.assert_allclose(p, xy, atol=1e-5)
        assert float(h) == pytest.approx(hd, abs=1e-6)


def test_project_goldens():
    s = pl.arc_length(L_PTS, L_VALID)
    # (5, 2): above the first segment -> arc 5, 2 m to the left (travel +x, left = +y)
    # (12, 14): beyond the end of the vertical segment -> arc 10 + 14 = 24, 2 m to the right,
    #           distance to the end point (10, 10) = sqrt(2^2 + 4^2)
    # (-2, -1): before the start -> arc -2, 1 m right, distance sqrt(5)
    cases = [
        ([5, 2], (5, 2, 0, 2)),
        ([12, 14], (24, -2, math.pi / 2, math.sqrt(20))),
        ([-2, -1], (-2, -1, 0, math.sqrt(5))),
    ]
    for q, want in cases:
        got = pl.project(L_PTS, s, L_VALID, _f(q))
        np.testing.assert_allclose([float(g) for g in got], want, atol=1e-5)


def test_left_normal():
    np.testing.assert_allclose(pl.left_normal(_f(0.0)), [0, 1], atol=1e-7)
    np.testing.assert_allclose(pl.left_normal(_f(math.pi / 2)), [-1, 0], atol=1e-7)


def _random_polyline(rng, p=9):
    n = int(rng.integers(1, p + 1))
    pts = np.cumsum(rng.normal(0, 3, (p, 2)), axis=0).astype(np.float32)
    valid = np.arange(p) < n
    pts[~valid] = rng.normal(0, 50, (p - n, 2))  # junk in the padding
    return pts, valid, n


def test_project_matches_reference():
    rng = np.random.default_rng(0)
    proj = jax.jit(pl.project)
    checked = 0
    for _ in range(60):
        pts, valid, n = _random_polyline(rng)
        s = pl.arc_length(_f(pts), jnp.asarray(valid))
        for _ in range(4):
            q = rng.normal(0, 8, 2).astype(np.float32) + pts[rng.integers(0, n)]
            got = [float(x) for x in proj(_f(pts), s, jnp.asarray(valid), _f(q))]
            want = ref.project(pts, n, q)
            np.testing.assert_allclose(got[3], want[3], atol=2e-4)
            if want[4] < 1e-3:  # nearest segment ambiguous (shared vertex): only distance
                continue
            np.testing.assert_allclose(got[0], want[0], atol=2e-4)
            np.testing.assert_allclose(got[1], want[1], atol=2e-4)
            d = (got[2] - want[2] + math.pi) % (2 * math.pi) - math.pi
            assert abs(d) < 1e-5
            checked += 1
    assert checked > 150


def test_polyline_gradients_finite_with_padding_and_duplicates():
    # a duplicate point (zero-length segment), a single-point polyline and padding
    pts = _f([[0, 0], [0, 0], [5, 0], [5, 5], [0, 0], [0, 0]])
    valid = jnp.array([True, True, True, True, False, False])

    def f(points, q, sq):
        s = pl.arc_length(points, valid)
        xy, h = pl.interpolate(points, s, valid, sq)
        arc, lat, hd, dist = pl.project(points, s, valid, q)
        return jnp.sum(xy) + h + arc + lat + hd + dist

    grad_f = jax.jit(jax.grad(f, argnums=(0, 1, 2)))
    for q in ([0.0, 0.0], [5.0, 0.0], [2.0, 1.0], [9.0, 9.0]):
        for sq in (-1.0, 0.0, 5.0, 7.0, 30.0):
            assert _finite(grad_f(pts, _f(q), _f(sq)))
    single = jnp.array([True, False, False, False, False, False])

    def g(points, q):
        s = pl.arc_length(points, single)
        xy, h = pl.interpolate(points, s, single, _f(3.0))
        return jnp.sum(xy) + h + sum(pl.project(points, s, single, q))

    np.testing.assert_allclose(
        jax.jit(pl.interpolate)(pts, pl.arc_length(pts, single), single, _f(3.0))[0], [0, 0]
    )
    assert _finite(jax.jit(jax.grad(g, argnums=(0, 1)))(pts, _f([0.0, 0.0])))


# ---------------------------------------------------------------------------------------------
# ego bicycle
# ---------------------------------------------------------------------------------------------
@jax.jit
def _drive_const(ego, steer, accel, friction):
    def body(e, _):
        e = bicycle_step(e, steer, accel, friction)
        return e, e

    return jax.lax.scan(body, ego, None, length=400)[1]


def _fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares (Kasa) circle fit in float64: |p|^2 = 2 c.p + (r^2 - |c|^2)."""
    a = np.c_[2 * xy, np.ones(len(xy))]
    b = (xy**2).sum(1)
    c = np.linalg.lstsq(a, b, rcond=None)[0]
    return c[:2], float(np.sqrt(c[2] + c[0] ** 2 + c[1] ** 2))


@pytest.mark.parametrize("steer_cmd", [0.25, -0.12, 1.0])
def test_constant_steer_traces_derived_circle(steer_cmd):
    # Centre-referenced bicycle, lr = L/2: the instantaneous centre of rotation is on the rear-axle
    # line at L / tan(delta) from the rear axle; the box centre is lr ahead of the axle, so it runs
    # on R = sqrt(lr^2 + (L / tan delta)^2).  delta = 0.25: R = sqrt(1.425^2 + 11.161^2) = 11.252.
    # A command of 1.0 rad saturates at EGO_MAX_STEER = 0.3685 -> R = 7.517 m.
    delta = float(np.clip(steer_cmd, -EGO_MAX_STEER, EGO_MAX_STEER))
    want = math.sqrt((EGO_WHEELBASE / 2) ** 2 + (EGO_WHEELBASE / math.tan(abs(delta))) ** 2)
    assert float(turning_radius(_f(delta))) == pytest.approx(want, rel=1e-6)
    tr = _drive_const(make_ego(speed=5.0), _f(steer_cmd), _f(0.0), _f(1.0))
    # the wheel angle reaches delta after |delta| / 0.7 rad/s <= 0.53 s = 11 ticks
    assert float(tr.steer[20]) == pytest.approx(delta, abs=1e-6)
    xy = np.asarray(tr.xy, np.float64)[20:]
    centre, radius = _fit_circle(xy)
    assert radius == pytest.approx(want, rel=2e-5)
    assert np.std(np.hypot(*(xy - centre).T)) < 2e-4
    # turning direction: positive steer turns left (centre to the left of the start heading +x)
    assert np.sign(centre[1]) == np.sign(delta)


@pytest.mark.parametrize("friction,v0", [(0.5, 20.0), (1.0, 15.0), (0.3, 8.0)])
def test_friction_limited_braking_distance(friction, v0):
    # full braking at min(EGO_MAX_BRAKE, mu g): distance v0^2 / (2 min(8, mu g))
    # mu = 0.5, v0 = 20: 400 / 9.81 = 40.775 m;  mu = 1.0 (limit 8): 225 / 16 = 14.0625 m
    decel = min(EGO_MAX_BRAKE, friction * GRAVITY)
    tr = _drive_const(make_ego(speed=v0), _f(0.0), _f(-100.0), _f(friction))
    assert float(tr.speed[-1]) == 0.0
    assert float(tr.xy[-1, 0]) == pytest.approx(v0**2 / (2 * decel), abs=2e-3)
    assert float(jnp.min(tr.accel)) == pytest.approx(-decel, abs=1e-4)


@jax.jit
def _drive_seq(ego, steers, accels, friction):
    def body(e, u):
        e = bicycle_step(e, u[0], u[1], friction)
        return e, e

    return jax.lax.scan(body, ego, jnp.stack([steers, accels], 1))[1]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), v0=st.floats(0.0, 25.0), friction=st.floats(0.05, 1.2))
def test_speed_never_negative_and_state_finite(seed, v0, friction):
    rng = np.random.default_rng(seed)
    steers = rng.uniform(-1, 1, 200).astype(np.float32)
    accels = rng.uniform(-30, 5, 200).astype(np.float32)
    tr = _drive_seq(make_ego(speed=v0), _f(steers), _f(accels), _f(friction))
    assert float(jnp.min(tr.speed)) >= 0.0
    assert _finite(tr)
    assert float(jnp.max(jnp.abs(tr.steer))) <= EGO_MAX_STEER + 1e-6


def test_sanitize_controls_nan_means_full_brake_and_fault():
    for bad in [(jnp.nan, 1.0), (0.1, jnp.inf), (-jnp.inf, jnp.nan)]:
        steer, accel, fault = sanitize_controls(_f(bad[0]), _f(bad[1]))
        assert bool(fault) and float(steer) == 0.0 and float(accel) == -EGO_MAX_BRAKE
    steer, accel, fault = sanitize_controls(_f(0.1), _f(-2.0))
    assert not bool(fault) and float(steer) == pytest.approx(0.1) and float(accel) == -2.0
    # a NaN command brakes at the friction limit and never puts NaN in the state
    e = bicycle_step(make_ego(speed=10.0), _f(jnp.nan), _f(jnp.nan), _f(1.0))
    assert _finite(e)
    assert float(e.speed) == pytest.approx(10.0 - 8.0 * DT, abs=1e-5)


def test_bicycle_matches_numpy_reference_step_by_step():
    rng = np.random.default_rng(1)
    n = 150
    steers = rng.uniform(-0.6, 0.6, n)
    accels = rng.uniform(-12, 5, n)
    steers[::37] = np.nan  # a few faulty commands
    friction = 0.7
    tr = _drive_seq(make_ego(speed=6.0), _f(steers), _f(accels), _f(friction))
    prev = {"x": 0.0, "y": 0.0, "yaw": 0.0, "speed": 6.0, "steer": 0.0}
    whole = dict(prev)
    for k in range(n):
        # one step from the same (JAX) state: tight agreement
        want = ref.bicycle_step(prev, float(steers[k]), float(accels[k]), friction, DT)
        got = tree_index(tr, k)
        np.testing.assert_allclose(got.xy, [want["x"], want["y"]], atol=5e-5)
        np.testing.assert_allclose(float(got.speed), want["speed"], atol=1e-5)
        np.testing.assert_allclose(float(got.steer), want["steer"], atol=1e-6)
        np.testing.assert_allclose(float(got.accel), want["accel"], atol=2e-3)
        dyaw = (float(got.yaw) - want["yaw"] + math.pi) % (2 * math.pi) - math.pi
        assert abs(dyaw) < 1e-5
        prev = {
            "x": float(got.xy[0]),
            "y": float(got.xy[1]),
            "yaw": float(got.yaw),
            "speed": float(got.speed),
            "steer": float(got.steer),
        }
        whole = ref.bicycle_step(whole, float(steers[k]), float(accels[k]), friction, DT)
    # the whole float64 reference trajectory (no re-synchronisation) stays close as well
    np.testing.assert_allclose(tr.xy[-1], [whole["x"], whole["y"]], atol=5e-3)


def test_bicycle_gradients_finite():
    # through 150 ticks from standstill with zero steering (sinc at 0, stop-in-tick branch)
    def final_pos(v0, steers, accels):
        tr = _drive_seq(make_ego(speed=v0), steers, accels, _f(0.8))
        return jnp.sum(tr.xy[-1]) + tr.yaw[-1] + tr.speed[-1]

    rng = np.random.default_rng(3)
    for v0, steers, accels in [
        (0.0, np.zeros(150), np.zeros(150)),
        (0.0, np.zeros(150), np.full(150, -5.0)),
        (5.0, rng.uniform(-0.5, 0.5, 150), rng.uniform(-10, 4, 150)),
    ]:
        grads = jax.jit(jax.grad(final_pos, argnums=(0, 1, 2)))(_f(v0), _f(steers), _f(accels))
        assert _finite(grads)


def test_longitudinal_step_stops_mid_tick():
    # v = 0.2 m/s, a = -8: stops after 0.025 s having covered 0.2^2 / 16 = 0.0025 m
    d, v = longitudinal_step(_f(0.2), _f(-8.0), 0.05)
    assert float(v) == 0.0 and float(d) == pytest.approx(0.0025, rel=1e-5)


# ---------------------------------------------------------------------------------------------
# controller
# ---------------------------------------------------------------------------------------------
def _to_ego(points, xy, yaw):
    """World points (N, 2) -> ego frame (x forward, y right)."""
    d = points - xy
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([c * d[:, 0] + s * d[:, 1], s * d[:, 0] - c * d[:, 1]], axis=1)


def _closed_loop(plan_fn, ego, n):
    """Drive n ticks with waypoints planned from the world state by ``plan_fn(ego)``."""

    @jax.jit
    def run(e):
        def body(e, _):
            wp = plan_fn(e)
            steer, accel = track_waypoints(e, wp, _f(1.0))
            e = bicycle_step(e, steer, accel, _f(1.0))
            return e, e

        return jax.lax.scan(body, e, None, length=n)[1]

    return run(ego)


K_STEPS = jnp.arange(1, 11, dtype=F32)  # waypoint k at 0.25 (k + 1) s
_track = jax.jit(track_waypoints)


def test_controller_straight_constant_speed():
    # Waypoints every 8 * 0.25 = 2 m along the x axis starting at the ego's projection: the plan
    # of a car cruising at 8 m/s.  From 8 m/s with a 0.5 m lateral offset the car converges to
    # the line and holds 8 m/s for the 10 s drive.
    def plan(e):
        pts = jnp.stack([e.xy[0] + 2.0 * K_STEPS, jnp.zeros(10)], axis=1)
        return _to_ego(pts, e.xy, e.yaw)

    tr = _closed_loop(plan, make_ego(y=0.5, speed=8.0), 200)
    assert float(jnp.max(jnp.abs(tr.speed - 8.0))) < 0.05
    assert float(jnp.max(jnp.abs(tr.xy[100:, 1]))) < 0.005  # settled on the line after 5 s
    assert float(tr.xy[-1, 0]) == pytest.approx(80.0, abs=0.5)

    # from standstill the same plan accelerates (<= 3 m/s^2) and settles at 8 m/s
    tr = _closed_loop(plan, make_ego(speed=0.0), 200)
    assert float(jnp.max(tr.accel)) <= 3.0 + 1e-4
    assert float(jnp.max(jnp.abs(tr.speed[100:] - 8.0))) < 0.05


def test_controller_follows_constant_curvature_arc():
    # Reference: left-turning circle of radius 30 m through the origin, centre (0, 30); waypoints
    # at 2 m of arc apart (8 m/s) starting from the ego's angular position.  80 m of driving is
    # 2.7 rad of the circle; the cross-track error |dist(ego, centre) - 30| stays small.
    radius, centre = 30.0, jnp.array([0.0, 30.0])

    def plan(e):
        rel = e.xy - centre
        theta = jnp.arctan2(rel[0], -rel[1]) + 2.0 * K_STEPS / radius
        pts = centre + radius * jnp.stack([jnp.sin(theta), -jnp.cos(theta)], axis=1)
        return _to_ego(pts, e.xy, e.yaw)

    tr = _closed_loop(plan, make_ego(speed=8.0), 200)
    cte = jnp.abs(jnp.linalg.norm(tr.xy - centre, axis=1) - radius)
    assert float(jnp.max(cte)) < 0.15
    assert float(jnp.max(cte[60:])) < 0.05
    assert float(jnp.max(jnp.abs(tr.speed - 8.0))) < 0.1


def test_controller_all_zero_waypoints_stop():
    # all waypoints at the origin = "stop here": full braking at 8 m/s^2 (friction 1) stops a
    # 10 m/s car in 10^2 / 16 = 6.25 m and it stays still (no reversing).
    tr = _closed_loop(lambda e: jnp.zeros((10, 2), F32), make_ego(speed=10.0), 80)
    assert float(tr.speed[-1]) == 0.0
    assert float(jnp.min(tr.speed)) >= 0.0
    assert float(tr.xy[-1, 0]) == pytest.approx(6.25, abs=0.01)


def test_controller_braking_plan_goldens():
    ego = make_ego(speed=10.0)
    # plan of a constant 3 m/s^2 deceleration from 10 m/s: x(t) = 10 t - 1.5 t^2.  Segment
    # speeds at 0.375 s / 0.875 s are 8.875 / 7.375 -> a_ff = -3; v_des(0.75 s) = 7.75 ->
    # planned speed now 7.75 + 0.75 * 3 = 10 = v, so the command is exactly -3.
    t = 0.25 * K_STEPS
    wp = jnp.stack([10 * t - 1.5 * t**2, jnp.zeros(10)], axis=1)
    _, accel = _track(ego, wp, _f(1.0))
    assert float(accel) == pytest.approx(-3.0, abs=1e-4)
    # bunched waypoints 1 m ahead: v_des = 0 < 0.4 -> full friction-limited braking
    wp = jnp.tile(_f([[1.0, 0.0]]), (10, 1))
    steer, accel = _track(ego, wp, _f(0.5))
    assert float(accel) == pytest.approx(-0.5 * GRAVITY, abs=1e-5)
    # gentle start from standstill at 0.5 m/s^2: v_des(0.75 s) = 0.375 < 0.4 but the plan keeps
    # accelerating (1.1 m/s at 2.25 s), so it is not a stop: a_ff = 0.5, v_ref = 0 -> accel 0.5
    wp = jnp.stack([0.25 * t**2, jnp.zeros(10)], axis=1)
    _, accel = _track(make_ego(speed=0.0), wp, _f(1.0))
    assert float(accel) == pytest.approx(0.5, abs=1e-4)
    # a plan slowing to 5 m/s (far below 10 m/s) asks for far more than the feed-forward alone
    wp = jnp.stack([5 * t, jnp.zeros(10)], axis=1)
    _, accel = _track(ego, wp, _f(1.0))
    assert float(accel) == pytest.approx(-8.0)
    # waypoints to the right (ego y is right) steer right (negative wheel angle)
    wp = jnp.stack([2 * K_STEPS, 0.1 * K_STEPS**2], axis=1)
    steer, _ = _track(make_ego(speed=8.0), wp, _f(1.0))
    assert float(steer) < 0.0


def test_controller_gradients_finite():
    grad = jax.jit(jax.grad(lambda wp, v: sum(_track(make_ego(speed=v), wp, _f(1.0))), (0, 1)))
    plans = [
        jnp.stack([2 * K_STEPS, 0.05 * K_STEPS**2], axis=1),
        jnp.zeros((10, 2), F32),
        jnp.tile(_f([[1.0, 0.0]]), (10, 1)),
    ]
    for wp in plans:
        for v in (0.0, 8.0):
            assert _finite(grad(wp, _f(v)))


def test_a_plan_faster_than_the_limit_is_a_fault_and_one_just_under_is_not():
    """Legs of MAX_PLAN_SPEED * WAYPOINT_DT = 25 m: a straight plan at 99 m/s is driven, one at
    101 m/s is a fault, as is a single 26 m jump between two waypoints of a slow plan (or from
    the ego to the first waypoint), whatever its direction."""
    from lantern_jax.core.constants import MAX_PLAN_SPEED, WAYPOINT_DT

    leg = MAX_PLAN_SPEED * WAYPOINT_DT
    assert leg == 25.0
    straight = jnp.stack([K_STEPS * WAYPOINT_DT, jnp.zeros(10)], axis=1)  # 1 m/s
    assert not bool(waypoints_fault(99.0 * straight))
    assert bool(waypoints_fault(101.0 * straight))
    assert bool(waypoints_fault(-101.0 * straight))  # backwards as well
    jump = straight.at[5:, 1].add(26.0)  # waypoints 5..9 shifted 26 m sideways
    assert bool(waypoints_fault(jump))
    assert bool(waypoints_fault(straight.at[0, 0].set(26.0)))  # from the ego
    assert not bool(waypoints_fault(straight.at[5:, 1].add(24.0)))


def test_controller_nan_waypoints_fault():
    wp = jnp.stack([2 * K_STEPS, jnp.zeros(10)], axis=1).at[4, 1].set(jnp.nan)
    assert bool(waypoints_fault(wp))
    assert not bool(waypoints_fault(jnp.zeros((10, 2))))
    steer, accel = _track(make_ego(speed=5.0), wp, _f(1.0))
    assert bool(jnp.isnan(steer)) and bool(jnp.isnan(accel))
    s, a, fault = sanitize_controls(steer, accel)
    assert bool(fault) and float(a) == -EGO_MAX_BRAKE and float(s) == 0.0
    # no NaN leaks into gradients with respect to the (finite) ego state
    g = jax.jit(
        jax.grad(lambda v: sanitize_controls(*track_waypoints(make_ego(speed=v), wp, 1.0))[1])
    )
    assert np.isfinite(float(g(_f(5.0))))


# ---------------------------------------------------------------------------------------------
# traffic lights
# ---------------------------------------------------------------------------------------------
def test_light_states_cycle():
    # cycle 10 s green, 3 s yellow, 7 s red (20 s); light 1 is offset by 5 s; light 2 is padding
    lights = TrafficLights(
        green=_f([10, 10, 10]),
        yellow=_f([3, 3, 3]),
        red=_f([7, 7, 7]),
        offset=_f([0, 5, 0]),
        stop_xy=jnp.zeros((3, 2), F32),
        valid=jnp.array([True, True, False]),
    )
    f = jax.jit(light_states)
    g, y, r = LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED
    cases = {0.0: (g, g, g), 6.0: (g, y, g), 10.5: (y, r, g), 14.0: (r, r, g), 20.0: (g, g, g)}
    for t, want in cases.items():
        got = f(lights, _f(t))
        assert got.dtype == jnp.int32
        assert tuple(int(x) for x in got) == want


# ---------------------------------------------------------------------------------------------
# actor scenes
# ---------------------------------------------------------------------------------------------
def _path_x(y=0.0, x0=0.0, x1=400.0):
    """Straight path along +x at height y: 2 valid points, padding filled with junk."""
    pts = np.full((P, 2), 123.0, np.float32)
    pts[0], pts[1] = (x0, y), (x1, y)
    valid = np.arange(P) < 2
    s = np.full(P, x1 - x0, np.float32)
    s[0] = 0.0
    return pts, s, valid


def make_scene(specs: list[dict], num_slots: int | None = None):
    """Actor states + scripts from per-actor dicts; slots beyond len(specs) are junk padding."""
    num = num_slots or len(specs)
    rng = np.random.default_rng(7)
    cols = {
        k: []
        for k in (
            "motion path path_s path_valid s_init v_pre v_post s_hold s_end trigger "
            "trigger_delay lat_shift lat_duration despawn_at_end light_index stop_s "
            "trigger_deadline handover_after xy yaw speed extent kind s"
        ).split()
    }
    for i in range(num):
        if i < len(specs):
            d = dict(
                motion=MOTION_SCRIPTED, y=0.0, s_init=0.0, v_pre=0.0, v_post=0.0, s_hold=BIG,
                s_end=BIG, trigger=TRIGGER_NEVER, trigger_delay=0.0, lat_shift=0.0,
                lat_duration=1.0, despawn_at_end=False, light_index=-1, stop_s=BIG, speed=None,
                extent=(2.0, 0.9), kind=KIND_VEHICLE, trigger_deadline=INF_TIME,
                handover_after=INF_TIME,
            )  # fmt: skip
            d.update(specs[i])
            pts, s, valid = _path_x(d["y"])
            x = d["s_init"]
            speed = d["v_pre"] if d["speed"] is None else d["speed"]
            xy, yaw, ext = (x, d["y"]), 0.0, d["extent"]
        else:  # padding: garbage everywhere, including NaN, placed right on the other paths
            d = dict(
                motion=int(rng.integers(0, 2)), s_init=np.nan, v_pre=3.0, v_post=np.nan,
                s_hold=0.0, s_end=-5.0, trigger=TRIGGER_CLOCK, trigger_delay=0.0,
                lat_shift=np.nan, lat_duration=0.0, despawn_at_end=True, light_index=0,
                stop_s=1.0, kind=KIND_VEHICLE, trigger_deadline=0.0, handover_after=0.0,
            )  # fmt: skip
            pts = rng.normal(0, 30, (P, 2)).astype(np.float32)
            pts[2] = np.nan
            s = np.full(P, np.nan, np.float32)
            valid = np.ones(P, bool)
            xy, yaw, ext, speed, x = tuple(rng.uniform(0, 60, 2) * [1, 0]), 0.0, (3, 3), 5.0, 30.0
        cols["motion"].append(d["motion"])
        cols["path"].append(pts)
        cols["path_s"].append(s)
        cols["path_valid"].append(valid)
        for k in ("s_init v_pre v_post s_hold s_end trigger trigger_delay lat_shift "
                  "lat_duration despawn_at_end light_index stop_s kind trigger_deadline "
                  "handover_after").split():  # fmt: skip
            cols[k].append(d[k])
        cols["xy"].append(xy)
        cols["yaw"].append(yaw)
        cols["speed"].append(speed)
        cols["extent"].append(ext)
        cols["s"].append(x)
    valid = np.arange(num) < len(specs)
    script = ActorScript(
        extent=_f(np.asarray(cols["extent"], np.float32)),
        kind=jnp.asarray(cols["kind"], jnp.int32),
        role=jnp.full((num,), ROLE_BACKGROUND, jnp.int32),
        valid=jnp.asarray(valid),
        motion=jnp.asarray(cols["motion"], jnp.int32),
        path=_f(np.stack(cols["path"])),
        path_s=_f(np.stack(cols["path_s"])),
        path_valid=jnp.asarray(np.stack(cols["path_valid"])),
        s_init=_f(cols["s_init"]),
        v_pre=_f(cols["v_pre"]),
        v_post=_f(cols["v_post"]),
        s_hold=_f(cols["s_hold"]),
        s_end=_f(cols["s_end"]),
        trigger=jnp.asarray(cols["trigger"], jnp.int32),
        trigger_delay=_f(cols["trigger_delay"]),
        lat_shift=_f(cols["lat_shift"]),
        lat_duration=_f(cols["lat_duration"]),
        despawn_at_end=jnp.asarray(cols["despawn_at_end"], bool),
        light_index=jnp.asarray(cols["light_index"], jnp.int32),
        stop_s=_f(cols["stop_s"]),
        trigger_deadline=_f(cols["trigger_deadline"]),
        handover_after=_f(cols["handover_after"]),
    )
    actors = ActorState(
        xy=_f(np.asarray(cols["xy"], np.float32)),
        yaw=_f(cols["yaw"]),
        speed=_f(cols["speed"]),
        s=_f(cols["s"]),
        lat=jnp.zeros((num,), F32),
        active=jnp.ones((num,), bool),
    )
    return actors, script


def make_lights(green, yellow, red):
    return TrafficLights(
        green=_f([green]),
        yellow=_f([yellow]),
        red=_f([red]),
        offset=_f([0.0]),
        stop_xy=jnp.zeros((1, 2), F32),
        valid=jnp.array([True]),
    )


FAR_EGO = (_f([0.0, 500.0]), _f(0.0), _f(0.0))  # an ego far off every path


N_ROLL = 600  # ticks (30 s) of every actor rollout: one compilation per actor count


@jax.jit
def _rollout_jit(actors, script, lights, ego, t_event):
    def body(a, k):
        t_next = (k + 1).astype(F32) * DT
        ls = light_states(lights, t_next - DT)
        a = step_actors(a, script, t_next, t_event, ls, *ego)
        return a, a

    return jax.lax.scan(body, actors, jnp.arange(N_ROLL))[1]


def _rollout_actors(actors, script, lights, ego=None, t_event=INF_TIME):
    """Step the actors N_ROLL ticks (ego held fixed); returns the states after each tick."""
    return _rollout_jit(actors, script, lights, ego or FAR_EGO, _f(t_event))


_step = jax.jit(step_actors)


NO_LIGHTS = make_lights(100.0, 0.0, 0.0)  # always green


# ---------------------------------------------------------------------------------------------
# IDM
# ---------------------------------------------------------------------------------------------
def test_idm_formula_golden():
    # v = 10, v0 = 20, gap = 30, dv = 2 (closing), defaults s0 2, T 1.2, a 1.5, b 2:
    # s* = 2 + 12 + 10 * 2 / (2 sqrt(3)) = 19.7735;  a (1 - 0.5^4 - (19.7735 / 30)^2) = 0.75456
    want = 1.5 * (1 - 0.5**4 - ((2 + 12 + 20 / (2 * math.sqrt(3))) / 30) ** 2)
    assert float(idm_accel(_f(10), _f(20), _f(30), _f(2))) == pytest.approx(want, rel=1e-5)
    # touching / overlapping leader: clipped at the braking limit, finite
    assert float(idm_accel(_f(10), _f(20), _f(0.0), _f(10))) == -8.0
    assert float(idm_accel(_f(10), _f(20), _f(-3.0), _f(10))) == -8.0
    # free road from standstill: a; v0 = 0 means hold still
    assert float(idm_accel(_f(0), _f(10), _f(BIG), _f(0))) == pytest.approx(1.5)
    assert float(idm_accel(_f(0), _f(0), _f(BIG), _f(0))) == -8.0
    p = IDMParams(s0=4.0, time_headway=0.25)
    assert float(idm_accel(_f(0), _f(10), _f(4.0), _f(0), p)) == pytest.approx(0.0, abs=1e-6)


def test_idm_settles_behind_stopped_leader():
    # leader: static scripted car at x = 100; follower: IDM at x = 20, 12 m/s, v0 = 14.
    # Equilibrium of the IDM at v = 0 is gap = s0 = 2 m; both half lengths are 2 m.
    actors, script = make_scene(
        [dict(s_init=100.0), dict(motion=MOTION_IDM, s_init=20.0, v_pre=14.0, speed=12.0)]
    )
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    gap = tr.s[:, 0] - tr.s[:, 1] - 4.0
    assert float(jnp.min(gap)) > 0.0
    assert float(gap[-1]) == pytest.approx(2.0, abs=0.2)
    assert float(tr.speed[-1, 1]) < 0.02
    assert float(jnp.min(tr.speed)) >= 0.0
    np.testing.assert_allclose(tr.xy[-1, 1], [tr.s[-1, 1], 0.0], atol=1e-4)
    np.testing.assert_array_equal(tr.lat, 0.0)


def test_idm_free_road_converges_to_v0():
    actors, script = make_scene([dict(motion=MOTION_IDM, v_pre=11.0, speed=0.0)])
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    assert float(tr.speed[-1, 0]) == pytest.approx(11.0, abs=0.02)
    assert float(jnp.max(tr.speed)) <= 11.0 + 1e-4


def test_idm_stops_behind_the_ego():
    # the ego stands at x = 60 on the actor's lane: the IDM actor (from 10 m/s) stops behind it
    actors, script = make_scene([dict(motion=MOTION_IDM, v_pre=12.0, speed=10.0)])
    ego = (_f([60.0, 0.3]), _f(0.0), _f(0.0))
    tr = _rollout_actors(actors, script, NO_LIGHTS, ego=ego)
    gap = 60.0 - EGO_HALF_LENGTH - (tr.s[:, 0] + 2.0)
    assert float(jnp.min(gap)) > 0.0
    assert float(gap[-1]) == pytest.approx(2.0, abs=0.2)


V_FOLLOW = 8.0  # m/s, the follower of the ego-as-leader scenes below, at its desired speed


def _one_tick_speed(actors, script, ego, rule):
    """The follower's (slot 0) speed after one tick under the ego-leader ``rule``."""
    out = jax.jit(step_actors, static_argnames="ego_leader")(
        actors, script, _f(DT), _f(INF_TIME), light_states(NO_LIGHTS, _f(0.0)), *ego,
        ego_leader=rule,
    )  # fmt: skip
    return float(out.speed[0])


def _braked_for(gap: float, v_lead: float = 0.0) -> float:
    """The IDM follower's speed after one tick behind a leader ``gap`` m ahead (no other)."""
    acc = float(idm_accel(_f(V_FOLLOW), _f(V_FOLLOW), _f(gap), _f(V_FOLLOW - v_lead)))
    assert -IDMParams().max_brake < acc < 0.0  # not at the limit: the gap and speed count
    return V_FOLLOW + acc * DT


@pytest.mark.parametrize("case", ["bend", "nose in", "adjacent lane", "behind"])
def test_the_ego_as_a_leader_by_heading_line_or_by_box_on_the_path(case):
    """The two ego-leader rules (``ActorSettings.ego_leader``) on hand-built scenes, one IDM car
    at 8 m/s (its desired speed, so without a leader it keeps it); where the ego leads, the car's
    next speed is the IDM's behind a leader at the derived gap and speed (neither at the braking
    limit, so both count):

    * *bend*: both on a circle of radius 18 m, the ego 20 m ahead along it, aligned with it, at
      6 m/s: its centre lies 18 (1 - cos(20/18)) = 10.0 m off the car's heading line, which misses
      it; on the path it leads at 20 - 2.0 - 2.4508 m and 6 m/s;
    * *nose in*: a straight lane, the ego 20 m ahead, 2.6 m to the right, turned 60 degrees into
      the lane, at 4 m/s: its box reaches sin 60 * 2.4508 + cos 60 * 1.0642 = 2.654 m across,
      within 0.9 + 2.654 + 0.3 of the lane's line; it leads at 20 - 2.0 - (cos 60 * 2.4508 +
      sin 60 * 1.0642) m and 4 cos 60 = 2 m/s along the lane;
    * *adjacent lane*: the ego parallel, 3.5 m to the side (its box reaches 1.0642 m across:
      outside 0.9 + 1.0642 + 0.3): no rule brakes;
    * *behind*: the ego 15 m behind on the lane: no rule brakes.
    """
    actors, script = make_scene([dict(motion=MOTION_IDM, v_pre=V_FOLLOW, speed=V_FOLLOW)])
    half_len, half_w = 2.0, 0.9  # make_scene's car
    if case == "bend":
        r = 18.0
        n = 161  # a point every 0.25 m: the chords' arcs within 1e-4 m of the circle's
        s_path = np.linspace(0.0, 40.0, n)
        pts = np.stack([r * np.sin(s_path / r), r * (1 - np.cos(s_path / r))], -1)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=-1)
        script = script.replace(
            path=_f(pts[None]), path_s=_f(np.concatenate([[0.0], np.cumsum(seg)])[None]),
            path_valid=jnp.ones((1, n), bool),
        )  # fmt: skip
        th = 20.0 / r
        ego = (_f([r * np.sin(th), r * (1 - np.cos(th))]), _f(th), _f(6.0))
        assert r * (1 - np.cos(th)) > LEADER_LATERAL  # off the heading line
        want_box = _braked_for(20.0 - half_len - EGO_HALF_LENGTH, 6.0)
    elif case == "nose in":
        yaw = np.pi / 3
        across = np.sin(yaw) * EGO_HALF_LENGTH + np.cos(yaw) * EGO_HALF_WIDTH
        assert LEADER_LATERAL < 2.6 < half_w + across + EGO_BOX_MARGIN
        ego = (_f([20.0, -2.6]), _f(yaw), _f(4.0))
        along = np.cos(yaw) * EGO_HALF_LENGTH + np.sin(yaw) * EGO_HALF_WIDTH
        want_box = _braked_for(20.0 - half_len - along, 4.0 * np.cos(yaw))
    elif case == "adjacent lane":
        assert 3.5 > half_w + EGO_HALF_WIDTH + EGO_BOX_MARGIN
        ego = (_f([15.0, -3.5]), _f(0.0), _f(0.0))
        want_box = V_FOLLOW
    else:
        ego = (_f([-15.0, 0.0]), _f(0.0), _f(0.0))
        want_box = V_FOLLOW
    heading = _one_tick_speed(actors, script, ego, "heading_line")
    box = _one_tick_speed(actors, script, ego, "heading_line_or_box")
    assert heading == pytest.approx(V_FOLLOW, abs=1e-4)  # the heading line sees no leader
    assert box == pytest.approx(want_box, abs=2e-3)
    if case in ("bend", "nose in"):
        assert box < V_FOLLOW - 0.05  # it brakes


def test_the_box_rule_keeps_every_leader_the_heading_line_finds():
    """``"heading_line_or_box"`` takes the nearer of the two gaps: where the heading line finds
    the ego (on the lane, 30 m ahead) the car brakes exactly as under ``"heading_line"``; an
    unknown rule is refused naming the field."""
    actors, script = make_scene([dict(motion=MOTION_IDM, v_pre=V_FOLLOW, speed=V_FOLLOW)])
    ego = (_f([30.0, 0.2]), _f(0.0), _f(0.0))
    heading = _one_tick_speed(actors, script, ego, "heading_line")
    assert heading == pytest.approx(_braked_for(30.0 - 2.0 - EGO_HALF_LENGTH), abs=2e-3)
    assert _one_tick_speed(actors, script, ego, "heading_line_or_box") == pytest.approx(
        heading, abs=1e-5
    )
    with pytest.raises(ValueError, match="ActorSettings.ego_leader: 'box' is not one of"):
        ActorSettings(ego_leader="box").validate()


def test_idm_red_light_and_yellow_dilemma():
    # permanent red, stop line at s = 80: the front bumper (s + 2) stops before the line, about
    # s0 = 2 m short of it.
    spec = dict(motion=MOTION_IDM, v_pre=12.0, speed=10.0, light_index=0, stop_s=80.0)
    actors, script = make_scene([spec])
    tr = _rollout_actors(actors, script, make_lights(0.0, 0.0, 100.0))
    front = tr.s[:, 0] + 2.0
    assert float(jnp.max(front)) < 80.0
    assert float(front[-1]) == pytest.approx(78.0, abs=0.3)
    assert float(tr.speed[-1, 0]) < 0.02
    # green: it drives through
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    assert float(tr.s[-1, 0]) > 100.0
    # permanent yellow: far away it stops; already within its comfortable braking distance
    # (10^2 / (2 * 2) = 25 m > 10 m to the line) it proceeds
    tr = _rollout_actors(actors, script, make_lights(0.0, 100.0, 0.0))
    assert float(jnp.max(tr.s[:, 0] + 2.0)) < 80.0
    near, near_script = make_scene([dict(spec, s_init=68.0)])
    tr = _rollout_actors(near, near_script, make_lights(0.0, 100.0, 0.0))
    assert float(tr.s[-1, 0]) > 100.0


# ---------------------------------------------------------------------------------------------
# scripted actors
# ---------------------------------------------------------------------------------------------
PED = dict(
    kind=KIND_PEDESTRIAN, y=-20.0, s_init=5.0, v_pre=0.0, v_post=3.0, trigger=TRIGGER_EVENT,
    trigger_delay=0.0, extent=(0.3, 0.3), s_end=40.0,
)  # fmt: skip


_scripted_pose_jit = jax.jit(scripted_pose)


def _pose(script, i, t, tau):
    motion = jax.tree.map(lambda x: x[i], ScriptedMotion.of(script))
    path = (script.path[i], script.path_s[i], script.path_valid[i])
    return _scripted_pose_jit(*path, motion, _f(t), _f(tau))


def test_pedestrian_triggered_by_event_moves_6m_in_2s():
    # v_post = 3 m/s triggered at t_event = 2 s: at t = 4 s it has walked 3 * 2 = 6 m
    actors, script = make_scene([PED])
    tau = trigger_time(script.trigger, script.trigger_delay, _f(2.0))
    assert float(tau[0]) == 2.0
    s, lat, speed, xy, yaw, active = _pose(script, 0, 4.0, 2.0)
    assert float(s) == pytest.approx(5.0 + 6.0, abs=1e-5)
    np.testing.assert_allclose(xy, [11.0, -20.0], atol=1e-5)
    assert float(speed) == pytest.approx(3.0) and bool(active)
    # through step_actors: still at t = 2 (not yet moved), 6 m further at t = 4
    a = _step(actors, script, _f(2.0), _f(2.0), jnp.zeros(1, jnp.int32), *FAR_EGO)
    assert float(a.s[0]) == pytest.approx(5.0)
    a = _step(a, script, _f(4.0), _f(2.0), jnp.zeros(1, jnp.int32), *FAR_EGO)
    assert float(a.s[0]) == pytest.approx(11.0, abs=1e-5)
    # event still pending: never moves
    a = _step(actors, script, _f(4.0), _f(INF_TIME), jnp.zeros(1, jnp.int32), *FAR_EGO)
    assert float(a.s[0]) == pytest.approx(5.0) and float(a.speed[0]) == 0.0


def test_trigger_time_sources():
    trig = jnp.array([TRIGGER_CLOCK, TRIGGER_EVENT, TRIGGER_EVENT, TRIGGER_NEVER], jnp.int32)
    delay = _f([1.5, 0.5, 0.5, 0.0])
    np.testing.assert_allclose(trigger_time(trig, delay, _f(3.0)), [1.5, 3.5, 3.5, INF_TIME])
    assert float(trigger_time(trig, delay, _f(INF_TIME))[1]) >= INF_TIME / 2


def test_trigger_deadline_fires_before_a_late_source():
    # event source with a 4-s deadline: the event at 3 s triggers at 3 s, one at 6 s (or none)
    # is overtaken by the deadline at 4 s
    trig = jnp.array([TRIGGER_EVENT, TRIGGER_EVENT, TRIGGER_NEVER], jnp.int32)
    delay, deadline = _f([0.0, 0.0, 0.0]), _f([4.0, 4.0, INF_TIME])
    np.testing.assert_allclose(trigger_time(trig, delay, _f(3.0), deadline), [3.0, 3.0, INF_TIME])
    np.testing.assert_allclose(trigger_time(trig, delay, _f(6.0), deadline), [4.0, 4.0, INF_TIME])
    np.testing.assert_allclose(
        trigger_time(trig, delay, _f(INF_TIME), deadline), [4.0, 4.0, INF_TIME]
    )


def test_handover_continues_as_idm_with_its_lateral_offset():
    # A scripted car at 10 m/s changes lane (lat 3.5 m over 2 s) on a clock trigger at 1 s and
    # is handed over 2 s after it, i.e. at t = 3 s with x = 30, lat = 3.5.  A static car stands
    # in the new lane (y = 3.5) at x = 60: as IDM traffic the handed-over car brakes and stops
    # behind it (gap -> s0 = 2 m, half lengths 2 + 2: x -> 54); a car without the hand-over
    # (scripted, constant speed) drives through it.
    lead = dict(y=3.5, s_init=60.0)
    car = dict(v_pre=10.0, v_post=10.0, trigger=TRIGGER_CLOCK, trigger_delay=1.0,
               lat_shift=3.5, lat_duration=2.0, handover_after=2.0)  # fmt: skip
    actors, script = make_scene([car, lead], num_slots=3)
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    k3 = int(round(3.0 / DT)) - 1  # state after the tick ending at t = 3 s
    assert float(tr.s[k3, 0]) == pytest.approx(30.0, abs=0.6)
    np.testing.assert_allclose(np.asarray(tr.lat[k3:, 0]), 3.5, atol=1e-4)  # offset kept
    np.testing.assert_allclose(np.asarray(tr.xy[k3:, 0, 1]), 3.5, atol=1e-3)
    assert float(tr.speed[-1, 0]) < 0.05 and float(tr.xy[-1, 0, 0]) == pytest.approx(54.0, abs=0.5)
    assert np.all(np.asarray(tr.xy[:, 0, 0]) <= 56.0)  # never reaches the leader's box
    scripted = dict(car, handover_after=INF_TIME)
    actors, script = make_scene([scripted, lead], num_slots=3)
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    assert float(tr.xy[-1, 0, 0]) > 200.0  # constant speed, no car following


def test_lane_change_lateral_profile():
    # triggered at tau = 1 s (clock), lat_shift 3.5 m over 2 s at 10 m/s along +x:
    # lat(tau + 1) = 3.5 * smoothstep(0.5) = 1.75; lat(tau + 2) = 3.5; lat(t < tau) = 0.
    # Mid-manoeuvre dlat/dt = 3.5 * 6 * 0.5 * 0.5 / 2 = 2.625 m/s -> yaw = atan(2.625 / 10).
    spec = dict(v_pre=10.0, v_post=10.0, trigger=TRIGGER_CLOCK, trigger_delay=1.0,
                lat_shift=3.5, lat_duration=2.0)  # fmt: skip
    _, script = make_scene([spec])
    for t, lat_want in [(0.5, 0.0), (1.0, 0.0), (2.0, 1.75), (3.0, 3.5), (5.0, 3.5)]:
        s, lat, speed, xy, yaw, _ = _pose(script, 0, t, 1.0)
        assert float(lat) == pytest.approx(lat_want, abs=1e-5)
        np.testing.assert_allclose(xy, [10.0 * t, lat_want], atol=1e-4)
    _, _, speed, _, yaw, _ = _pose(script, 0, 2.0, 1.0)
    assert float(yaw) == pytest.approx(math.atan2(2.625, 10.0), abs=1e-6)
    assert float(speed) == pytest.approx(math.hypot(2.625, 10.0), abs=1e-5)
    _, _, _, _, yaw, _ = _pose(script, 0, 3.5, 1.0)
    assert float(yaw) == pytest.approx(0.0, abs=1e-7)


def test_hold_point_respected():
    # v_pre = 5 from s = 0, hold at s = 10 (reached at 2 s), trigger at 5 s, then v_post = 2
    spec = dict(v_pre=5.0, v_post=2.0, s_hold=10.0, trigger=TRIGGER_CLOCK, trigger_delay=5.0)
    _, script = make_scene([spec])
    for t, s_want, v_want in [(1.0, 5.0, 5.0), (3.0, 10.0, 0.0), (4.99, 10.0, 0.0),
                              (6.0, 12.0, 2.0)]:  # fmt: skip
        s, _, speed, _, _, _ = _pose(script, 0, t, 5.0)
        assert float(s) == pytest.approx(s_want, abs=1e-5)
        assert float(speed) == pytest.approx(v_want, abs=1e-6)


def test_despawn_at_end_and_stop_at_end():
    # v_post = 10 from s = 0 at t = 0, s_end = 20: reaches the end at t = 2
    spec = dict(v_post=10.0, trigger=TRIGGER_CLOCK, s_end=20.0)
    actors, script = make_scene([dict(spec, despawn_at_end=True), dict(spec, y=10.0)])
    for t, active_want in [(1.9, True), (2.0, False), (3.0, False)]:
        s, _, speed, _, _, active = _pose(script, 0, t, 0.0)
        assert bool(active) == active_want
        assert float(s) == pytest.approx(min(10.0 * t, 20.0), abs=1e-5)
    s, _, speed, xy, _, active = _pose(script, 1, 3.0, 0.0)  # no despawn: parked at the end
    assert bool(active) and float(speed) == 0.0 and float(s) == 20.0
    tr = _rollout_actors(actors, script, NO_LIGHTS)
    assert bool(tr.active[30, 0]) and not bool(tr.active[-1, 0]) and bool(tr.active[-1, 1])
    # once despawned the slot is frozen
    assert float(tr.s[-1, 0]) == float(tr.s[40, 0])


def test_scripted_gradients_finite_and_nonzero():
    # pedestrian-like actor on a bent path, triggered by the event at t_event + delay
    pts = _f([[0, 0], [10, 0], [10, 10], [0, 0]])
    valid = jnp.array([True, True, True, False])
    s = pl.arc_length(pts, valid)

    def xy_at(v_pre, v_post, delay, lat_shift, s_init, t_event=2.0, t=4.0):
        tau = trigger_time(jnp.int32(TRIGGER_EVENT), delay, _f(t_event))
        motion = ScriptedMotion(
            s_init=s_init, v_pre=v_pre, v_post=v_post, s_hold=_f(BIG), s_end=_f(30.0),
            lat_shift=lat_shift, lat_duration=_f(2.0), despawn_at_end=jnp.bool_(True),
        )  # fmt: skip
        out = scripted_pose(pts, s, valid, motion, _f(t), tau)
        return out[3]

    args = (_f(1.0), _f(3.0), _f(0.5), _f(1.5), _f(2.0))
    jac = jax.jit(
        jax.jacobian(lambda *a: jnp.sum(xy_at(*a) * _f([1.0, 0.7])), argnums=tuple(range(5)))
    )(*args)
    names = ["v_pre", "v_post", "trigger_delay", "lat_shift", "s_init"]
    for name, g in zip(names, jac, strict=True):
        assert np.isfinite(float(g)) and abs(float(g)) > 1e-3, name
    # d xy / d v_post along the path = (t - tau) * direction = 1.5 m per m/s
    g = jax.jit(jax.grad(lambda v: xy_at(args[0], v, *args[2:])[0]))(args[1])
    assert float(g) == pytest.approx(1.5, abs=1e-5)
    # event pending (t_event = INF_TIME): finite (zero) gradients, no NaN / inf anywhere
    pending = jax.jit(
        jax.jacobian(lambda *a: jnp.sum(xy_at(*a, t_event=_f(INF_TIME))), argnums=tuple(range(5)))
    )(*args)
    assert all(np.isfinite(float(g)) for g in pending)
    assert float(pending[1]) == 0.0 and float(pending[2]) == 0.0
    # with respect to the event time itself (through tau = t_event + delay)
    g = jax.jit(jax.grad(lambda te: jnp.sum(xy_at(*args, t_event=te))))(_f(2.0))
    assert np.isfinite(float(g)) and abs(float(g)) > 1e-3


# ---------------------------------------------------------------------------------------------
# batch and padding invariance
# ---------------------------------------------------------------------------------------------
def _mixed_specs(shift: float):
    return [
        dict(PED, s_init=5.0 + shift),
        dict(
            v_pre=6.0 + shift,
            v_post=8.0,
            trigger=TRIGGER_CLOCK,
            trigger_delay=0.5,
            lat_shift=3.5,
            lat_duration=2.0,
            y=-3.5,
        ),  # fmt: skip
        dict(motion=MOTION_IDM, s_init=10.0, v_pre=12.0, speed=9.0 + shift),
        dict(motion=MOTION_IDM, s_init=30.0 + shift, v_pre=7.0, speed=7.0),
        dict(s_init=90.0, y=0.5),  # static obstacle in the IDM lane
    ]


def test_vmap_equals_single_and_padding_changes_nothing():
    ego = (_f([55.0, 0.2]), _f(0.1), _f(4.0))
    ls = jnp.zeros(1, jnp.int32)

    def f(actors, script):
        return step_actors(actors, script, _f(1.5), _f(1.0), ls, *ego)

    scenes = [make_scene(_mixed_specs(k), num_slots=8) for k in range(3)]
    batch_a = tree_stack([a for a, _ in scenes])
    batch_s = tree_stack([s for _, s in scenes])
    out = jax.jit(jax.vmap(f))(batch_a, batch_s)
    single = jax.jit(f)
    for i, (a, s) in enumerate(scenes):
        one = single(a, s)
        for x, y in zip(jax.tree.leaves(tree_index(out, i)), jax.tree.leaves(one), strict=True):
            np.testing.assert_array_equal(x, y)

    # padding: the same 5 actors with no padding vs with 3 junk padding slots
    a5, s5 = make_scene(_mixed_specs(0))
    a8, s8 = scenes[0]
    out5, out8 = single(a5, s5), single(a8, s8)
    for x5, x8, before in zip(
        jax.tree.leaves(out5), jax.tree.leaves(out8), jax.tree.leaves(a8), strict=True
    ):
        np.testing.assert_array_equal(x5, x8[:5])
        np.testing.assert_array_equal(x8[5:], before[5:])  # padding untouched (NaN included)
    assert _finite(jax.tree.map(lambda x: x[:5], out8))
    # gradients through a padded scene (NaN-filled padding) with respect to the script are finite
    names = ("path", "s_init", "v_pre", "v_post", "trigger_delay", "lat_shift", "lat_duration")

    def hazard_y(floats):
        out = step_actors(a8, s8.replace(**floats), _f(1.5), _f(1.0), ls, *ego)
        return out.xy[1, 1] + jnp.sum(jnp.where(s8.valid[:, None], out.xy, 0.0))

    grads = jax.jit(jax.grad(hazard_y))({k: getattr(s8, k) for k in names})
    assert _finite(grads)  # NaN padding included: masked on the input, not only the output
    assert abs(float(grads["v_post"][1])) > 1e-3 and abs(float(grads["lat_shift"][1])) > 1e-3
    # moving along: the IDM actors did something, the scene is consistent
    assert float(out8.s[2]) > 10.0 and float(out8.lat[1]) > 0.0
