"""The world compiled apart from the policy (``lantern_jax.sim.split``): packing, the observation
of every sensor, equality with the fused rollout on every family, the path's choice, fresh
programs for a changed policy or setting, and the store's refusal of another signature.

The world program of the built-in suite's batch shape is compiled once for the session
(``conftest.pytest_configure``); the batches here are cut to that shape so that every test
compiles only its policy's own small program.
"""

from __future__ import annotations

import dataclasses
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import HORIZON, MODE_COOP, MODE_EXPERT, select
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import FAMILIES, NUM_WAYPOINTS, WAYPOINT_DT
from lantern_jax.io import program_store
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.table import REPRODUCIBLE_ATOL
from lantern_jax.sim import engine, programs, split
from lantern_jax.sim.engine import SUITE_BATCH_SHAPE, PathChoice, choose_path
from lantern_jax.sim.observe import observe, observe_every_sensor
from lantern_jax.sim.packing import Layout
from lantern_jax.sim.settings import Settings, default_settings
from lantern_jax.sim.state import init_state
from lantern_jax.types.observation import FRONT_CAMERA, PRIVILEGED, SURROUND_RIG, WARNING
from lantern_jax.types.world import tree_stack, trim_padding

SUITE_WIDTHS = SUITE_BATCH_SHAPE[1:]  # actor and lane slots of the session's world program


# ---------------------------------------------------------------------------------------------
# packing
# ---------------------------------------------------------------------------------------------
_DTYPES = st.sampled_from([np.float32, np.int32, np.bool_, np.uint32])
_SHAPES = st.lists(st.integers(0, 3), min_size=0, max_size=3).map(tuple)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(_SHAPES, _DTYPES), min_size=1, max_size=6), st.integers(0, 2**31 - 1))
def test_packing_round_trips_any_tree_exactly(leaves, seed):
    rng = np.random.default_rng(seed)
    tree = {
        f"leaf{i}": (rng.standard_normal(shape) * 1e3).astype(dt) for i, (shape, dt) in
        enumerate(leaves)
    }  # fmt: skip
    layout = Layout.of(tree)
    assert len(layout.groups) == len({np.dtype(dt).name for _, dt in leaves})
    packed = layout.pack(tree)
    back = layout.unpack(packed)
    for k, v in tree.items():
        assert back[k].dtype == v.dtype and back[k].shape == v.shape
        np.testing.assert_array_equal(np.asarray(back[k]), v)
    # the host packing of a batch equals the traced packing under vmap, and round-trips
    batch = jax.tree.map(lambda x: np.stack([x, x]), tree)
    host = layout.pack_host(batch)
    traced = jax.vmap(layout.pack)(batch)
    for a, b in zip(host, traced, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b))
    for k, v in layout.unpack_host(host).items():
        np.testing.assert_array_equal(v, batch[k])


def test_a_layout_finds_a_leaf_by_path_and_names_a_missing_one():
    tree = {"a": np.zeros((2, 3), np.float32), "b": {"c": np.ones(4, np.int32)}}
    layout = Layout.of(tree)
    leaf = layout.index_of("['b']['c']")
    assert (leaf.shape, layout.groups[leaf.group][0]) == ((4,), "int32")
    with pytest.raises(KeyError, match="no leaf at"):
        layout.index_of("['d']")
    with pytest.raises(ValueError, match="leaves"):
        layout.pack({"a": np.zeros((2, 3), np.float32)})


# ---------------------------------------------------------------------------------------------
# the observation of every sensor
# ---------------------------------------------------------------------------------------------
def _same(a, b) -> None:
    """Equal: exactly for masks, kinds and ids; to float32 rounding for numbers (a view built
    inside a branch is compiled apart from the rest, so its last bits may differ)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    if np.issubdtype(a.dtype, np.floating):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=REPRODUCIBLE_ATOL)
    else:
        np.testing.assert_array_equal(a, b)


#: Compiled as the simulator compiles them (one program per sensor declaration for ``observe``,
#: one for every declaration for ``observe_every_sensor``), rather than run op by op: the worlds
#: share one shape, so the cases below reuse these programs.
_observe = jax.jit(observe, static_argnums=2)
_observe_every_sensor = jax.jit(observe_every_sensor)
_init_state = jax.jit(init_state)


@pytest.mark.parametrize("sensors", [(), (WARNING,), (PRIVILEGED,), (SURROUND_RIG, WARNING),
                                     (PRIVILEGED, SURROUND_RIG)])  # fmt: skip
def test_the_observation_of_every_sensor_equals_the_declared_one(family_runs, sensors):
    """Once the undeclared views are dropped, the world program's observation is exactly what
    :func:`observe` gives a policy of those sensors, at the start and mid-route."""
    worlds, (final, _) = family_runs
    bank = default_settings().bank
    declared = tuple(sorted({FRONT_CAMERA, *sensors}))
    for i in (0, 5, 8):  # PE Route A, VC Route B, LWW Route A
        world = worlds[i]
        for state in (_init_state(world), select(final, i)):
            want = _observe(world, state, declared, bank)
            on = {s: jnp.asarray(s in sensors) for s in (PRIVILEGED, SURROUND_RIG)}
            got, view = _observe_every_sensor(world, state, on[PRIVILEGED], on[SURROUND_RIG],
                                              bank)  # fmt: skip
            got = got.replace(
                privileged=view if PRIVILEGED in sensors else None,
                surround=got.surround if SURROUND_RIG in sensors else None,
            )
            if WARNING not in sensors:
                got = got.replace(warning_tokens=want.warning_tokens,
                                  warning_values=want.warning_values)  # fmt: skip
            assert jax.tree.structure(got) == jax.tree.structure(want), (sensors, i)
            for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
                _same(a, b)


@pytest.mark.parametrize("sensors", [(), (WARNING,), (PRIVILEGED,), (SURROUND_RIG, WARNING),
                                     (PRIVILEGED, SURROUND_RIG, WARNING)])  # fmt: skip
def test_the_declared_observation_read_from_the_signature_is_observe_s(sensors):
    """The observation a split-path policy is checked against (read from the world signature,
    never traced again) has :func:`observe`'s structure, shapes and dtypes for its sensors."""
    execs = engine.build_executions(load_suite(), bucket=True)
    one = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), execs.scenarios)
    pol = Policy("probe", lambda key: (), lambda params, obs: jnp.zeros((NUM_WAYPOINTS, 2)),
                 sensors=sensors)  # fmt: skip
    settings_ = default_settings()
    got = split.declared_observation(pol, one, settings_)
    want = jax.eval_shape(lambda sc: observe(sc, init_state(sc), pol.sensors, settings_.bank), one)
    assert jax.tree.structure(got) == jax.tree.structure(want)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        assert (a.shape, a.dtype) == (b.shape, b.dtype)


def test_the_world_program_leaves_the_ground_truth_to_a_privileged_policy_s_program():
    """The world program's observation outputs are its observation layout's groups alone (no
    ground truth written every tick); only a policy that declares the ground truth is given
    the slots' packed scenarios and states to compute it from, every other one ``()``."""
    execs = engine.build_executions(load_suite().select(["pe_0001"]), bucket=True)
    settings_ = default_settings()
    one = jax.tree.map(lambda x: np.asarray(x)[0], execs.scenarios)
    sig = split.world_signature(one, settings_, split.split_slots())
    device = jax.local_devices()[0]
    setp = tuple(jax.device_put(b, device) for b in split._pack_one(sig.settings, settings_))
    _, obs, _ = jax.eval_shape(
        lambda *a: split._tick_batch(*a, signed=split._Signed(sig)),
        *split._tick_args(sig, setp, device),
    )  # fmt: skip
    want = [((sig.slots, size), np.dtype(dt)) for dt, size in sig.observation.groups]
    assert [(o.shape, o.dtype) for o in obs] == want
    assert [(o.shape[1:], o.dtype) for o in sig.observations(4, device)] == [
        ((size,), np.dtype(dt)) for dt, size in sig.observation.groups
    ]
    act = lambda params, obs: jnp.zeros((NUM_WAYPOINTS, 2))  # noqa: E731
    sees_all = Policy("sees all", lambda key: (), act, sensors=(PRIVILEGED,))
    camera = Policy("camera", lambda key: (), act, sensors=(WARNING,))
    assert split.ground_truth_inputs(sees_all, ("sc",), ("st",)) == (("sc",), ("st",))
    assert split.ground_truth_inputs(camera, ("sc",), ("st",)) == ()


# ---------------------------------------------------------------------------------------------
# equal to the fused rollout, on every family
# ---------------------------------------------------------------------------------------------
def _to_suite_widths(worlds):
    """The worlds as one batch cut to the built-in suite's slot widths (the session's world
    program); padding slots are inert."""
    return trim_padding(tree_stack(worlds), at_least=SUITE_WIDTHS)


@pytest.mark.parametrize("mode", [MODE_EXPERT, MODE_COOP])
def test_split_equals_the_fused_rollout_on_every_family(sim, family_pairs, family_runs, mode):
    """Both routes of one pair per family: the split path (world program + the conftest probe
    policy's own program) and the session's fused runner end every execution at the same tick
    with the same telemetry, to the reproducibility tolerance (float rounding between two
    programs)."""
    worlds, (fused_expert, _) = family_runs
    fused = fused_expert if mode == MODE_EXPERT else sim.batch(worlds, mode)[0]
    params = (jnp.int32(mode), jnp.float32(0.0))
    final, _ = split.run_split(sim.policy, _to_suite_widths(worlds), params, HORIZON,
                               default_settings())  # fmt: skip
    np.testing.assert_array_equal(final.tick, np.asarray(fused.tick))
    np.testing.assert_array_equal(final.done, np.asarray(fused.done))
    fused_leaves = jax.tree.leaves(fused.telemetry)
    for (path, a), b in zip(jax.tree_util.tree_flatten_with_path(final.telemetry)[0],
                            fused_leaves, strict=True):  # fmt: skip
        a, b, where = np.asarray(a), np.asarray(b), jax.tree_util.keystr(path)
        if a.dtype == bool or np.issubdtype(a.dtype, np.integer):
            np.testing.assert_array_equal(a, b, err_msg=where)
        else:
            np.testing.assert_allclose(a, b, atol=REPRODUCIBLE_ATOL, rtol=1e-5, err_msg=where)
    assert len(FAMILIES) * 2 == len(worlds)


def _counter_policy() -> Policy:
    """Drives at the reference speed for its first 100 ticks, then stops: its carry counts the
    ticks since its execution started."""

    def act(params, carry, obs):
        k = jnp.arange(1, NUM_WAYPOINTS + 1, dtype=jnp.float32) * WAYPOINT_DT
        speed = jnp.where(carry < 100, obs.v_ref, 0.0)
        return jnp.stack([k * speed, jnp.zeros_like(k)], -1), carry + 1

    return Policy("counter", lambda key: None, act, init_carry=lambda p: jnp.int32(0))


def test_a_refilled_slot_starts_its_policy_carry_afresh():
    """60 executions through one worker's 48 slots: 12 start in a slot refilled after another
    execution ended.  With a carry that stops the ego after 100 ticks, every execution ends
    where it ends with two workers (30 executions each, no refill); and the final carry that
    comes back is each execution's own: the ticks it was stepped."""
    suite = load_suite()
    execs = engine.build_executions(suite.select([p.pair_id for p in suite.pairs[:20]]),
                                    bucket=True)  # fmt: skip
    pol = _counter_policy()
    refilled, _ = split.run_split(pol, execs.scenarios, None, 300, default_settings(), workers=1)
    fresh, _ = split.run_split(pol, execs.scenarios, None, 300, default_settings(), workers=2)
    np.testing.assert_allclose(refilled.ego.xy, fresh.ego.xy, atol=1e-4)
    moved = np.linalg.norm(refilled.ego.xy - np.asarray(execs.scenarios.ego0.xy), axis=-1)
    assert (moved > 5.0).all()  # every execution drove before it stopped
    assert np.allclose(refilled.ego.speed, 0.0, atol=0.5)  # and stopped: its carry counted
    for run in (refilled, fresh):
        np.testing.assert_array_equal(run.policy_carry, run.tick)


def test_two_runs_give_the_same_bits():
    suite = load_suite().subset(1)
    execs = engine.build_executions(suite, bucket=True)
    from lantern_jax.policies.registry import get_policy

    ego = get_policy("ego")
    params = ego.init(jax.random.PRNGKey(0))
    one, _ = split.run_split(ego, execs.scenarios, params, execs.max_ticks, default_settings())
    two, _ = split.run_split(ego, execs.scenarios, params, execs.max_ticks, default_settings())
    jax.tree.map(np.testing.assert_array_equal, one, two)


def test_the_layout_is_the_backends(monkeypatch):
    """On the CPU one worker per core steps SPLIT_SLOTS executions each; on another backend (a
    GPU, whose one device runs the threads' calls one after another) one worker steps the
    accelerator layout's slots.  The environment variable sets the workers on either, and a
    bad value is refused naming it."""
    monkeypatch.delenv(split.WORKERS_ENV, raising=False)
    assert split.split_slots("cpu") == split.SPLIT_SLOTS
    assert split.worker_count("cpu") == len(os.sched_getaffinity(0))
    workers, slots = split.SPLIT_LAYOUT_ACCELERATOR
    assert (split.worker_count("gpu"), split.split_slots("gpu")) == (workers, slots)
    assert slots >= SUITE_BATCH_SHAPE[0]  # the built-in suite in one call per tick
    monkeypatch.setenv(split.WORKERS_ENV, "3")
    assert split.worker_count("gpu") == split.worker_count("cpu") == 3
    monkeypatch.setenv(split.WORKERS_ENV, "0")
    with pytest.raises(ValueError, match=split.WORKERS_ENV):
        split.worker_count("gpu")


def test_executions_are_dealt_longest_first_round_robin():
    timeout = np.asarray([10.0, 40.0, 20.0, 40.0, 30.0])
    dealt = split.deal(timeout, 2)
    assert [list(d) for d in dealt] == [[1, 4, 0], [3, 2]]
    assert sorted(np.concatenate(dealt)) == list(range(5))


# ---------------------------------------------------------------------------------------------
# the path's choice
# ---------------------------------------------------------------------------------------------
def test_the_path_depends_on_the_policy_and_the_batch_only():
    """The package's policies run fused (their programs are kept), a policy from outside the
    package split; bulk batches fused; an explicit request wins.  Nothing cached and not the
    backend enters the choice, so a run gives the same bits whatever ran before it."""
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.sim.switch import policy_switch

    mine = Policy("p", lambda k: None, lambda p, o: jnp.zeros((NUM_WAYPOINTS, 2)))
    coop = get_policy("coop")
    n = 360
    assert choose_path(mine, n).path == "split"
    kept = choose_path(coop, n)
    assert kept.path == "fused" and "compiled once and kept" in kept.reason
    assert choose_path(mine, engine.SPLIT_MAX_EXECUTIONS).path == "split"
    bulk = choose_path(mine, engine.SPLIT_MAX_EXECUTIONS + 1)
    assert bulk.path == "fused" and "bulk" in bulk.reason
    assert choose_path(coop, n, "split").path == "split"
    assert choose_path(mine, n, "fused").path == "fused"
    assert str(PathChoice("split", "why")) == "split (why)"
    with pytest.raises(ValueError, match="not one of"):
        choose_path(mine, n, "fast")
    switch = policy_switch([get_policy("expert"), coop])
    assert choose_path(switch, 10).path == "fused"
    with pytest.raises(ValueError, match="not possible here: a policy switch"):
        choose_path(switch, 10, "split")


def test_evaluate_refuses_an_unknown_path_before_compiling():
    from lantern_jax.apps.evaluation import evaluate

    with pytest.raises(ValueError, match="path 'fast' is not one of auto, fused, split"):
        evaluate(["coop"], suite=load_suite().subset(1), path="fast", progress=False)


# ---------------------------------------------------------------------------------------------
# no stale program
# ---------------------------------------------------------------------------------------------
def _constant(speed: float):
    def act(params, obs):
        k = jnp.arange(1, NUM_WAYPOINTS + 1, dtype=jnp.float32) * WAYPOINT_DT
        return jnp.stack([k * speed, jnp.zeros_like(k)], -1)

    return act


def test_a_changed_policy_never_reuses_a_stale_policy_program():
    """Two policies with the same name, sensors and code text but different behaviour (as a
    file edited and loaded again): each gets its own program and its own result."""
    execs = engine.build_executions(load_suite().select(["pe_0001"]), bucket=True)
    settings = default_settings()
    finals = []
    for speed in (2.0, 6.0):
        pol = Policy("edited", lambda k: None, _constant(speed))
        before = set(programs._EXECUTABLES)
        final, _ = split.run_split(pol, execs.scenarios, None, 200, settings)
        # compiled its own (a new key: the count alone stays put once the store is full)
        assert set(programs._EXECUTABLES) - before
        finals.append(final)
    assert not np.allclose(finals[0].ego.xy, finals[1].ego.xy)


def test_a_changed_setting_never_reuses_a_stale_world_program():
    """A static setting (a tick window) is another world program; a traced one (a threshold)
    runs the same program with its new value."""
    execs = engine.build_executions(load_suite().select(["pe_0001"]), bucket=True)
    pol = Policy("steady", lambda k: None, _constant(5.0))
    base = default_settings()
    split.run_split(pol, execs.scenarios, None, 100, base)
    world_programs = lambda: {k for k in programs._EXECUTABLES if k[0] is split._tick_jit}  # noqa: E731
    known = world_programs()
    traced = base.replace(scoring=dataclasses.replace(base.scoring, ttc_norm_s=2.5))
    split.run_split(pol, execs.scenarios, None, 100, traced)
    assert world_programs() == known
    window = base.replace(scoring=dataclasses.replace(base.scoring, react_window_s=0.75))
    a = split.world_signature(jax.tree.map(lambda x: np.asarray(x)[0], execs.scenarios), base, 48)
    b = split.world_signature(jax.tree.map(lambda x: np.asarray(x)[0], execs.scenarios), window,
                              48)  # fmt: skip
    assert a.identity() != b.identity()
    assert isinstance(window, Settings)


def test_the_store_refuses_a_world_program_of_another_signature(tmp_path, monkeypatch):
    """A stored world program answers only its own signature: another slot count or another
    scenario shape (the pair cut to its own actor and lane slots) has another key, and the
    program stored under one key is not found under the other."""
    monkeypatch.setattr(program_store, "store_dir", lambda: tmp_path)
    execs = engine.build_executions(load_suite().select(["pe_0001"]), bucket=True)
    one = jax.tree.map(lambda x: np.asarray(x)[0], execs.scenarios)
    settings = default_settings()
    device = jax.local_devices()[0]
    setp = split._pack_one(Layout.of(settings), settings)
    keys = {}
    for name, scen, slots in (("suite", one, 48), ("slots", one, 24),
                              ("shape", trim_padding(one), 48)):  # fmt: skip
        sig = split.world_signature(scen, settings, slots)
        args = split._tick_args(sig, setp, device)
        keys[name] = program_store.program_key((sig.identity(), "tick"), args)
    assert len(set(keys.values())) == 3 and None not in keys.values()
    program_store.save(keys["suite"], split.world_programs(
        split.world_signature(one, settings, 48), setp, device).tick)  # fmt: skip
    assert program_store.exists(keys["suite"])
    assert not program_store.exists(keys["slots"]) and not program_store.exists(keys["shape"])
    assert program_store.load(keys["slots"]) is None
