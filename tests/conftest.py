"""Shared closed-loop runners for the rollout and protocol tests.

Compiling a rollout dominates the cost of these tests, so a handful of jitted runners are built
once per session and every test feeds them worlds of the same shapes:

* ``sim.batch(worlds, modes, values)`` — ``jit(vmap(rollout(..., record=True)))`` over a batch
  padded to :data:`BATCH` executions, :data:`HORIZON` ticks;
* ``sim.single(world, mode, value)`` — ``jit(rollout(..., record=True))`` of one execution;
* ``sim.evaluate(worlds, mode, value)`` — ``jit(rollout_batch(...))`` (early-exit driver).

All three drive the same *probe* policy: its parameters ``(mode, value)`` pick one of the
reference policies or a small scripted test behaviour (see ``MODE_*``), so one compilation serves
every policy the tests need.  Under ``vmap`` each execution of a batch has its own mode.  The
probe declares every sensor the references need (the ``expert``'s ground truth, ``coop``'s
warning text), so every mode pays for them; for ``ego`` and ``coop`` it hands the reference act
function only what their own sensors would deliver (no ground truth; no text for ``ego``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from xla_flags import xla_flags_for_tests

#: XLA flags of every test process (and of the processes the tests start, which inherit them):
#: XLA's CPU backend with its earlier fusion emitters, where the installed jaxlib has them
#: (``tests/xla_flags.py`` says why and where not).  The test that starts processes with
#: ``XLA_FLAGS`` of their own (the written promise across devices and batches) runs the default
#: emitters, as a user's process does.  An ``XLA_FLAGS`` that names the flag wins, e.g.
#: ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=true`` runs the tests as a user's process compiles.
#: ``.ci/run`` gives the documentation build's notebook kernels the same flags.
TEST_XLA_FLAGS = xla_flags_for_tests()
if TEST_XLA_FLAGS and TEST_XLA_FLAGS.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()

#: No cache folder path in the programs' cache keys, as ``import lantern_jax`` sets it on a
#: CPU-only install where JAX is not imported first (here it is, so this file does it;
#: ``lantern_jax.core.jax_setup.xla_caches_default``, checked in ``tests/test_jax_setup.py``):
#: the tests then compile the programs a user's process compiles, whose keys do not depend on
#: the cache folder.  Exported, so the processes the tests start (and the notebooks' kernels)
#: share it.
TEST_XLA_CACHES = "none"
os.environ.setdefault("JAX_PERSISTENT_CACHE_ENABLE_XLA_CACHES", TEST_XLA_CACHES)

#: XLA CPU devices of the processes the tests start (the command line, scripts), exported: one,
#: as in the test processes themselves (JAX is imported above before ``lantern_jax``, which
#: leaves JAX's one device).  A program for two devices is another program, so a command-line
#: process on one device per core compiled again what the in-process tests had put in the
#: shared cache (the default tier on a 2-core CPU, cold cache: 93 fewer programs compiled with
#: it, docs/performance.md).  The tests of other device counts set their own
#: (``tests/test_bad_inputs.py``'s written promise, ``tests/test_multihost.py``,
#: ``tests/test_jax_setup.py``); a count set before the tests start is kept.
TEST_CPU_DEVICES = "1"
os.environ.setdefault("LANTERN_JAX_CPU_DEVICES", TEST_CPU_DEVICES)

import jax  # XLA reads its flags when JAX starts its backend
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import NUM_WAYPOINTS, WAYPOINT_DT
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.sim.rollout import rollout, rollout_batch
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import FRONT_CAMERA, PRIVILEGED, WARNING
from lantern_jax.types.world import tree_stack

#: JAX's persistent compilation cache for the whole test session, from its first compile on:
#: ``$JAX_COMPILATION_CACHE_DIR`` when set (``.ci/run`` sets it), else ``.jax_cache/`` in the
#: project root (git-ignored).  Without this, the first in-process command-line test would
#: switch the cache on half-way through the session (``lantern-jax`` enables it by default), in
#: the user's own cache folder.  Every program is kept, however short its compilation (JAX's
#: default keeps only those of >= 1 s): the tests run about 2,300 small programs (eager
#: operations, helpers), whose compilation is most of a warm run's time.  Both settings are
#: exported, so the command-line and notebook subprocesses the tests start share them.
COMPILE_CACHE_DIR = os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
jax.config.update("jax_enable_compilation_cache", True)
jax.config.update("jax_compilation_cache_dir", COMPILE_CACHE_DIR)
jax.config.update(
    "jax_persistent_cache_min_compile_time_secs",
    float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
)

#: Bytes of constants one compiled program of the tests may capture: past it JAX warns, and
#: the warning fails the test (pyproject.toml's ``filterwarnings``).  A captured array is copied
#: into the program, which the persistent cache then serialises and writes: the training
#: programs, when they captured the 33 MB embedding table, took 6.7-8.1 s to compile against
#: 0.7-1.9 s with it an argument (``benchmarks/bench_fit_compile.py``).  The package's programs
#: take such tables as arguments; a brax environment's programs capture its scene bank
#: (0.4 MB for the tests' bank), which brax's interface leaves no other way to pass.
CAPTURED_CONSTANTS_LIMIT_BYTES = 1_000_000
jax.config.update("jax_captured_constants_warn_bytes", CAPTURED_CONSTANTS_LIMIT_BYTES)

#: Most worker processes ``-n auto`` starts (pyproject's pytest options).  Every worker compiles
#: its own programs and holds 1-2 GB; past one worker per core they only compete for it.
MAX_WORKERS = 4


def pytest_xdist_auto_num_workers(config) -> int:
    """Worker count for ``-n auto``: ``$PYTEST_XDIST_AUTO_NUM_WORKERS`` when set, else one per
    core this process may run on, at most :data:`MAX_WORKERS`."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return int(os.environ["PYTEST_XDIST_AUTO_NUM_WORKERS"])
    return max(1, min(len(os.sched_getaffinity(0)), MAX_WORKERS))


def pytest_configure(config) -> None:
    """Before any test runs (in the controlling process, before pytest-xdist starts its
    workers): compile the world program of the built-in suite's batch shape once and keep it
    in the session's program store (:func:`lantern_jax.sim.engine.warm_world`), so that every
    evaluation in every worker compiles only its policy's own program.
    ``LANTERN_TEST_WARM_WORLD=0`` skips it (each worker then compiles what it needs)."""
    if hasattr(config, "workerinput") or os.environ.get("LANTERN_TEST_WARM_WORLD") == "0":
        return
    if config.getoption("collectonly", False):
        return
    from lantern_jax.sim.engine import warm_world

    warm_world()


#: s, each test file's share of a tier's test time on the 2-core CPU, files over 3 s: the
#: default tier's from ``benchmarks/profile_tests.py --workers 2 --cold`` (2026-12-05), the slow
#: tier's from the ``--durations`` of a fresh-clone ``.ci/run`` that day (its 40 slowest tests,
#: which hold nearly all of the tier's time).  pytest-xdist hands whole files to its workers
#: in the order of the collection (``--no-loadscope-reorder`` in pyproject.toml; its own order
#: is by the number of tests in a file), so
#: :func:`pytest_collection_modifyitems` puts the longest files first and the short ones fill
#: in at the end, rather than a long file starting last while the other worker idles.  A file
#: not listed runs after these, in its usual order: the table orders the files, never selects
#: tests, and a stale entry costs only balance.
FILE_SECONDS = {
    "default": {
        "tests/test_bad_inputs.py": 58, "tests/test_evaluate.py": 52, "tests/test_unseen.py": 43,
        "tests/test_split.py": 41, "tests/test_rollout.py": 38, "tests/test_learned.py": 31,
        "tests/test_settings.py": 30, "tests/test_extension.py": 20, "tests/test_dynamics.py": 18,
        "tests/test_plot_pair.py": 18, "tests/test_ensemble.py": 15,
        "tests/test_policy_boundary.py": 14, "tests/test_jax_setup.py": 14,
        "tests/test_adversary.py": 14, "tests/test_false_brake.py": 14, "tests/test_cli.py": 13,
        "tests/test_bad_inputs_evidence.py": 12, "tests/test_expert.py": 11,
        "tests/test_envs.py": 11, "tests/test_scenarios.py": 10,
        "tests/test_distractor_drives.py": 10, "tests/test_switch.py": 9,
        "tests/test_diagnostics.py": 9, "tests/test_report_page.py": 8,
        "tests/test_visibility.py": 8, "tests/test_host_policy.py": 7, "tests/test_protocol.py": 7,
        "tests/test_stress.py": 7, "tests/test_suite.py": 6, "tests/test_scoring_telemetry.py": 6,
        "tests/test_allocator.py": 6, "tests/test_stream.py": 5, "tests/test_report_tables.py": 4,
        "tests/test_scoring_components.py": 4, "tests/test_viz.py": 4, "tests/test_geometry.py": 4,
        "tests/test_schedule.py": 3, "tests/test_warning_override.py": 3,
    },
    "slow": {
        "tests/test_stress.py": 298, "tests/test_cli.py": 224, "tests/test_settings.py": 159,
        "tests/test_closed_loop.py": 124, "tests/test_evaluate.py": 100, "tests/test_envs.py": 94,
        "tests/test_bad_inputs.py": 81, "tests/test_rollout.py": 59, "tests/test_multihost.py": 54,
        "tests/test_fragility.py": 50, "tests/test_policy_boundary.py": 50,
        "tests/test_stream.py": 38, "tests/test_unseen.py": 34, "tests/test_program_store.py": 34,
        "tests/test_suite.py": 32, "tests/test_dataset.py": 30, "tests/test_host_policy.py": 24,
        "tests/test_vector_env.py": 15, "tests/test_training.py": 9, "tests/test_learned.py": 8,
    },
}  # fmt: skip


def file_seconds(markexpr: str) -> dict[str, float]:
    """:data:`FILE_SECONDS` of the tier a ``-m`` expression selects: the default tier's for one
    that leaves out ``slow``, the slow tier's for one that asks for it, both added otherwise."""
    if "not slow" in markexpr:
        return FILE_SECONDS["default"]
    if "slow" in markexpr:
        return FILE_SECONDS["slow"]
    both = dict(FILE_SECONDS["default"])
    for name, seconds in FILE_SECONDS["slow"].items():
        both[name] = both.get(name, 0) + seconds
    return both


def pytest_collection_modifyitems(config, items) -> None:
    """Longest test files first (:data:`FILE_SECONDS`); a stable sort, so the tests of a file
    keep their order and unlisted files theirs."""
    seconds = file_seconds(config.getoption("markexpr", "") or "")
    items.sort(key=lambda item: -seconds.get(item.nodeid.split("::")[0], 0))


#: Modules that register scenario families when imported (the unseen hazards; a user's family
#: file loaded by the command line; the test family): :func:`registrations_stay_in_their_test`
#: forgets them with the families they registered, so that a later import registers again.
REGISTERING_MODULES = (
    "lantern_jax.apps.transfer",
    "lantern_jax.scenarios.unseen",
    "family_example",
)
USER_FAMILY_MODULE_PREFIX = "lantern_jax_user_families_"


@pytest.fixture(autouse=True)
def registrations_stay_in_their_test():
    """Families a test registers (and their warning texts) are forgotten when it ends.

    A family left registered would change what later tests see (the families of the
    registry, the default text bank, suites built from the registry).  Registrations made
    before the test (a module fixture's) are kept."""
    from lantern_jax.scenarios import registry

    state, before = registry.snapshot(), set(sys.modules)
    yield
    if registry.snapshot() == state:
        return
    registry.restore(state)
    for name in set(sys.modules) - before:
        if name in REGISTERING_MODULES or name.startswith(USER_FAMILY_MODULE_PREFIX):
            parent, _, child = name.rpartition(".")
            sys.modules.pop(name)
            if parent in sys.modules and getattr(sys.modules[parent], child, None) is not None:
                delattr(sys.modules[parent], child)  # ``from parent import child`` imports again


HORIZON = 600  # ticks (30 s) of the shared runners
BATCH = 12  # executions per call of the shared batched runner

MODE_EXPERT = 0  # the reference ``expert``
MODE_EGO = 1  # the reference ``ego``
MODE_COOP = 2  # the reference ``coop``
MODE_NAN_BELOW = 3  # expert, but NaN waypoints whenever ego_speed < value
MODE_STOP_PAST = 4  # constant speed v_ref, all-zero waypoints once dist_to_route_end < value
MODE_CONST = 5  # straight waypoints at a constant speed of ``value`` m/s


def constant_speed_waypoints(speed: jax.Array) -> jax.Array:
    """(10, 2) ego-frame waypoints straight ahead at ``speed`` m/s."""
    k = jnp.arange(1, NUM_WAYPOINTS + 1, dtype=jnp.float32) * WAYPOINT_DT
    return jnp.stack([k * speed, jnp.zeros_like(k)], axis=-1)


def _make_probe_policy() -> Policy:
    ref = [get_policy(n) for n in ("ego", "coop")]
    act = ref[0].act
    # ego and coop share one act function and differ only in their sensors (coop reads the
    # warning text), so a per-execution choice between them is a choice of what it is shown.
    assert all(p.act is act for p in ref), "reference policies no longer share act"
    ref_params = ref[0].init(jax.random.PRNGKey(0))
    expert = get_policy("expert")
    expert_params = expert.init(jax.random.PRNGKey(0))

    def probe_act(params, obs):
        mode, value = params
        text = mode == MODE_COOP
        camera_obs = obs.replace(
            privileged=None,
            warning_tokens=jnp.where(text, obs.warning_tokens, PAD_ID),
            warning_values=jnp.where(text, obs.warning_values, 0.0),
        )
        camera = act(ref_params, camera_obs).astype(jnp.float32)
        # the expert, also under the scripted behaviours that wrap it
        use_expert = (mode == MODE_EXPERT) | (mode > MODE_COOP)
        planned = jnp.where(use_expert, expert.act(expert_params, obs), camera)
        cruise = constant_speed_waypoints(obs.v_ref)
        out = jnp.where(mode == MODE_NAN_BELOW, jnp.where(obs.ego_speed < value, jnp.nan, planned),
                        planned)  # fmt: skip
        out = jnp.where(mode == MODE_STOP_PAST,
                        jnp.where(obs.dist_to_route_end < value, 0.0, cruise), out)  # fmt: skip
        out = jnp.where(mode == MODE_CONST, constant_speed_waypoints(value), out)
        return out

    return Policy(
        "probe",
        lambda key: (jnp.int32(MODE_EXPERT), jnp.float32(0.0)),
        probe_act,
        "test probe: a reference policy or a scripted behaviour chosen by its parameters",
        sensors=(FRONT_CAMERA, WARNING, PRIVILEGED),
    )


def to_numpy(tree):
    return jax.tree.map(np.asarray, tree)


class Sim:
    """Jitted runners built once; ``traces`` counts how often each one was traced."""

    def __init__(self) -> None:
        self.traces = {"single": 0, "batch": 0, "evaluate": 0}
        policy = _make_probe_policy()
        self.policy = policy

        def one(world, mode, value, counter=None):
            if counter is not None:
                self.traces[counter] += 1
            return rollout(world, policy, (mode, value), HORIZON, record=True)

        def single(world, mode, value):
            return one(world, mode, value, "single")

        def batch(worlds, modes, values):
            self.traces["batch"] += 1
            return jax.vmap(one)(worlds, modes, values)

        def evaluate(worlds, mode, value):
            self.traces["evaluate"] += 1
            return rollout_batch(worlds, policy, (mode, value), HORIZON)

        self.single_fn = jax.jit(single)
        self.batch_fn = jax.jit(batch)
        self.evaluate_fn = jax.jit(evaluate)

    def single(self, world, mode=MODE_EXPERT, value=0.0):
        """(final SimState, TickRecord) of one execution, as numpy."""
        out = self.single_fn(world, jnp.int32(mode), jnp.float32(value))
        return to_numpy(out)

    def batch(self, worlds, modes=MODE_EXPERT, values=0.0):
        """(final SimState, TickRecord) of up to BATCH executions, as numpy (unpadded)."""
        n = len(worlds)
        if not 1 <= n <= BATCH:
            raise ValueError(f"batch of {n} executions; the shared runner takes 1..{BATCH}")
        modes = np.broadcast_to(np.asarray(modes, np.int32), (n,))
        values = np.broadcast_to(np.asarray(values, np.float32), (n,))
        pad = BATCH - n
        stacked = tree_stack(list(worlds) + [worlds[-1]] * pad)
        m = jnp.asarray(np.concatenate([modes, np.repeat(modes[-1:], pad)]))
        v = jnp.asarray(np.concatenate([values, np.repeat(values[-1:], pad)]))
        out = to_numpy(self.batch_fn(stacked, m, v))
        return jax.tree.map(lambda x: x[:n], out)

    def evaluate(self, worlds, mode=MODE_EXPERT, value=0.0):
        """Final batched SimState of ``rollout_batch`` over BATCH worlds, as numpy."""
        if len(worlds) != BATCH:
            raise ValueError(f"rollout_batch runner takes exactly {BATCH} worlds")
        out = self.evaluate_fn(tree_stack(list(worlds)), jnp.int32(mode), jnp.float32(value))
        return to_numpy(out)


@pytest.fixture(scope="session")
def sim() -> Sim:
    return Sim()


def select(tree, i):
    """Element ``i`` of a batched numpy pytree."""
    return jax.tree.map(lambda x: x[i], tree)


@pytest.fixture(scope="session")
def obs():
    """The observation of a policy reading the warning, at the start of a straight 120-m road
    with a pedestrian emergence's markers (the learned models' and ensembles' tests)."""
    from lantern_jax.scenarios.handmade import straight_scene
    from lantern_jax.sim.observe import observe
    from lantern_jax.sim.state import init_state

    world = straight_scene([], length=120.0, speed=8.0, s_warn=22.0, s_event=31.0,
                           s_conflict=40.0, hazard_index=0, clear_s=22.0)  # fmt: skip
    return jax.jit(lambda w: observe(w, init_state(w), (WARNING,)))(world)


@pytest.fixture(scope="session")
def embedding():
    """(V, D) float32, the shipped token-embedding table as a device array."""
    from lantern_jax.types.language import load_embedding

    return jnp.asarray(load_embedding(), jnp.float32)


@pytest.fixture(scope="session")
def family_pairs():
    """One (world_a, world_b, meta) pair per family, fixed seeds, varied weather."""
    from lantern_jax.core.constants import FAMILIES, WEATHERS
    from lantern_jax.scenarios.families import build_pair, sample_params

    out = {}
    for i, fam in enumerate(FAMILIES):
        params = sample_params(fam, np.random.default_rng(1000 + i), WEATHERS[i % len(WEATHERS)])
        if fam == "OR":  # the fastest lead van and the shortest route: both routes end in 30 s
            params["lead_speed_kmh"] = 20.0
            params["route_length"] = round(params["reveal_s"] + params["object_ahead"] + 29.5, 3)
        out[fam] = build_pair(params)
    return out


@pytest.fixture(scope="session")
def family_runs(sim, family_pairs):
    """The six pairs under the expert: (worlds, (final, records)); index 2 i is Route A of
    family i, 2 i + 1 its Route B."""
    from lantern_jax.core.constants import FAMILIES

    worlds = [w for f in FAMILIES for w in family_pairs[f][:2]]
    return worlds, sim.batch(worlds, MODE_EXPERT)


@pytest.fixture
def shared_runner(sim, monkeypatch):
    """Route :func:`lantern_jax.apps.diagnostics.run_recorded` through the session's compiled batch
    runner (no compile of its own); ``shared_runner["mode"]`` picks the reference policy."""
    from lantern_jax.apps import diagnostics
    from lantern_jax.scoring.metrics import finalize

    chosen = {"mode": MODE_COOP}

    def run(policy, params, scenarios):
        del policy, params
        final, rec = sim.batch(scenarios, chosen["mode"])
        return final, rec, to_numpy(jax.vmap(finalize)(final.telemetry))

    monkeypatch.setattr(diagnostics, "run_recorded", run)
    return chosen
