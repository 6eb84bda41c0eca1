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

from lantern_jax.constants import (
    CAMERA_BACK_OFFSET,
    FAMILIES,
    MOTION_IDM,
    MOTION_SCRIPTED,
    ROLE_BACKGROUND,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    TRIGGER_CLOCK,
    TRIGGER_NEVER,
    WEATHERS,
)
from lantern_jax.scenarios import road as rd
from lantern_jax.scenarios.families import build_pair, sample_params, validate_params
from lantern_jax.scenarios.families_common import box_corners, boxes_overlap
from lantern_jax.scenarios.spec import (
    PARAM_RANGES,
    WEATHER_PROFILES,
    canonical_json,
    content_hash,
)
from lantern_jax.scenarios.warnings import (
    TEMPLATES,
    TEXT_BANK,
    TOKEN,
    ground_position,
    render_warning,
)
from lantern_jax.world import tree_stack

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


def segment_hits_box(p0, p1, box) -> bool:
    """Liang-Barsky clip of segment p0-p1 against an oriented box (xy, yaw, (hl, hw))."""
    c, s = math.cos(box[1]), math.sin(box[1])
    rot = np.array([[c, s], [-s, c]])
    a = rot @ (np.asarray(p0) - box[0])
    b = rot @ (np.asarray(p1) - box[0])
    d = b - a
    t0, t1 = 0.0, 1.0
    for k in range(2):
        half = box[2][k]
        for p, q in ((-d[k], a[k] + half), (d[k], half - a[k])):
            if abs(p) < 1e-12:
                if q < 0:
                    return False
            else:
                r = q / p
                if p < 0:
                    t0 = max(t0, r)
                else:
                    t1 = min(t1, r)
    return t0 <= t1


def camera_at(route_xy, s):
    xy = rd.point_at(route_xy, s)
    yaw = rd.heading_at(route_xy, s)
    return xy - CAMERA_BACK_OFFSET * np.array([math.cos(yaw), math.sin(yaw)])


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
    assert abs(length - params["route_length"]) < 1e-3
    route = route_np(wa)
    _, d = rd.project(route, meta["conflict_xy"])
    assert d < 1.0
    spacing = np.diff(np.asarray(a.route.s)[np.asarray(a.route.valid)])
    assert spacing.max() <= rd.ROUTE_SPACING + 1e-4 and spacing.min() > 0.5

    # A/B agreement: everything but the route flag, the warning flag and the scenario slots
    for name in ("route", "lanes", "lights", "ego0"):
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
    assert float(pa.friction) == np.float32(WEATHER_PROFILES[weather].friction)
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


def _check_initial_state(w, route):
    """Ego at the route start on a lane centre; actors at their closed-form t = 0 state."""
    np.testing.assert_allclose(w.ego0.xy, route[0], atol=1e-4)
    d = route[1] - route[0]
    assert abs(math.remainder(float(w.ego0.yaw) - math.atan2(d[1], d[0]), 2 * math.pi)) < 1e-5
    assert float(w.ego0.speed) == pytest.approx(float(w.config.v_ref))
    assert float(w.ego0.steer) == 0.0 and float(w.ego0.accel) == 0.0
    lanes = lane_polylines(w)
    assert min(rd.project(c, route[0])[1] for c, _, _ in lanes) < 1e-3
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
# occlusion (line of sight from the front camera)
# ------------------------------------------------------------------------------------------------
def _assert_pe_hidden(wa):
    route = route_np(wa)
    ped, truck = actor_box(wa, 0), actor_box(wa, 1)
    targets = list(box_corners(*ped)) + [ped[0]]
    for s in np.linspace(0.0, float(wa.config.s_event), 80):
        cam = camera_at(route, s)
        for t in targets:
            assert segment_hits_box(cam, t, truck), f"pedestrian visible from route arc {s:.1f}"


@PROP
@given(seed=SEEDS)
def test_pe_pedestrian_hidden_behind_truck_until_event(seed):
    _assert_pe_hidden(make_pair("PE", seed)[1])


@pytest.mark.parametrize("conflict_s", [33.0, 48.0])
@pytest.mark.parametrize("rotation_deg", [0.0, 137.5])
def test_pe_hidden_at_range_extremes(conflict_s, rotation_deg):
    params = sample_params("PE", np.random.default_rng(0))
    params.update(conflict_s=conflict_s, route_length=135.0, rotation_deg=rotation_deg)
    _assert_pe_hidden(build_pair(params)[0])


@PROP
@given(seed=SEEDS)
def test_or_object_hidden_behind_van_before_the_lane_change(seed):
    _, wa, _, _ = make_pair("OR", seed)
    route = route_np(wa)
    sc = wa.actors
    obj = actor_box(wa, 0)
    targets = list(box_corners(*obj)) + [obj[0]]
    path = np.asarray(sc.path[1], np.float64)[np.asarray(sc.path_valid[1])]
    extent = tuple(np.asarray(wa.actors.extent[1]))
    gap = extent[0] + 2.4508  # bumper to bumper at the closest
    for s_van in np.linspace(float(sc.s_init[1]), float(sc.s_hold[1]), 12):
        van_xy = rd.point_at(path, s_van)
        van = (van_xy, rd.heading_at(path, s_van), extent)
        s_van_route, _ = rd.project(route, van_xy)
        s_max = min(float(wa.config.s_event), s_van_route - gap)
        for s in np.linspace(0.0, s_max, 12):
            cam = camera_at(route, s)
            assert all(segment_hits_box(cam, t, van) for t in targets)


def test_segment_box_helper():
    box = (np.array([0.0, 0.0]), 0.0, (1.0, 1.0))
    assert segment_hits_box((-5, 0), (5, 0), box)
    assert not segment_hits_box((-5, 2), (5, 2), box)
    assert not segment_hits_box((2, -5), (2, 5), box)


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


@pytest.mark.parametrize("family", ["LWW", "RWW", "RTY"])
def test_junction_conflict_is_corridor_entry(family):
    params, wa, wb, meta = make_pair(family, 11)
    route = route_np(wa)
    sc = wa.actors
    thr = 2.4508 + 1.0 + 0.5
    path = np.asarray(sc.path[0], np.float64)[np.asarray(sc.path_valid[0])]
    d_line = (path[-1] - path[0]) / np.linalg.norm(path[-1] - path[0])
    nrm = np.array([-d_line[1], d_line[0]])

    def dist(s):
        return abs((rd.point_at(route, s) - path[0]) @ nrm)

    s_c = float(wa.config.s_conflict)
    assert dist(s_c) == pytest.approx(thr, abs=1e-3)
    assert all(dist(s) > thr for s in np.linspace(0.0, s_c - 0.05, 50))
    near_s, _ = rd.project(path, meta["conflict_xy"])
    if family == "RTY":
        assert near_s == pytest.approx(params["source_dist"], abs=1e-3)
        assert float(wa.config.clear_s) == pytest.approx(near_s + 2.3 + 5.0, abs=1e-3)
        assert int(wb.actors.trigger[0]) == 2 and float(wb.actors0.speed[0]) == 0.0
        np.testing.assert_allclose(wa.actors0.xy[0], wb.actors0.xy[0], atol=1e-5)
    else:
        off, clear = (25.0, 15.0) if family == "LWW" else (20.0, 20.0)
        assert near_s == pytest.approx(off, abs=1e-3)
        assert float(wa.config.clear_s) == pytest.approx(off + clear, abs=1e-3)
        # Route B: same spawn point, legal direction (away from the junction), moving at t = 0
        np.testing.assert_allclose(wa.actors0.xy[0], wb.actors0.xy[0], atol=1e-4)
        dyaw = math.remainder(float(wa.actors0.yaw[0]) - float(wb.actors0.yaw[0]), 2 * math.pi)
        assert abs(abs(dyaw) - math.pi) < 1e-4
        assert float(wb.actors0.speed[0]) == pytest.approx(params["actor_speed"])
        assert np.linalg.norm(wb.actors0.xy[0]) < np.linalg.norm(wb.actors.path[0, -1])


def test_signal_plan_red_then_green():
    road = rd.junction(4, 2, True, ego_red_s=4.5)
    ego, cross = road.lights
    cycle = ego.green + ego.yellow + ego.red

    def state(light, t):
        ph = (t + light.offset) % cycle
        return 0 if ph < light.green else (1 if ph < light.green + light.yellow else 2)

    assert [state(ego, t) for t in (0.0, 4.4, 4.6, 60.0, 94.0)] == [2, 2, 0, 0, 0]
    assert [state(cross, t) for t in (0.0, 1.4, 1.6, 4.6, 90.0)] == [0, 0, 1, 2, 2]
    for t in np.linspace(0, 120, 2401):  # never green together
        assert not (state(ego, t) == 0 and state(cross, t) == 0)


def test_right_turn_radius_is_drivable():
    road = rd.junction(4, 2, False)
    name = rd.add_connector(road, "S", 1, "E", 1)
    pts = road.lane(name).center
    centre = np.array([road.half_size, -road.half_size])
    np.testing.assert_allclose(np.linalg.norm(pts - centre, axis=1), 8.75, atol=1e-9)
    assert 8.75 > 2.85 / math.tan(0.3685)  # ego minimum turning radius


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
        render_warning(len(TEXT_BANK) + 100, (0.0, 0.0))


def test_text_bank_canonical_ids():
    assert len(TEMPLATES) == 6
    for i in range(len(FAMILIES)):
        e = TEXT_BANK[i]
        assert (e.text_id, e.family, e.kind) == (i, i, "canonical")
        assert e.text == TEMPLATES[i] and e.text.count(TOKEN) == 1
    assert TEMPLATES[5] == (
        "The vehicle at position <FRONT_CAR_POS> will cross the ego right-turn path. "
        "Yield before turning right."
    )


def test_route_b_controls():
    # PE: pedestrian slot empty, truck kept
    _, wa, wb, _ = make_pair("PE", 2)
    assert not bool(wb.actors.valid[0]) and bool(wb.actors.valid[1])
    assert int(wb.actors.kind[1]) == int(wa.actors.kind[1]) == 0
    # VC: the same car at the same speed, never merging
    _, wa, wb, _ = make_pair("VC", 2)
    assert float(wa.actors.lat_shift[0]) == 3.5 and float(wb.actors.lat_shift[0]) == 0.0
    assert int(wb.actors.trigger[0]) == TRIGGER_NEVER
    assert float(wb.actors.v_pre[0]) == float(wa.actors.v_pre[0]) == float(wb.actors.v_post[0])
    np.testing.assert_array_equal(wa.actors0.xy[0], wb.actors0.xy[0])
    # OR: no object; the van keeps leading (no hold, no lane change, never triggered)
    _, wa, wb, _ = make_pair("OR", 2)
    assert bool(wa.actors.valid[0]) and not bool(wb.actors.valid[0])
    assert float(wa.actors.s_hold[1]) < 1e3 <= float(wb.actors.s_hold[1])
    assert float(wb.actors.lat_shift[1]) == 0.0 and int(wb.actors.trigger[1]) == TRIGGER_NEVER
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
    road = rd.straight_road(2, 1, 100.0, True)
    assert road.names == ["fwd_0", "fwd_1", "back_0", "shoulder"]
    assert road.lane("shoulder").kind == rd.LANE_SHOULDER and road.lane("shoulder").width == 2.5
    np.testing.assert_allclose(road.lane("back_0").center[0], [100.0, 1.75])
    j = rd.junction(3, 2, True, missing_arm="N")
    assert rd.inbound_lane(j, "S", 0)[0] == "S_in_0" and rd.outbound_lane(j, "E", 1)[0] == "WE_1"
    assert [rd.turn_direction("S", x) for x in ("W", "E", "N")] == ["left", "right", "straight"]
    with pytest.raises(ValueError, match="no arm opposite"):
        rd.turn_route(j, "S", 0, "N", 0, 20.0, 60.0)
    j4 = rd.junction(4, 2, True)
    straight = rd.turn_route(j4, "S", 1, "N", 1, 20.0, 60.0)
    assert straight.length == pytest.approx(60.0) and straight.stop_s == pytest.approx(18.0)
    left = rd.turn_route(j4, "S", 0, "W", 0, 20.0, 70.0)
    assert left.length == pytest.approx(70.0) and left.lanes[1] == "S0>W0"
    assert j4.lane("S0>W0").kind == rd.LANE_CONNECTOR
    assert len(j4.lanes) <= rd.MAX_LANES
    # corridor entry on a straight line crossing y = 0 at 45 degrees
    line = np.array([[0.0, -10.0], [10.0, 0.0]])
    s = rd.corridor_entry(line, (0.0, 0.0), (1.0, 0.0), 2.0)
    assert s == pytest.approx(8.0 * math.sqrt(2.0))
