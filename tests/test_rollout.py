"""Simulator core: batching, padding, compilation, the early-exit driver, gradients, faults."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    BATCH,
    MODE_CONST,
    MODE_COOP,
    MODE_EGO,
    MODE_EXPERT,
    MODE_NAN_BELOW,
    constant_speed_waypoints,
    select,
)

from lantern_jax.core.constants import (
    DT,
    FAMILIES,
    KIND_PEDESTRIAN,
    MOTION_IDM,
    ROLE_HAZARD,
    ROLE_OCCLUDER,
    TRIGGER_EVENT,
)
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.handmade import ActorSpec, straight_scene
from lantern_jax.scenarios.knobs import set_knobs
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import rollout
from lantern_jax.sim.state import init_state

GRAD_TICKS = 200


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def assert_trees_close(actual, expected, rtol=1e-5, atol=1e-5, what=""):
    """Leaf-wise comparison: floats to tolerance, ints and bools exactly; names the leaf."""
    la = jax.tree_util.tree_leaves_with_path(actual)
    le = jax.tree_util.tree_leaves_with_path(expected)
    assert len(la) == len(le)
    for (path, a), (_, e) in zip(la, le, strict=True):
        name = what + jax.tree_util.keystr(path)
        a, e = np.asarray(a), np.asarray(e)
        if np.issubdtype(a.dtype, np.floating):
            np.testing.assert_allclose(a, e, rtol=rtol, atol=atol, err_msg=name)
        else:
            np.testing.assert_array_equal(a, e, err_msg=name)


def assert_trees_equal(actual, expected, what=""):
    for (path, a), (_, e) in zip(
        jax.tree_util.tree_leaves_with_path(actual),
        jax.tree_util.tree_leaves_with_path(expected),
        strict=True,
    ):
        np.testing.assert_array_equal(
            np.asarray(a), np.asarray(e), err_msg=what + jax.tree_util.keystr(path)
        )


def assert_all_finite(tree, what=""):
    for path, x in jax.tree_util.tree_leaves_with_path(tree):
        x = np.asarray(x)
        if np.issubdtype(x.dtype, np.floating):
            bad = ~np.isfinite(x)
            assert not bad.any(), f"{what}{jax.tree_util.keystr(path)}: non-finite entries"


def ticks_before_done(rec) -> int:
    """Number of recorded ticks up to and including the tick at which the execution ended."""
    done = np.asarray(rec.done)
    return int(np.argmax(done)) + 1 if done.any() else done.shape[0]


def crossing_scene(**overrides):
    """Straight road, a pedestrian hidden behind a parked truck crosses at x = 40 on the event,
    plus an IDM car in the adjacent lane.  Markers 22 / 31 / 40 m."""
    ped = ActorSpec(
        path=np.array([[40.0, -5.0], [40.0, 17.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
        role=ROLE_HAZARD, v_post=3.0, trigger=TRIGGER_EVENT, despawn_at_end=True,
    )  # fmt: skip
    truck = ActorSpec(path=np.array([[35.4, -3.4]]), extent=(4.0, 1.25), role=ROLE_OCCLUDER)
    car = ActorSpec(
        path=np.array([[-50.0, -3.5], [170.0, -3.5]]), motion=MOTION_IDM, s_init=40.0, v_pre=7.0
    )
    kw = dict(
        s_warn=22.0, s_event=31.0, s_conflict=40.0, hazard_index=0, clear_s=22.0,
        despawn_on_clear=True,
    )  # fmt: skip
    kw.update(overrides)
    return straight_scene([ped, truck, car], length=120.0, speed=8.0, **kw)


def with_garbage_padding(world, seed: int = 0):
    """The same world with random (finite, validate-clean) values in every padding slot:
    actors, actor scripts, lanes, lane points, route points and traffic lights."""
    rng = np.random.default_rng(seed)
    a, sc, ln, r, lt = world.actors0, world.actors, world.lanes, world.route, world.lights

    def fill(x, mask, garbage):
        x = np.array(x)
        m = np.asarray(mask, bool).reshape(mask.shape + (1,) * (x.ndim - np.ndim(mask)))
        return jnp.asarray(np.where(m, np.asarray(garbage).astype(x.dtype), x))

    pad = ~np.asarray(sc.valid)
    n_a, n_p = sc.path.shape[:2]
    xy = rng.uniform(-200.0, 200.0, (n_a, 2))
    # A few invisible actors right in front of the ego, in its lane.
    first = np.flatnonzero(pad)[:3]
    xy[first] = [[12.0, 0.0], [25.0, 0.4], [45.0, -0.3]]
    actors = a.replace(
        xy=fill(a.xy, pad, xy),
        yaw=fill(a.yaw, pad, rng.uniform(-3.0, 3.0, n_a)),
        speed=fill(a.speed, pad, rng.uniform(0.0, 20.0, n_a)),
        active=fill(a.active, pad, np.ones(n_a, bool)),
        s=fill(a.s, pad, rng.uniform(0.0, 50.0, n_a)),
        lat=fill(a.lat, pad, rng.uniform(-2.0, 2.0, n_a)),
    )
    n_valid = rng.integers(1, n_p + 1, n_a)
    path_valid = np.arange(n_p)[None, :] < n_valid[:, None]
    path = rng.uniform(-100.0, 100.0, (n_a, n_p, 2))
    path[first, :, 1] = 0.0  # paths along the ego lane
    script = sc.replace(
        extent=fill(sc.extent, pad, rng.uniform(0.2, 5.0, (n_a, 2))),
        kind=fill(sc.kind, pad, rng.integers(0, 3, n_a)),
        role=fill(sc.role, pad, rng.integers(0, 4, n_a)),
        motion=fill(sc.motion, pad, rng.integers(0, 2, n_a)),
        path=fill(sc.path, pad, path),
        path_s=fill(sc.path_s, pad, np.cumsum(rng.uniform(0.5, 5.0, (n_a, n_p)), -1)),
        path_valid=fill(sc.path_valid, pad, path_valid),
        s_init=fill(sc.s_init, pad, rng.uniform(0.0, 30.0, n_a)),
        v_pre=fill(sc.v_pre, pad, rng.uniform(0.0, 15.0, n_a)),
        v_post=fill(sc.v_post, pad, rng.uniform(0.0, 15.0, n_a)),
        s_hold=fill(sc.s_hold, pad, rng.uniform(0.0, 60.0, n_a)),
        s_end=fill(sc.s_end, pad, rng.uniform(0.0, 90.0, n_a)),
        trigger=fill(sc.trigger, pad, rng.integers(0, 3, n_a)),
        trigger_delay=fill(sc.trigger_delay, pad, rng.uniform(0.0, 5.0, n_a)),
        lat_shift=fill(sc.lat_shift, pad, rng.uniform(-3.0, 3.0, n_a)),
        lat_duration=fill(sc.lat_duration, pad, rng.uniform(0.5, 3.0, n_a)),
        despawn_at_end=fill(sc.despawn_at_end, pad, rng.random(n_a) < 0.5),
        light_index=fill(sc.light_index, pad, rng.integers(-1, 2, n_a)),
        stop_s=fill(sc.stop_s, pad, rng.uniform(0.0, 80.0, n_a)),
    )
    # Lanes: padded lanes, and the padded points of the valid lanes.
    lane_pad = ~np.asarray(ln.valid)
    pt_pad = ~np.asarray(ln.point_valid) | lane_pad[:, None]
    lanes = ln.replace(
        center=fill(ln.center, pt_pad, rng.uniform(-100.0, 100.0, ln.center.shape)),
        s=fill(ln.s, pt_pad, rng.uniform(0.0, 300.0, ln.s.shape)),
        point_valid=fill(ln.point_valid, lane_pad, rng.random(ln.point_valid.shape) < 0.5),
        width=fill(ln.width, lane_pad, rng.uniform(1.0, 6.0, ln.width.shape)),
        kind=fill(ln.kind, lane_pad, rng.integers(0, 3, ln.kind.shape)),
    )
    r_pad = ~np.asarray(r.valid)
    route = r.replace(
        xy=fill(r.xy, r_pad, rng.uniform(-100.0, 100.0, r.xy.shape)),
        s=fill(r.s, r_pad, rng.uniform(0.0, 300.0, r.s.shape)),
    )
    l_pad = ~np.asarray(lt.valid)
    lights = lt.replace(
        green=fill(lt.green, l_pad, rng.uniform(1.0, 10.0, lt.green.shape)),
        yellow=fill(lt.yellow, l_pad, rng.uniform(0.0, 3.0, lt.green.shape)),
        red=fill(lt.red, l_pad, rng.uniform(1.0, 10.0, lt.green.shape)),
        offset=fill(lt.offset, l_pad, rng.uniform(0.0, 10.0, lt.green.shape)),
        stop_xy=fill(lt.stop_xy, l_pad, rng.uniform(0.0, 60.0, lt.stop_xy.shape)),
    )
    out = world.replace(actors0=actors, actors=script, lanes=lanes, route=route, lights=lights)
    return out.validate()


# ---------------------------------------------------------------------------------------------
# batching and padding
# ---------------------------------------------------------------------------------------------
def test_vmap_equals_single_rollout(sim, family_pairs):
    worlds = [family_pairs["PE"][0], family_pairs["RTY"][0], crossing_scene()]
    final_b, _ = sim.batch(worlds)
    for i, w in enumerate(worlds):
        final_1, _ = sim.single(w)
        got = select(final_b, i)
        assert_trees_close(got.telemetry, final_1.telemetry, what=f"[{i}] telemetry")
        assert_trees_close(got.protocol, final_1.protocol, what=f"[{i}] protocol")
        assert_trees_close(got.ego, final_1.ego, what=f"[{i}] ego")


def test_padding_slots_change_nothing(sim):
    clean = crossing_scene()
    dirty = with_garbage_padding(clean, seed=3)
    n_valid = int(np.sum(np.asarray(clean.actors.valid)))
    assert n_valid == 3
    final, rec = sim.batch([clean, dirty])
    c, d = select(final, 0), select(final, 1)
    # The scene actually exercised the hazard.
    assert c.protocol.t_event < 1e3 and c.protocol.t_clear < 1e3
    assert_trees_equal(d.telemetry, c.telemetry, "telemetry")
    assert_trees_equal(d.ego, c.ego, "ego")
    assert_trees_equal(d.protocol, c.protocol, "protocol")
    assert_trees_equal((d.t, d.tick, d.done, d.fault), (c.t, c.tick, c.done, c.fault))
    for f in ("xy", "yaw", "speed", "active", "s", "lat"):
        np.testing.assert_array_equal(
            getattr(d.actors, f)[:n_valid], getattr(c.actors, f)[:n_valid], f
        )
    np.testing.assert_array_equal(d.percept.visible[:n_valid], c.percept.visible[:n_valid])
    for f in ("ranges", "route_arc", "dist_to_route", "progress"):
        np.testing.assert_array_equal(getattr(d.percept, f), getattr(c.percept, f), f)
    # Every recorded tick agrees too (ego trajectory, warning, plan).
    rc, rd = select(rec, 0), select(rec, 1)
    for f in ("ego_xy", "ego_speed", "warning_active", "warning_pos", "waypoints", "done"):
        np.testing.assert_array_equal(getattr(rd, f), getattr(rc, f), f)
    # Padding slots keep their (garbage) state bit for bit and are never seen.
    pad = ~np.asarray(dirty.actors.valid)
    for f in ("xy", "yaw", "speed", "s", "lat"):
        np.testing.assert_array_equal(
            getattr(d.actors, f)[pad], np.asarray(getattr(dirty.actors0, f))[pad], f
        )
    assert not d.percept.visible[pad].any()
    assert not rd.visible[:, pad].any() and not rd.actor_present[:, pad].any()


# ---------------------------------------------------------------------------------------------
# compilation
# ---------------------------------------------------------------------------------------------
def test_single_rollout_traces_once(sim, family_pairs):
    worlds = [family_pairs["VC"][0], family_pairs["LWW"][1], crossing_scene(s_warn=20.0)]
    for w in worlds:
        sim.single(w)
    sim.single(worlds[0], MODE_CONST, 6.0)
    assert sim.traces["single"] == 1


def test_batched_rollout_traces_once(sim, family_pairs):
    a = [family_pairs[f][0] for f in FAMILIES]
    b = [family_pairs[f][1] for f in FAMILIES]
    sim.batch(a)
    sim.batch(b, MODE_EGO)
    assert sim.traces["batch"] == 1


def test_rollout_batch_traces_once_and_matches_fixed_horizon(sim, family_pairs):
    worlds = [w for f in FAMILIES for w in family_pairs[f][:2]]
    assert len(worlds) == BATCH
    early = sim.evaluate(worlds)
    sim.evaluate(worlds[::-1], MODE_EGO)
    assert sim.traces["evaluate"] == 1

    fixed, _ = sim.batch(worlds)
    assert np.asarray(fixed.done).all(), "horizon too short for the family routes"
    assert np.asarray(early.done).all()
    # The two drivers are different XLA programs: per-tick results agree to float32 rounding,
    # which the closed loop can amplify over a few hundred ticks (to ~1e-4 on accelerations).
    tol = dict(rtol=1e-3, atol=2e-3)
    for i in range(BATCH):
        e, f = select(early, i), select(fixed, i)
        assert_trees_close(e.telemetry, f.telemetry, what=f"[{i}] telemetry", **tol)
        assert_trees_close(e.protocol, f.protocol, what=f"[{i}] protocol", **tol)
        assert_trees_close(e.ego, f.ego, what=f"[{i}] ego", **tol)
        assert int(e.tick) == int(f.tick)


# ---------------------------------------------------------------------------------------------
# gradients
# ---------------------------------------------------------------------------------------------
def _soft_clearance_grad(policy: Policy):
    """``jit(value_and_grad)`` of the soft clearance accumulator of :func:`crossing_scene` with
    respect to the pedestrian's crossing speed ``v_post`` (3 m/s), over GRAD_TICKS ticks."""
    world = crossing_scene()
    params = policy.init(jax.random.PRNGKey(0))

    def soft_clearance(v_post):
        final, _ = rollout(set_knobs(world, hazard_speed=v_post), policy, params, GRAD_TICKS)
        return final.telemetry.clearance.lse

    value, grad = jax.jit(jax.value_and_grad(soft_clearance))(jnp.float32(3.0))
    return float(value), float(grad)


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_gradient_through_simulator_core():
    """Scripted actor, protocol and telemetry are differentiable (constant-speed ego plan)."""
    cruise = Policy("cruise", lambda key: None, lambda _, obs: constant_speed_waypoints(8.0))
    value, grad = _soft_clearance_grad(cruise)
    assert np.isfinite(value)
    assert np.isfinite(grad) and abs(grad) > 1e-6


def test_expert_plan_gradient_wrt_observation_is_finite():
    """d(plan)/d(observation) of the expert is finite for an ordinary scene, including actors
    aligned with the route (where a sqrt(1 - cos^2) footprint would have an infinite slope) and
    the privileged forecast."""
    expert = get_policy("expert")
    pp = expert.init(jax.random.PRNGKey(0))
    world = crossing_scene()
    obs = jax.jit(lambda w: observe(w, init_state(w), expert.sensors))(world)

    def plan_sum(route, actor_dir, forecast_x):
        pv = obs.privileged.replace(forecast_x=forecast_x, actor_dir=actor_dir)
        return jnp.sum(expert.act(pp, obs.replace(route=route, privileged=pv)))

    grads = jax.jit(jax.grad(plan_sum, argnums=(0, 1, 2)))(
        obs.route, obs.privileged.actor_dir, obs.privileged.forecast_x
    )
    for g in grads:
        assert np.isfinite(np.asarray(g)).all()


def test_expert_refuses_an_ordinary_observation():
    """The expert needs the privileged view; an ordinary rollout gets a clear error."""
    expert = get_policy("expert")
    world = crossing_scene()
    obs = jax.jit(lambda w: observe(w, init_state(w)))(world)
    assert obs.privileged is None
    with pytest.raises(ValueError, match="'privileged' sensor"):
        expert.act(expert.init(jax.random.PRNGKey(0)), obs)


@pytest.mark.slow
def test_gradient_through_expert_policy():
    value, grad = _soft_clearance_grad(get_policy("expert"))
    assert np.isfinite(value)
    assert np.isfinite(grad) and abs(grad) > 1e-6


# ---------------------------------------------------------------------------------------------
# policy faults, done mask, finiteness
# ---------------------------------------------------------------------------------------------
def test_nan_waypoints_are_a_recorded_fault_and_isolated(sim):
    # The probe returns NaN waypoints while ego_speed < 2.5 m/s: from the first tick in the slow
    # scene, never in the fast one (the expert stays above ~4 m/s until the route is completed).
    slow = straight_scene([], speed=2.0)
    fast = straight_scene([], speed=8.0)
    final, rec = sim.batch([slow, fast], MODE_NAN_BELOW, 2.5)

    m_slow = finalize(select(final.telemetry, 0))
    assert bool(m_slow.controller_fault)
    assert not bool(m_slow.gate_block)
    assert bool(select(final.fault, 0))
    r = select(rec, 0)
    n = ticks_before_done(r)
    assert np.isfinite(r.ego_xy).all() and np.isfinite(r.ego_speed).all()
    assert np.isfinite(r.waypoints).all()  # the recorded (sanitized) plan
    assert_all_finite(select(final, 0), "slow final state")
    # Full braking: decelerating from the first tick, stopped well within a second.
    assert r.ego_accel[0] < -5.0
    assert np.all(np.diff(r.ego_speed[:n]) <= 1e-6)
    assert r.ego_speed[20] < 0.1

    # The other execution of the batch is unaffected: equal to running it alone.
    fast_final = select(final, 1)
    assert not bool(finalize(fast_final.telemetry).controller_fault)
    alone, _ = sim.single(fast, MODE_NAN_BELOW, 2.5)
    assert_trees_close(fast_final.telemetry, alone.telemetry, what="telemetry")
    assert_trees_close(fast_final.ego, alone.ego, what="ego")


@pytest.mark.parametrize("scene", ["family_pe", "empty_road"])
def test_done_freezes_the_state(sim, family_pairs, scene):
    # On the empty road the expert is still moving (~4 m/s) when the route is completed.
    world = family_pairs["PE"][0] if scene == "family_pe" else straight_scene([], speed=8.0)
    final, rec = sim.single(world)
    assert rec.done.any()
    k = int(np.argmax(rec.done))  # tick at which the execution ended
    assert k < rec.done.shape[0] - 10
    assert rec.done[k:].all()
    assert int(final.tick) == k + 1
    assert int(final.telemetry.context.n_ticks) == k + 1
    np.testing.assert_allclose(final.t, (k + 1) * DT, atol=1e-4)
    if scene == "empty_road":
        assert final.ego.speed > 1.0
    # Records after the end repeat the frozen state; the policy no longer acts.
    for f in ("t", "ego_xy", "ego_yaw", "ego_speed", "actor_xy", "actor_present"):
        got = getattr(rec, f)[k:]
        np.testing.assert_array_equal(got, np.broadcast_to(got[0], got.shape), err_msg=f)
    np.testing.assert_array_equal(rec.ego_xy[k], final.ego.xy)
    np.testing.assert_array_equal(rec.actor_xy[k], final.actors.xy)
    assert not rec.warning_active[k + 1 :].any()
    assert (rec.waypoints[k + 1 :] == 0.0).all()


def _check_no_nan_and_forward_motion(final, rec, label):
    assert_all_finite(final, label)
    assert np.isfinite(rec.ego_xy).all() and np.isfinite(rec.ego_speed).all(), label
    assert (rec.ego_speed >= 0.0).all(), label
    present = final.actors.active  # padding slots are never active
    assert (final.actors.speed[present] >= 0.0).all(), label
    # Never reversing: every tick's displacement points along the previous heading.
    step = np.diff(rec.ego_xy, axis=-2)
    yaw = rec.ego_yaw[..., :-1]
    along = step[..., 0] * np.cos(yaw) + step[..., 1] * np.sin(yaw)
    assert (along >= -1e-4).all(), f"{label}: ego moved backwards"


@pytest.mark.parametrize("mode", [MODE_EXPERT, MODE_EGO, MODE_COOP], ids=["expert", "ego", "coop"])
def test_all_families_all_policies_stay_finite(sim, family_pairs, mode):
    worlds = [w for f in FAMILIES for w in family_pairs[f][:2]]
    final, rec = sim.batch(worlds, mode)
    for i in range(len(worlds)):
        _check_no_nan_and_forward_motion(select(final, i), select(rec, i), f"{i} mode {mode}")


def test_plan_behind_the_ego_never_reverses_it(sim):
    """Waypoints straight behind the ego: speeds stay >= 0 and the ego never backs up."""
    standing = straight_scene([], speed=8.0)
    standing = standing.replace(ego0=standing.ego0.replace(speed=jnp.float32(0.0)))
    worlds = [straight_scene([], speed=8.0), standing]
    final, rec = sim.batch(worlds, MODE_CONST, -8.0)
    for i in range(2):
        _check_no_nan_and_forward_motion(select(final, i), select(rec, i), f"behind {i}")


# ---------------------------------------------------------------------------------------------
# slot permutation and capacity
# ---------------------------------------------------------------------------------------------
def _permute_slots(scenario, order):
    """The same scene with actor slot ``order[i]`` moved to slot ``i`` (hazard index follows)."""
    order = np.asarray(order)
    take = lambda x: x[order]  # noqa: E731
    inverse = np.argsort(order)
    h = int(scenario.config.hazard_index)
    return scenario.replace(
        actors=jax.tree.map(take, scenario.actors),
        actors0=jax.tree.map(take, scenario.actors0),
        config=scenario.config.replace(hazard_index=jnp.int32(inverse[h])),
    )


def _with_capacity(scenario, num_slots):
    """The same scene with ``num_slots`` actor slots (extra slots are empty padding)."""
    extra = num_slots - scenario.actors.num

    def grow(x):
        pad = np.zeros((extra, *x.shape[1:]), x.dtype)
        return jnp.concatenate([x, jnp.asarray(pad)])

    script = jax.tree.map(grow, scenario.actors)
    script = script.replace(path_valid=script.path_valid.at[-extra:, 0].set(True),
                            lat_duration=script.lat_duration.at[-extra:].set(1.0))  # fmt: skip
    return scenario.replace(actors=script, actors0=jax.tree.map(grow, scenario.actors0))


def test_permuting_actor_slots_changes_nothing(sim, family_pairs):
    """Which slot an actor sits in is bookkeeping: scores, protocol and ego are the same."""
    scene = family_pairs["OR"][0]  # hazard object, lead van and background traffic
    n = scene.actors.num
    rng = np.random.default_rng(4)
    order = rng.permutation(n)
    permuted = _permute_slots(scene, order).validate()
    assert int(permuted.config.hazard_index) != int(scene.config.hazard_index)
    final, _ = sim.batch([scene, permuted])
    a, b = select(final, 0), select(final, 1)
    assert_trees_close(b.telemetry, a.telemetry, rtol=1e-6, atol=1e-6, what="telemetry")
    assert_trees_close(b.protocol, a.protocol, rtol=1e-6, atol=1e-6, what="protocol")
    assert_trees_close(b.ego, a.ego, rtol=1e-6, atol=1e-6, what="ego")
    for f in ("xy", "speed", "active"):
        np.testing.assert_allclose(getattr(b.actors, f), getattr(a.actors, f)[order], atol=1e-5)


@pytest.mark.slow
def test_actor_capacity_changes_nothing(family_pairs):
    """A scene packed into more actor slots (a different static shape, so its own compilation)
    rolls out exactly as in the standard capacity."""
    get = get_policy("coop")
    pp = get.init(jax.random.PRNGKey(0))
    scene = family_pairs["PE"][0]
    big = _with_capacity(scene, scene.actors.num + 8).validate()
    run = jax.jit(lambda sc: rollout(sc, get, pp, 600)[0])
    a, b = jax.device_get(run(scene)), jax.device_get(run(big))
    assert_trees_close(b.telemetry, a.telemetry, rtol=1e-6, atol=1e-6, what="telemetry")
    assert_trees_close(b.protocol, a.protocol, rtol=1e-6, atol=1e-6, what="protocol")
    assert_trees_close(b.ego, a.ego, rtol=1e-6, atol=1e-6, what="ego")
    assert bool(a.done) and bool(b.done)
