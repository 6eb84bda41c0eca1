"""Scenario families, road builder, warnings and parameter specs."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import (
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    FAMILIES,
    INF_TIME,
    MOTION_IDM,
    MOTION_SCRIPTED,
    OCC_BUILDING,
    OCC_PARKED_VEHICLE,
    OCC_WALL,
    ROLE_BACKGROUND,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    TRIGGER_CLOCK,
    TRIGGER_EVENT,
    TRIGGER_NEVER,
    WEATHERS,
)
from lantern_jax.dynamics.scripted import ScriptedMotion, scripted_pose, trigger_time
from lantern_jax.scenarios import road as rd
from lantern_jax.scenarios import road_junction as rj
from lantern_jax.scenarios.duplicates import near_duplicate, resample_route, route_samples
from lantern_jax.scenarios.families import build_pair, sample_params, validate_params
from lantern_jax.scenarios.families_common import FLOW_SLOTS, boxes_overlap
from lantern_jax.scenarios.families_junction import CLEAR_TARGET, SPAWN_OFFSET
from lantern_jax.scenarios.premise import premise_error
from lantern_jax.scenarios.road_straight import Centerline, StraightLayout, straight_road
from lantern_jax.scenarios.spec import (
    PARAM_RANGES,
    WEATHER_PROFILES,
    canonical_json,
    content_hash,
)
from lantern_jax.scenarios.warnings import (
    DEFAULT_BANK,
    TEMPLATES,
    TOKEN,
    ground_position,
    render_warning,
)
from lantern_jax.types.world import pad_rows, tree_stack

SEEDS = st.integers(0, 2**32 - 1)
WEATHER = st.sampled_from(WEATHERS)
PROP = settings(
    max_examples=20, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)


def make_pair(family: str, seed: int, weather: str = "clear_day"):
    params = sample_params(family, np.random.default_rng(seed), weather)
    return (params, *build_pair(params))


def np_tree(tree):
    return jax.tree.map(np.asarray, tree)


def route_np(world):
    v = np.asarray(world.route.valid)
    return np.asarray(world.route.xy, np.float64)[v]


def lane_polylines(world):
    out = []
    for i in np.flatnonzero(np.asarray(world.lanes.valid)):
        pv = np.asarray(world.lanes.point_valid[i])
        pts = np.asarray(world.lanes.center[i], np.float64)[pv]
        out.append((pts, float(world.lanes.width[i]), int(world.lanes.kind[i])))
    return out


def actor_box(scenario, i):
    a, ext = scenario.actors0, scenario.actors.extent
    return (np.asarray(a.xy[i], np.float64), float(a.yaw[i]), tuple(np.asarray(ext[i])))


# ------------------------------------------------------------------------------------------------
# property tests over seeds, every family
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("family", FAMILIES)
@PROP
@given(seed=SEEDS, weather=WEATHER)
def test_pair_is_valid_and_matched(family, seed, weather):
    params, wa, wb, meta = make_pair(family, seed, weather)
    wa.validate()
    wb.validate()
    a, b = np_tree(wa), np_tree(wb)
    pa = a.config

    # markers: order (equality of warn/event only for RTY), on the route, 29 m of recovery
    s_warn, s_event, s_conf = float(pa.s_warn), float(pa.s_event), float(pa.s_conflict)
    length = float(a.route.length)
    assert 0.0 <= s_warn <= s_event <= s_conf <= length
    assert (s_warn == s_event) == (family == "RTY")
    assert length - s_conf >= 29.0 - 1e-3
    lo, hi = PARAM_RANGES[family]["route_length"].lo, PARAM_RANGES[family]["route_length"].hi
    assert lo - 1e-3 <= length <= hi + 1e-3
    # 2-m chords of a curve of radius >= 70 m are shorter than its arc by at most
    # L (2 / 70)^2 / 24 = 5 mm over 164 m; OR's corner (radius R, arc A) adds A (2 / R)^2 / 24
    tol = 6e-3
    if family == "OR":
        r = params["turn_radius"]
        tol += math.radians(params["turn_angle"]) * r * (rd.ROUTE_SPACING / r) ** 2 / 24.0
    assert abs(length - params["route_length"]) < tol
    route = route_np(wa)
    _, d = rd.project(route, meta["conflict_xy"])
    assert d < 1.0
    spacing = np.diff(np.asarray(a.route.s)[np.asarray(a.route.valid)])
    assert spacing.max() <= rd.ROUTE_SPACING + 1e-4 and spacing.min() > 0.5

    # A/B agreement: everything but the route flag, the warning flag and the scenario slots
    for name in ("route", "lanes", "occluders", "lights", "ego0"):
        for x, y in zip(
            jax.tree.leaves(getattr(a, name)), jax.tree.leaves(getattr(b, name)), strict=True
        ):
            np.testing.assert_array_equal(x, y, err_msg=name)
    for f in type(pa).__dataclass_fields__:
        x, y = getattr(pa, f), getattr(b.config, f)
        if f in ("is_route_a", "warning_enabled"):
            assert bool(x) and not bool(y)
        else:
            np.testing.assert_array_equal(x, y, err_msg=f)
    assert float(pa.friction) == 1.0 == WEATHER_PROFILES[weather].friction  # CARLA weather
    assert float(pa.sensing_range) == np.float32(WEATHER_PROFILES[weather].sensing_range)
    scen = meta["scenario_slots"]
    others = np.setdiff1d(np.arange(rd.MAX_ACTORS), scen)
    differs = np.zeros(rd.MAX_ACTORS, bool)
    for part in ("actors", "actors0"):
        for x, y in zip(
            jax.tree.leaves(getattr(a, part)), jax.tree.leaves(getattr(b, part)), strict=True
        ):
            np.testing.assert_array_equal(x[others], y[others], err_msg=part)
            neq = x != y
            differs |= neq.reshape(neq.shape[0], -1).any(axis=1)
    assert differs[int(pa.hazard_index)] and differs[scen].all()
    assert int(a.actors.role[int(pa.hazard_index)]) == ROLE_HAZARD
    assert bool(a.actors.valid[int(pa.hazard_index)])

    # ExecutionConfig conventions
    assert int(pa.family) == FAMILIES.index(family) == int(pa.template_id) == int(pa.text_id)
    assert bool(pa.force_event) == (family != "RTY")
    assert float(pa.force_delay) == 2.0
    assert float(pa.d_safe) == (2.0 if family in ("PE", "OR") else 3.0)
    assert float(pa.timeout_s) == pytest.approx(20.0 + length / 3.0, rel=1e-6)
    assert not bool(pa.late_onset) and float(pa.pos_noise_m) == 0.0
    if meta["signalized"]:
        assert int(pa.ego_light) == 0
        assert float(pa.ego_stop_s) == pytest.approx(params["approach"] - 2.0, abs=1e-4)
    else:
        assert int(pa.ego_light) == -1 and float(pa.ego_stop_s) >= 1e5

    for w in (a, b):
        _check_initial_state(w, route)
        _check_background(w, meta)
        _check_occluders(w, route)


def _check_initial_state(w, route):
    """Ego at the route start on a lane centre; actors at their closed-form t = 0 state."""
    np.testing.assert_allclose(w.ego0.xy, route[0], atol=1e-4)
    d = route[1] - route[0]
    assert abs(math.remainder(float(w.ego0.yaw) - math.atan2(d[1], d[0]), 2 * math.pi)) < 1e-5
    assert float(w.ego0.speed) == pytest.approx(float(w.config.v_ref))
    assert float(w.ego0.steer) == 0.0 and float(w.ego0.accel) == 0.0
    lanes = lane_polylines(w)
    # on a lane centre line, to the sagitta of its (<= 6.1 m) chords on a >= 70 m radius
    assert min(rd.project(c, route[0])[1] for c, _, _ in lanes) < 0.07
    for p in route:  # the ego route always lies inside some lane
        assert any(rd.project(c, p)[1] <= wd / 2 + 1e-3 for c, wd, k in lanes if k != 1)
    a, sc = w.actors0, w.actors
    np.testing.assert_array_equal(a.active, sc.valid)
    for i in np.flatnonzero(sc.valid):
        path = np.asarray(sc.path[i], np.float64)[np.asarray(sc.path_valid[i])]
        s0 = float(a.s[i])
        np.testing.assert_allclose(a.xy[i], rd.point_at(path, s0), atol=1e-3)
        dyaw = math.remainder(float(a.yaw[i]) - rd.heading_at(path, s0), 2 * math.pi)
        assert abs(dyaw) < 1e-4
        assert float(a.lat[i]) == 0.0
        if int(sc.motion[i]) == MOTION_IDM:
            assert float(a.speed[i]) == float(sc.v_pre[i]) and s0 == float(sc.s_init[i])
        elif int(sc.trigger[i]) == TRIGGER_CLOCK and float(sc.trigger_delay[i]) == 0.0:
            assert float(a.speed[i]) == float(sc.v_post[i])
        else:
            assert s0 == min(float(sc.s_init[i]), float(sc.s_hold[i]))
            assert float(a.speed[i]) == float(sc.v_pre[i])


def _check_occluders(w, route):
    """Occluders: finite boxes of known kinds, clear of the route corridor (outline every 0.25 m
    at least ego half width + 0.5 m from the route)."""
    occ = w.occluders
    for k in np.flatnonzero(occ.valid):
        box = rd.OccluderSpec(
            np.asarray(occ.center[k], np.float64),
            float(occ.yaw[k]),
            tuple(np.asarray(occ.extent[k], np.float64)),
            int(occ.kind[k]),
        )
        assert int(occ.kind[k]) in (OCC_BUILDING, OCC_WALL, OCC_PARKED_VEHICLE)
        clearance = rd.distances_to_polyline(rd._box_outline(box), route).min()
        assert clearance >= EGO_HALF_WIDTH + 0.5 - 1e-3


def _check_background(w, meta):
    """Background traffic: IDM, 7-11 m/s, off the ego's lanes, no overlap at t = 0."""
    sc = w.actors
    bg = np.flatnonzero(sc.valid & (sc.role == ROLE_BACKGROUND))
    assert len(bg) == meta["num_background"] <= 5
    ego = (np.asarray(w.ego0.xy, np.float64), float(w.ego0.yaw), (2.4508, 1.0642))
    route = route_np(w)
    for i in bg:
        assert int(sc.motion[i]) == MOTION_IDM
        assert 7.0 <= float(sc.v_pre[i]) <= 11.0
        box = actor_box(w, i)
        assert not boxes_overlap(box, ego)
        for j in np.flatnonzero(sc.valid):
            assert j == i or not boxes_overlap(box, actor_box(w, j))
        # never in the ego's lane ahead: no point of its remaining path runs along the route
        path = np.asarray(sc.path[i], np.float64)[np.asarray(sc.path_valid[i])]
        s_path = rd.arc_length(path)
        for s in np.linspace(float(w.actors0.s[i]), s_path[-1], 12):
            p = rd.point_at(path, s)
            s_r, dist = rd.project(route, p)
            along = abs(
                math.remainder(rd.heading_at(path, s) - rd.heading_at(route, s_r), 2 * math.pi)
            )
            assert not (dist < 1.8 and along < math.radians(35)), "background in ego corridor"
    for i in np.flatnonzero(sc.valid & (sc.motion == MOTION_SCRIPTED)):
        assert int(sc.role[i]) != ROLE_BACKGROUND
    valid = np.flatnonzero(sc.valid)
    for i in valid:  # nothing starts overlapping the ego or another actor
        assert not boxes_overlap(actor_box(w, i), ego)
        assert not any(boxes_overlap(actor_box(w, i), actor_box(w, j)) for j in valid if j > i)


# ------------------------------------------------------------------------------------------------
# geometry details
# ------------------------------------------------------------------------------------------------
def test_vc_nominal_gap_at_event():
    params, wa, _, meta = make_pair("VC", 7)
    v_ref, v_cut = params["v_ref"], meta["canonical"]["v_cut"]
    assert v_cut == pytest.approx(max(6.5, params["cut_frac"] * v_ref))
    t_event = float(wa.config.s_event) / v_ref  # ego at v_ref from arc 0
    gap = 21.0 - (v_ref - v_cut) * t_event
    assert gap == pytest.approx(params["gap_event"], abs=1e-3)
    assert float(wa.config.s_conflict) - float(wa.config.s_event) == pytest.approx(4.0, abs=1e-4)


def test_rty_conflict_is_corridor_entry():
    # C = the first route arc where the ego centre comes within EGO_HALF_LENGTH + car half
    # width + 0.5 = 3.9508 m of the cross lane (the first flow vehicle's path)
    params, wa, wb, meta = make_pair("RTY", 11)
    route = route_np(wa)
    sc = wa.actors
    path = np.asarray(sc.path[0], np.float64)[np.asarray(sc.path_valid[0])]
    thr = EGO_HALF_LENGTH + 1.0 + 0.5
    s_c = float(wa.config.s_conflict)
    d = lambda s: float(rd.distances_to_polyline(rd.point_at(route, [s]), path)[0])  # noqa: E731
    assert d(s_c) <= thr + 1e-3 and d(s_c - 0.06) > thr
    assert all(d(s) > thr for s in np.linspace(0.0, s_c - 0.05, 50))
    near_s, _ = rd.project(path, meta["conflict_xy"])
    assert near_s == pytest.approx(params["source_dist"], abs=0.1)
    assert float(wa.config.clear_s) == pytest.approx(params["source_dist"] + 2.3 + 5.0, abs=1e-3)
    assert int(wb.actors.trigger[0]) == TRIGGER_NEVER and float(wb.actors0.speed[0]) == 0.0
    np.testing.assert_allclose(wa.actors0.xy[0], wb.actors0.xy[0], atol=1e-5)


@pytest.mark.parametrize("family", ["LWW", "RWW"])
@pytest.mark.parametrize("seed", [3, 11])
def test_wrong_way_path_is_the_reversed_route(family, seed):
    # The wrong-way car follows the ego route backwards: its path equals the route polyline
    # between C - clearance target and C + spawn offset, reversed, every vertex in between.
    params, wa, wb, meta = make_pair(family, seed)
    route = route_np(wa)
    sc = wa.actors
    path = np.asarray(sc.path[0], np.float64)[np.asarray(sc.path_valid[0])]
    s_c = float(wa.config.s_conflict)
    off, clear = SPAWN_OFFSET[family], CLEAR_TARGET[family]
    want = rd.segment(route, s_c - clear, s_c + off)[::-1]
    np.testing.assert_allclose(path, want, atol=1e-4)  # float32 storage
    # every path point lies on the route, and the path runs against it
    assert rd.distances_to_polyline(path, route).max() < 1e-3
    s_route = np.array([rd.project(route, q)[0] for q in path])
    assert np.all(np.diff(s_route) < 0)
    # spawn: 25 m (LWW) / 20 m (RWW) before C along the path; removed once past C (own arc)
    s_near, _ = rd.project(path, meta["conflict_xy"])
    assert s_near == pytest.approx(off, abs=1e-3)
    assert float(wa.config.clear_s) == pytest.approx(off)
    assert bool(wa.config.despawn_on_clear) and int(sc.trigger[0]) == TRIGGER_EVENT
    assert 7.0 <= float(sc.v_post[0]) <= 9.0 and float(sc.v_pre[0]) == 0.0
    # Route B: the same car at the same place in the legal direction, handed to the IDM
    np.testing.assert_allclose(wa.actors0.xy[0], wb.actors0.xy[0], atol=1e-3)
    dyaw = math.remainder(float(wa.actors0.yaw[0]) - float(wb.actors0.yaw[0]), 2 * math.pi)
    # opposite headings, up to the angle between the route chords on either side of the spawn
    # point (2-m chords on a turn of radius >= 8 m: < 0.25 rad)
    assert abs(abs(dyaw) - math.pi) < 0.25
    assert int(wb.actors.motion[0]) == MOTION_IDM
    assert float(wb.actors0.speed[0]) == pytest.approx(params["actor_speed"])


def test_rty_flow_spacing_is_the_source_interval():
    for seed in range(6):
        params, wa, wb, meta = make_pair("RTY", seed)
        sc = wa.actors
        n = params["flow_size"]
        slots = [0, *FLOW_SLOTS[: n - 1]]
        assert all(bool(sc.valid[i]) for i in slots)
        assert not any(bool(sc.valid[i]) for i in FLOW_SLOTS[n - 1 :])
        assert not any(bool(wb.actors.valid[i]) for i in FLOW_SLOTS)  # Route B: one stand-in
        starts = np.asarray(wa.actors0.xy, np.float64)[slots]
        gaps = np.linalg.norm(np.diff(starts, axis=0), axis=1)
        rng = PARAM_RANGES["RTY"]["source_interval"]
        lo, hi = rng.lo, rng.hi
        assert np.all(gaps <= params["source_interval"] + 1e-3)  # chords of the lane
        assert np.all(gaps >= params["source_interval"] - 0.2)
        assert lo <= params["source_interval"] <= hi
        for i in slots:  # all wait for the event, then drive at the flow speed
            assert int(sc.trigger[i]) == TRIGGER_EVENT and float(sc.v_pre[i]) == 0.0
            assert float(sc.v_post[i]) == pytest.approx(params["actor_speed"])
        assert [int(sc.role[i]) for i in slots] == [ROLE_HAZARD] + [ROLE_CONTEXT] * (n - 1)


@pytest.mark.parametrize("seed", range(4))
def test_or_van_never_slows_before_the_event_and_never_touches_the_object(seed):
    # Closed-form van on Route A with the event never happening (the worst case: only its
    # guard, the trigger deadline, starts the lane change): speed never below the lead speed,
    # and the van's box never overlaps the object's box.
    params, wa, _, meta = make_pair("OR", seed)
    sc = wa.actors
    v_lead = params["lead_speed_kmh"] / 3.6
    van = jax.tree.map(lambda x: x[1], ScriptedMotion.of(sc))
    pose = jax.jit(lambda t, tau: scripted_pose(
        sc.path[1], sc.path_s[1], sc.path_valid[1], van, t, tau))  # fmt: skip
    tau = trigger_time(sc.trigger[1], sc.trigger_delay[1], jnp.float32(INF_TIME),
                       sc.trigger_deadline[1])  # fmt: skip
    assert float(tau) == pytest.approx((params["reveal_s"] - params["lead_gap"]) / v_lead, 1e-4)
    obj = actor_box(wa, 0)
    for t in np.arange(0.0, float(tau) + 8.0, 0.05):
        s, lat, speed, xy, yaw, _ = pose(jnp.float32(t), tau)
        assert float(speed) >= v_lead - 1e-4
        van = (np.asarray(xy, np.float64), float(yaw), tuple(np.asarray(sc.extent[1])))
        assert not boxes_overlap(van, obj), f"van touches the object at t = {t:.2f}"
    # an earlier event starts the lane change earlier (never later than the guard)
    early = trigger_time(sc.trigger[1], sc.trigger_delay[1], jnp.float32(1.0),
                         sc.trigger_deadline[1])  # fmt: skip
    assert float(early) == pytest.approx(min(1.0, float(tau)))


def test_premise_rule_rejects_a_visible_hazard():
    params, wa, _, meta = make_pair("PE", 0)
    assert premise_error(wa, meta) is None or "premise" in premise_error(wa, meta)
    # the same pair without its occluders: the pedestrian stands in plain view
    bare = wa.replace(occluders=wa.occluders.replace(valid=jnp.zeros_like(wa.occluders.valid)))
    assert "premise violated" in premise_error(bare, meta)
    # VC's cut-in car is meant to be visible: the rule does not apply
    _, wv, _, mv = make_pair("VC", 0)
    assert premise_error(wv, mv) is None


def test_near_duplicate_rule_catches_rotated_copies():
    _, wa, _, _ = make_pair("LWW", 3)
    r = route_samples(wa)
    arcs = np.array([rd.project(route_np(wa), q)[0] for q in r])  # every 2 m of route arc
    np.testing.assert_allclose(np.diff(arcs)[:-1], 2.0, atol=1e-4)
    a = math.radians(73.0)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    copy = r @ rot.T + np.array([120.0, -45.0])
    assert near_duplicate(r, copy) and near_duplicate(copy, r)
    # a 2-m lateral offset of the whole route is still a near duplicate (within 3 m)
    assert near_duplicate(r, r + np.array([0.0, 2.0]) @ rot.T)
    # a straight road of the same length is not; nor is the route's first half alone
    line = resample_route(np.array([[0.0, 0.0], [float(wa.route.length), 0.0]]))
    assert not near_duplicate(r, line)
    assert not near_duplicate(r, r[: len(r) // 2])


def test_signal_plan_red_then_green():
    road = rj.junction(rj.JunctionShape(4, None, 2, 3.5, 7.0), True, ego_red_s=4.5)
    ego, cross = road.lights
    cycle = ego.green + ego.yellow + ego.red

    def state(light, t):
        ph = (t + light.offset) % cycle
        return 0 if ph < light.green else (1 if ph < light.green + light.yellow else 2)

    assert [state(ego, t) for t in (0.0, 4.4, 4.6, 60.0, 94.0)] == [2, 2, 0, 0, 0]
    assert [state(cross, t) for t in (0.0, 1.4, 1.6, 4.6, 90.0)] == [0, 0, 1, 2, 2]
    for t in np.linspace(0, 120, 2401):  # never green together
        assert not (state(ego, t) == 0 and state(cross, t) == 0)


def test_right_turn_is_concentric_with_the_kerb_and_drivable():
    # perpendicular arms, 2 lanes of 3.5 m, kerb radius 7: box edge at 7 + 7 = 14 m; the outer
    # right turn is a quarter circle about the fillet centre (14, -14), radius 7 + 1.75 = 8.75
    road = rj.junction(rj.JunctionShape(4, None, 2, 3.5, 7.0))
    name = rj.add_connector(road, "S", 1, "E", 1)
    pts = road.lane(name).center
    np.testing.assert_allclose(np.linalg.norm(pts - np.array([14.0, -14.0]), axis=1), 8.75,
                               atol=1e-9)  # fmt: skip
    assert 8.75 > 2.85 / math.tan(0.3685)  # ego minimum turning radius
    # skewed exit (E rotated 15 deg): still an arc of radius kerb + half a lane about its fillet
    road = rj.junction(rj.JunctionShape(4, None, 2, 3.5, 7.0, {"E": 15.0}))
    pts = road.lane(rj.add_connector(road, "S", 1, "E", 1)).center
    c = rj.corner_between(road, "S", "E")
    r = np.linalg.norm(pts - c.fillet_centre, axis=1)
    assert r.min() == pytest.approx(8.75, abs=1e-6) and rj.min_turn_radius(pts) > 8.7


def test_worlds_batch_across_families():
    worlds = []
    for fam in FAMILIES:
        _, wa, wb, _ = make_pair(fam, 3)
        worlds += [wa, wb]
    batch = tree_stack(worlds)
    assert batch.actors0.xy.shape == (12, rd.MAX_ACTORS, 2)
    assert batch.actors.path.shape == (12, rd.MAX_ACTORS, rd.PATH_POINTS, 2)
    assert batch.lanes.center.shape == (12, rd.MAX_LANES, rd.LANE_POINTS, 2)
    assert batch.route.xy.shape == (12, rd.ROUTE_POINTS, 2)
    assert batch.lights.valid.shape == (12, rd.MAX_LIGHTS)
    assert batch.config.noise_seed.dtype == jnp.uint32
    assert batch.actors.kind.dtype == jnp.int32 and batch.actors.valid.dtype == jnp.bool_


def test_build_is_deterministic():
    p1 = sample_params("LWW", np.random.default_rng(42), "dusk")
    p2 = sample_params("LWW", np.random.default_rng(42), "dusk")
    assert p1 == p2
    a1, b1, _ = build_pair(p1)
    a2, b2, _ = build_pair(dict(p2))
    for x, y in zip(jax.tree.leaves((a1, b1)), jax.tree.leaves((a2, b2)), strict=True):
        np.testing.assert_array_equal(x, y)


# ------------------------------------------------------------------------------------------------
# parameter validation and hashing
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("family", FAMILIES)
def test_out_of_range_params_are_rejected(family):
    params = sample_params(family, np.random.default_rng(1))
    hi = PARAM_RANGES[family]["route_length"].hi
    bad = dict(params, route_length=hi + 15.0)
    with pytest.raises(ValueError, match=rf"^{family}\.route_length: .* outside \["):
        validate_params(bad)
    with pytest.raises(ValueError, match=rf"{family}\.route_length"):
        build_pair(bad)
    with pytest.raises(ValueError, match=rf"{family}\.v_ref: 0\.5 outside"):
        validate_params(dict(params, v_ref=0.5))
    with pytest.raises(ValueError, match=rf"{family}\.weather"):
        validate_params(dict(params, weather="fog"))
    with pytest.raises(ValueError, match=rf"{family}\.bogus: unknown"):
        validate_params(dict(params, bogus=1))
    missing = dict(params)
    del missing["seed"]
    with pytest.raises(ValueError, match=rf"{family}\.seed: missing"):
        validate_params(missing)


def test_error_message_format_and_feasibility():
    params = sample_params("PE", np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"^PE\.route_length: 150\.0 outside \[68, 135\]$"):
        validate_params(dict(params, route_length=150.0))
    with pytest.raises(ValueError, match=r"PE\.route_length: .* too short"):
        validate_params(dict(params, conflict_s=45.0, route_length=70.0))
    with pytest.raises(ValueError, match=r"^family: "):
        validate_params(dict(params, family="XX"))
    lww = sample_params("LWW", np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"LWW\.missing_arm"):
        validate_params(dict(lww, num_arms=3, missing_arm="W"))
    with pytest.raises(ValueError, match=r"LWW\.approach"):
        validate_params(dict(lww, signalized=True, approach=13.0))
    with pytest.raises(ValueError, match=r"OR\.reveal_s"):
        p_or = sample_params("OR", np.random.default_rng(0))
        validate_params(dict(p_or, lead_gap=25.0, reveal_s=31.0))


def test_content_hash_stable_and_distinct():
    params = sample_params("RTY", np.random.default_rng(5), "wet_day")
    h = content_hash(params)
    assert h == content_hash(dict(reversed(list(params.items()))))  # key order irrelevant
    # exact values: any change that can build a different world changes the hash
    assert h != content_hash(dict(params, v_ref=params["v_ref"] + 1e-9))
    assert h != content_hash(dict(params, v_ref=params["v_ref"] + 1e-3))
    fixed = {"family": "PE", "b": 1.23456789, "a": [1, True, None, "x"], "c": -0.0}
    assert canonical_json(fixed) == '{"a":[1,true,null,"x"],"b":1.23456789,"c":0.0,"family":"PE"}'
    assert content_hash(fixed) == content_hash(dict(fixed))
    hashes = set()
    for fam in FAMILIES:
        for seed in range(4):
            p, _, _, meta = make_pair(fam, seed)
            assert meta["content_hash"] == content_hash(p)
            hashes.add(meta["content_hash"])
    assert len(hashes) == 4 * len(FAMILIES)


# ------------------------------------------------------------------------------------------------
# warnings
# ------------------------------------------------------------------------------------------------
def test_ground_position_hand_case():
    # ego at (10, 0) heading north; hazard at (12, 5): d = (2, 5) -> 5 m ahead, 2 m to the right
    out = ground_position(jnp.array([12.0, 5.0]), jnp.array([10.0, 0.0]), jnp.float32(math.pi / 2))
    np.testing.assert_allclose(out, [5.0, 2.0], atol=1e-5)
    # heading east, hazard ahead-left: (3, 4) -> 3 ahead, -4 (left)
    out = jax.jit(ground_position)(jnp.array([3.0, 4.0]), jnp.zeros(2), jnp.float32(0.0))
    np.testing.assert_allclose(out, [3.0, -4.0], atol=1e-6)
    batch = jax.vmap(ground_position)(
        jnp.array([[12.0, 5.0], [3.0, 4.0]]), jnp.array([[10.0, 0.0], [0.0, 0.0]]),
        jnp.array([math.pi / 2, 0.0]),
    )  # fmt: skip
    np.testing.assert_allclose(batch, [[5.0, 2.0], [3.0, -4.0]], atol=1e-5)


def test_render_warning_exact():
    assert (
        render_warning(0, (14.2, 3.1))
        == "The pedestrian at position (14.2, 3.1) is about to enter the ego lane."
    )
    assert render_warning(3, jnp.array([5.0, -2.04])) == (
        "A wrong-way vehicle at position (5.0, -2.0) will cross the ego left-turn path. "
        "Yield before turning left."
    )
    assert render_warning(1, (0.04, -0.04)) == (
        "The vehicle at position (0.0, 0.0) will cut into the ego lane soon."
    )
    with pytest.raises(ValueError, match="text_id"):
        render_warning(len(DEFAULT_BANK) + 100, (0.0, 0.0))


def test_text_bank_canonical_ids():
    assert len(TEMPLATES) == 6
    for i in range(len(FAMILIES)):
        e = DEFAULT_BANK[i]
        assert (e.text_id, e.family, e.kind) == (i, i, "canonical")
        assert e.text == TEMPLATES[i] and e.text.count(TOKEN) == 1
    assert TEMPLATES[5] == (
        "The vehicle at position <FRONT_CAR_POS> will cross the ego right-turn path. "
        "Yield before turning right."
    )


def test_route_b_controls():
    # PE: pedestrian slot empty; the truck is part of the map (an occluder) on both routes
    _, wa, wb, _ = make_pair("PE", 2)
    assert bool(wa.actors.valid[0]) and not bool(wb.actors.valid[0])
    assert int(wa.occluders.kind[0]) == int(wb.occluders.kind[0]) == OCC_PARKED_VEHICLE
    # VC: merges and is handed to the IDM on A; the same car as IDM traffic on B, never merging
    params, wa, wb, _ = make_pair("VC", 2)
    w = params["lane_width"]
    assert float(wa.actors.lat_shift[0]) == pytest.approx(w) and float(wb.actors.lat_shift[0]) == 0
    assert float(wa.actors.handover_after[0]) == pytest.approx(2.0)
    assert int(wb.actors.trigger[0]) == TRIGGER_NEVER and int(wb.actors.motion[0]) == MOTION_IDM
    assert float(wb.actors.v_pre[0]) == float(wa.actors.v_pre[0]) == float(wb.actors.v_post[0])
    np.testing.assert_array_equal(wa.actors0.xy[0], wb.actors0.xy[0])
    # OR: no object; the van keeps leading (no hold, no lane change, never triggered)
    _, wa, wb, _ = make_pair("OR", 2)
    assert bool(wa.actors.valid[0]) and not bool(wb.actors.valid[0])
    assert float(wa.actors.s_hold[1]) >= 1e5 and float(wa.actors.trigger_deadline[1]) < 100.0
    assert float(wb.actors.lat_shift[1]) == 0.0 and int(wb.actors.trigger[1]) == TRIGGER_NEVER
    assert float(wb.actors.trigger_deadline[1]) >= INF_TIME / 2
    # RTY: a stationary context vehicle
    _, wa, wb, _ = make_pair("RTY", 2)
    assert int(wb.actors.role[0]) == ROLE_CONTEXT and int(wb.actors.trigger[0]) == TRIGGER_NEVER
    assert float(wb.actors.v_pre[0]) == float(wb.actors.v_post[0]) == 0.0


def test_meta_is_json_and_describes_the_pair():
    for fam in FAMILIES:
        params, wa, _, meta = make_pair(fam, 9)
        again = json.loads(json.dumps(meta))
        assert again["family"] == fam and again["params"] == json.loads(json.dumps(params))
        assert meta["s_conflict"] == pytest.approx(float(wa.config.s_conflict), abs=1e-4)
        assert meta["lanes"] and meta["route_lanes"][0] in meta["lanes"]


def test_road_helpers():
    layout = StraightLayout(2, 1, 3.5, 1, 2.5)
    line = Centerline.two_piece(0.0, 0.0, 50.0)
    road = straight_road(layout, line, 0.0, 100.0)
    assert road.names == ["fwd_0", "fwd_1", "back_0", "shoulder"]
    assert road.lane("shoulder").kind == rd.LANE_SHOULDER and road.lane("shoulder").width == 2.5
    # ego in fwd_1 at d = 0: fwd_0 at +3.5, back_0 at +7 running from x = 100, shoulder at -3
    np.testing.assert_allclose(road.lane("back_0").center[0], [100.0, 7.0], atol=1e-9)
    np.testing.assert_allclose(road.lane("shoulder").center[0], [0.0, -3.0], atol=1e-9)
    # a 1/50 m left curve after 20 m: heading 20/50 rad at arc 40, radius 50 about (20, 50)
    bent = Centerline.two_piece(0.0, 0.02, 20.0)
    xy, th = bent.pose(np.array([10.0, 40.0]))
    np.testing.assert_allclose(xy[0], [10.0, 0.0], atol=1e-12)
    assert th[1] == pytest.approx(0.4)
    assert np.linalg.norm(xy[1] - [20.0, 50.0]) == pytest.approx(50.0)
    j = rj.junction(rj.JunctionShape(3, "N", 2, 3.5, 7.0), True)
    assert rj.inbound_lane(j, "S", 0)[0] == "S_in_0" and rj.outbound_lane(j, "E", 1)[0] == "WE_1"
    assert [rj.turn_direction("S", x) for x in ("W", "E", "N")] == ["left", "right", "straight"]
    with pytest.raises(ValueError, match="not a turn"):
        rj.turn_route(j, "S", 0, "N", 0, 20.0, 60.0)
    j4 = rj.junction(rj.JunctionShape(4, None, 2, 3.5, 7.0), True)
    assert j4.half_size == pytest.approx(14.0)
    left = rj.turn_route(j4, "S", 0, "W", 0, 20.0, 70.0)
    assert left.length == pytest.approx(70.0) and left.lanes[1] == "S0>W0"
    assert left.stop_s == pytest.approx(18.0)
    assert j4.lane("S0>W0").kind == rd.LANE_CONNECTOR
    assert len(j4.lanes) <= rd.MAX_LANES
    # a corner building keeps its set-back from both kerbs: perpendicular SW corner, kerb
    # radius 7, set-back 2: its inner corner lies 5 m from the fillet centre (-14, -14) along
    # the diagonal, i.e. at -14 + 5/sqrt(2) = -10.464 on both axes
    c = rj.corner_between(j4, "W", "S")
    (b,) = rj.corner_occluders(j4, c, OCC_BUILDING, 2.0, 12.0, 7.0)
    corners = rd._box_outline(b)
    assert corners[:, 0].max() == pytest.approx(-14.0 + 5.0 / math.sqrt(2.0))
    assert corners[:, 1].max() == pytest.approx(-14.0 + 5.0 / math.sqrt(2.0))
    walls = rj.corner_occluders(j4, c, OCC_WALL, 2.0, 12.0, 7.0)
    assert [w.kind for w in walls] == [OCC_WALL, OCC_WALL]
    j4.occluders = [b, *walls]
    assert rd.occluder_intrusions(j4, left.xy) == []
    # corridor entry on a straight line crossing y = 0 at 45 degrees
    line45 = np.array([[0.0, -10.0], [10.0, 0.0]])
    s = rd.corridor_entry(line45, (0.0, 0.0), (1.0, 0.0), 2.0)
    assert s == pytest.approx(8.0 * math.sqrt(2.0))


@pytest.mark.parametrize("seed", range(6))
def test_or_road_is_straight_to_the_object_then_turns_the_corner(seed):
    # The route (start-pose frame) runs along +x with no lateral offset up to 2 m past the
    # object, then turns by turn_angle to turn_side at turn_radius (the corner's end heading).
    from lantern_jax.scenarios.families_straight import OR_STRAIGHT_AFTER, or_centerline

    params, wa, _, _ = make_pair("OR", seed)
    line = or_centerline(params)
    s_b = params["reveal_s"] + params["object_ahead"] + OR_STRAIGHT_AFTER
    s = np.linspace(-20.0, s_b, 200)
    xy, th = line.pose(s)
    np.testing.assert_allclose(xy[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(th, 0.0, atol=1e-12)
    sign = 1.0 if params["turn_side"] == "left" else -1.0
    arc = np.deg2rad(params["turn_angle"]) * params["turn_radius"]
    assert float(line.heading(s_b + arc)) == pytest.approx(sign * np.deg2rad(params["turn_angle"]))
    mid = s_b + 0.5 * arc  # on the corner: curvature sign / radius
    assert (float(line.heading(mid + 0.5)) - float(line.heading(mid - 0.5))) == pytest.approx(
        sign / params["turn_radius"], rel=1e-6
    )
    # the built route follows the same line (rotation undone)
    route = route_np(wa)
    yaw0 = float(wa.ego0.yaw)
    rel = route - route[0]
    c, si = np.cos(-yaw0), np.sin(-yaw0)
    local = np.stack([c * rel[:, 0] - si * rel[:, 1], si * rel[:, 0] + c * rel[:, 1]], axis=1)
    before = local[:, 0] < s_b - 1.0
    np.testing.assert_allclose(local[before, 1], 0.0, atol=1e-3)


def test_or_left_turn_needs_room_for_its_inner_kerb():
    from lantern_jax.scenarios.families_straight import OR_INNER_KERB_MIN_R, or_left_kerb

    p = sample_params("OR", np.random.default_rng(0))
    p = dict(p, turn_side="left", lanes_fwd=3, lanes_back=2, lane_width=3.75)
    tight = round(or_left_kerb(p) + OR_INNER_KERB_MIN_R - 1.0, 3)
    with pytest.raises(ValueError, match=r"OR\.turn_radius: .* inner kerb"):
        validate_params(dict(p, turn_radius=tight))
    validate_params(dict(p, turn_radius=round(or_left_kerb(p) + OR_INNER_KERB_MIN_R + 0.01, 3)))
    validate_params(dict(p, turn_side="right", turn_radius=15.0))  # inside is the ego's kerb


def test_scene_deadline_knob_moves_the_reveal():
    # The OR van's guard is a leaf of the scenario: the knob reads it, and setting it (here
    # 1 s earlier) changes only that leaf; the van's start state is unchanged (deadline > 0).
    from lantern_jax.scenarios.knobs import get_knobs, set_knobs

    params, wa, _, _ = make_pair("OR", 4)
    v = params["lead_speed_kmh"] / 3.6
    t_guard = (params["reveal_s"] - params["lead_gap"]) / v
    assert float(get_knobs(wa, ["scene_deadline"])["scene_deadline"]) == pytest.approx(t_guard)
    moved = jax.jit(lambda sc, t: set_knobs(sc, scene_deadline=t))(wa, jnp.float32(t_guard - 1))
    assert float(moved.actors.trigger_deadline[1]) == pytest.approx(t_guard - 1.0)
    np.testing.assert_allclose(moved.actors0.xy, wa.actors0.xy, atol=1e-4)
    np.testing.assert_array_equal(moved.actors.trigger_deadline[2:], wa.actors.trigger_deadline[2:])


def test_host_built_suite_batches_equal_the_device_built_pairs():
    """``build_suite_batches`` (NumPy assembly, one stack on the host) gives exactly the leaves,
    dtypes and shapes of building each pair as device arrays and stacking them."""
    from lantern_jax.scenarios.assemble import host_arrays
    from lantern_jax.scenarios.suite import build_suite_batches, build_suite_scenarios, load_suite

    suite = load_suite().subset(1)
    a_host, b_host = build_suite_batches(suite)
    a_dev, b_dev, _ = build_suite_scenarios(suite)
    for host, dev in ((a_host, tree_stack(a_dev)), (b_host, tree_stack(b_dev))):
        assert jax.tree.structure(host) == jax.tree.structure(dev)
        for path, h, d in zip(
            jax.tree_util.tree_flatten_with_path(host)[0],
            jax.tree.leaves(host),
            jax.tree.leaves(dev),
            strict=True,
        ):
            assert isinstance(h, np.ndarray), path[0]
            assert h.dtype == d.dtype and h.shape == d.shape, path[0]
            np.testing.assert_array_equal(h, np.asarray(d), err_msg=str(path[0]))
    assert all(isinstance(x, jax.Array) for x in jax.tree.leaves(a_dev[0]))
    with host_arrays():
        a, _, _ = build_pair(suite.pairs[0].params)
    assert all(isinstance(x, np.ndarray) for x in jax.tree.leaves(a))
    assert all(
        isinstance(x, jax.Array) for x in jax.tree.leaves(build_pair(suite.pairs[0].params)[0])
    )


def test_a_pair_with_knob_values_builds_on_the_host():
    """A found-suite pair carries knob values; its host-built batch equals the device build."""
    from lantern_jax.scenarios.assemble import host_arrays
    from lantern_jax.scenarios.families import KNOB_RANGES
    from lantern_jax.scenarios.suite import load_suite

    pair = next(p for p in load_suite().pairs if p.family == "PE")
    name, (lo, hi) = next(iter(KNOB_RANGES["PE"].items()))
    params = {**pair.params, "knobs": {name: 0.5 * (lo + hi)}}
    with host_arrays():
        host_a, _, _ = build_pair(params)
    ref_a, _, _ = build_pair(params)
    for h, d in zip(jax.tree.leaves(host_a), jax.tree.leaves(ref_a), strict=True):
        np.testing.assert_array_equal(np.asarray(h), np.asarray(d))


# -- exact shortcuts of the planning geometry ----------------------------------------------------
def _dense_min_distance(points, xy):
    """Reference: every point against every segment, np.linalg.norm (the plain formula)."""
    a, b = xy[:-1], xy[1:]
    ab = b - a
    ll = np.maximum((ab * ab).sum(axis=1), 1e-18)
    t = np.clip(np.einsum("nmk,mk->nm", points[:, None, :] - a[None], ab) / ll, 0.0, 1.0)
    q = a[None] + t[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - q, axis=-1), axis=1)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), limit=st.floats(0.1, 30.0))
def test_polyline_shortcuts_equal_the_dense_computation(seed, limit):
    """The broad-phase minimum and the coarse-to-fine first hit give exactly what measuring
    every point against every segment gives."""
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(size=(int(rng.integers(2, 40)), 2)) * 4.0, axis=0)
    pts = rng.normal(size=(int(rng.integers(1, 30)), 2)) * 20.0
    dense = _dense_min_distance(pts, xy)
    np.testing.assert_array_equal(rd.distances_to_polyline(pts, xy), dense)
    below = rd.polyline_distance_below(pts, xy, limit)
    assert below == (dense.min() if dense.min() < limit else math.inf)
    # samples every 0.05 m along a random curve, against another polyline
    curve = np.cumsum(rng.normal(size=(6, 2)) * 10.0, axis=0)
    samples = rd.point_at(curve, np.arange(0.0, rd.arc_length(curve)[-1], 0.05))
    d = _dense_min_distance(samples, xy)
    inside = np.flatnonzero(d <= limit)
    expected = int(inside[0]) if inside.size else -1
    assert rd.first_within(samples, xy, limit, 0.05) == expected


@given(
    st.lists(
        st.tuples(st.floats(-500, 500, allow_nan=False), st.floats(-500, 500, allow_nan=False)),
        min_size=0,
        max_size=40,
    )
)
@settings(max_examples=60, deadline=None)
def test_host_arc_length_and_point_at_keep_numpys_values(points):
    """The world builder's host helpers compute exactly what ``np.linalg.norm``, ``np.clip``
    and ``np.stack`` gave (suite hashes depend on every bit of the built worlds)."""
    xy = np.asarray(points, np.float64).reshape(-1, 2)
    cs = rd.arc_length(xy)
    want = (
        np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
        if len(xy) >= 2
        else np.zeros(len(xy))
    )
    np.testing.assert_array_equal(cs, want)
    if len(xy) >= 2 and cs[-1] > 0:
        s = np.array([-3.0, 0.0, 0.37 * cs[-1], cs[-1], cs[-1] + 5.0])
        clipped = np.clip(s, 0.0, cs[-1])
        ref = np.stack([np.interp(clipped, cs, xy[:, 0]), np.interp(clipped, cs, xy[:, 1])], -1)
        np.testing.assert_array_equal(rd.point_at(xy, s), ref)
        np.testing.assert_array_equal(rd.point_at(xy, 0.37 * cs[-1]), ref[2])


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 40), multiple=st.integers(1, 16))
def test_pad_rows_repeats_rows_up_to_a_multiple_and_keeps_the_first_n(n, multiple):
    """Padding a batched tree: a multiple of ``multiple`` rows, the first ``n`` unchanged, every
    padding row a copy of a real one, every leaf padded alike."""
    tree = {"a": np.arange(n, dtype=np.float32), "b": np.arange(2 * n).reshape(n, 2)}
    padded, kept = pad_rows(tree, multiple)
    rows = len(padded["a"])
    assert kept == n and rows % multiple == 0 and n <= rows < n + multiple
    np.testing.assert_array_equal(padded["a"][:n], tree["a"])
    np.testing.assert_array_equal(padded["b"][:n], tree["b"])
    src = padded["a"].astype(int)  # each padded row names the real row it copies
    assert set(src) <= set(range(n))
    np.testing.assert_array_equal(padded["b"], tree["b"][src])
