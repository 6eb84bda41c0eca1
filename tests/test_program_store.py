"""The program store (:mod:`lantern_jax.io.program_store`): compiled evaluation programs kept on
disk and loaded by a later process without tracing or compiling.

* a new process loads a stored program instead of tracing it, with identical result files;
  a program that JAX's own cache served is not stored;
* what cannot be keyed with certainty (a policy from outside the package, a lambda, a user
  object) is not stored, and everything that determines a program changes its key;
* an unreadable entry is deleted and the program compiled again; the store keeps the most
  recently used programs; it is off when JAX's compilation cache is off.
"""

from __future__ import annotations

import collections
import functools
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.io import program_store
from lantern_jax.policies.base import Policy
from lantern_jax.policies.expert import expert_act
from lantern_jax.policies.reference import reference_act
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.sim import programs
from lantern_jax.sim.rollout import chunk_runner
from lantern_jax.sim.settings import DEFAULT_SETTINGS

PAIR = ["pe_0001"]


@pytest.fixture
def store(tmp_path, monkeypatch):
    """A fresh store folder and an empty in-process program cache (restored afterwards)."""
    monkeypatch.setattr(program_store, "store_dir", lambda: tmp_path)
    monkeypatch.setattr(programs, "_EXECUTABLES", collections.OrderedDict())
    return tmp_path


def _coop_user_act(params, obs):
    """A policy defined outside the package (here: in a test module)."""
    return reference_act(params, obs)


def _evaluate_in_new_process(cache: Path, out: Path) -> float:
    """``lantern-jax evaluate`` of ``coop`` on one pair in a fresh process with its own cache
    folder; returns the seconds its profile gives to loads from the program store."""
    from conftest import TEST_XLA_FLAGS  # the tests' flags, no device count of their own

    env = dict(os.environ, LANTERN_JAX_CACHE_DIR=str(cache), LANTERN_JAX_CPU_DEVICES="1",
               XLA_FLAGS=TEST_XLA_FLAGS)  # fmt: skip
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    res = subprocess.run(
        [sys.executable, "-m", "lantern_jax", "evaluate", "--policy", "coop", "--pairs",
         ",".join(PAIR), "--out", str(out), "--quiet", "--profile"],
        env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    profile = res.stdout.split("Where the time went", 1)[1]
    rows = {}
    for line in profile.splitlines()[1:]:  # label, seconds, share, "%"
        if line.strip():
            label, seconds, _, _ = line.strip().rsplit(None, 3)
            rows[label] = float(seconds)
    assert rows["trace + lower"] >= 0.0 and rows["XLA compile"] >= 0.0
    return rows["program load"], rows["trace + lower"]


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_new_process_loads_the_stored_program_without_tracing_and_same_results(tmp_path):
    cache = tmp_path / "cache"
    load, lower = _evaluate_in_new_process(cache, tmp_path / "first")
    assert load == 0.0 and lower > 0.0
    # the initial-state program, the rollout and the scoring program
    assert len(list((cache / program_store.STORE_SUBDIR).glob("*.program"))) == 3
    load, lower = _evaluate_in_new_process(cache, tmp_path / "second")
    assert load > 0.0 and lower == 0.0
    for name in ("route_level_results.csv", "family_cus.csv", "decomposition.csv"):
        assert (tmp_path / "first" / name).read_bytes() == (tmp_path / "second" / name).read_bytes()


#: A stress cell's verification of the nominal scene (``ego``, the first PE pair, the adversary
#: space): prints, as JSON, its verdict and, for the first request of each stress program, whether
#: it was loaded from the program store and the seconds spent tracing and lowering it.
STRESS_VERIFY_SCRIPT = """
import json
import numpy as np
from lantern_jax.core.jax_setup import configure_compile_cache
configure_compile_cache(True)
from lantern_jax.apps.stress import report, verify
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.sim import programs

asked = []
executable = programs.executable

def kept(fn, *args, identity=None, **kwargs):
    spent = {}
    exe = executable(fn, *args, identity=identity, timings=spent, **kwargs)
    name = identity[0] if identity else None
    if str(name).startswith("stress") and name not in [n for n, _, _ in asked]:  # first request
        asked.append((name, spent["program load"] > 0.0, spent["trace + lower"]))
    return exe

programs.executable = kept  # what programs.stored calls
pair = next(p for p in load_suite().pairs if p.family == "PE")
problem = report.make_problem(pair, get_policy("ego"), None, report.StressConfig(space="adversary"))
verdict = verify.Verifier(problem, batch=2)(np.zeros((1, problem.space.dim), np.float32))
print(json.dumps(dict(asked=asked, cus=verdict.cus.tolist(), failed=verdict.failed.tolist(),
                      clearance=verdict.clearance_m.tolist())))
"""


def _stress_verify_in_new_process(cache: Path) -> dict:
    """:data:`STRESS_VERIFY_SCRIPT` in a fresh process with its own cache folder."""
    import json

    from conftest import TEST_XLA_FLAGS

    env = dict(os.environ, LANTERN_JAX_CACHE_DIR=str(cache), LANTERN_JAX_CPU_DEVICES="1",
               XLA_FLAGS=TEST_XLA_FLAGS)  # fmt: skip
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    res = subprocess.run([sys.executable, "-c", STRESS_VERIFY_SCRIPT], env=env,
                         capture_output=True, text=True, timeout=600)  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_stress_cells_programs_load_in_a_new_process_with_the_same_verdict(tmp_path):
    """A stress cell run again in a new process (another seed, budget or method list) loads
    its programs from the store: the pair builder and the hard program of the verification
    here, whose first process compiled and kept them (the soft program takes the same road,
    ``tests/test_stress.py`` checks that it asks for it)."""
    cache = tmp_path / "cache"
    first = _stress_verify_in_new_process(cache)
    assert [(name, loaded) for name, loaded, _ in first["asked"]] == [
        ("stress-pairs", False), ("stress-hard", False)]  # fmt: skip
    assert all(traced > 0.0 for _, _, traced in first["asked"])
    second = _stress_verify_in_new_process(cache)
    assert [(name, loaded, traced) for name, loaded, traced in second["asked"]] == [
        ("stress-pairs", True, 0.0), ("stress-hard", True, 0.0)]  # fmt: skip
    for field in ("cus", "failed", "clearance"):
        assert second[field] == first[field], field


def test_a_program_served_by_jax_cache_is_not_fresh():
    """What JAX's persistent cache served cannot be stored (see ``compile_lowered``)."""
    if not jax.config.jax_enable_compilation_cache:
        pytest.skip("needs the test session's persistent compilation cache")
    salt = float(np.random.default_rng().uniform(1.0, 2.0))  # a program no run compiled before
    x = np.arange(5, dtype=np.float32)
    _, fresh = program_store.compile_lowered(jax.jit(lambda v: jnp.cos(v) * salt).lower(x))
    assert fresh
    # the same program again, through a new function object: JAX's cache serves it
    # (the test session keeps every program, conftest.py)
    _, fresh = program_store.compile_lowered(jax.jit(lambda v: jnp.cos(v) * salt).lower(x))
    assert not fresh


def test_a_program_jax_hands_back_from_memory_is_not_fresh():
    """A program lowered again in the same process is the module JAX lowered the first time,
    and JAX gives back the executable it made of it then, without a compile or a cache hit.
    When that executable came from JAX's persistent cache it cannot be stored whole: an entry
    written from it failed in a later process with "Function ... not found".  So only the
    compile that XLA ran here counts as fresh, and another thread's compile at the same moment
    does not make this thread's program fresh."""
    if not jax.config.jax_enable_compilation_cache:
        pytest.skip("needs the test session's persistent compilation cache")
    salt = float(np.random.default_rng().uniform(1.0, 2.0))  # a program no run compiled before
    x = np.arange(5, dtype=np.float32)
    first = jax.jit(lambda v: jnp.tan(v) * salt)
    _, fresh = program_store.compile_lowered(first.lower(x))
    assert fresh
    _, again = program_store.compile_lowered(first.lower(x))  # JAX's executable, from memory
    assert not again
    served = jax.jit(lambda v: jnp.tan(v) * salt)  # a new function: JAX's cache serves it
    compiled, fresh = program_store.compile_lowered(served.lower(x))
    assert not fresh

    class LoweredBesideAnotherCompile:
        """``served``'s program lowered again, compiled while another thread compiles a new
        program (as the split path compiles its programs side by side)."""

        def compile(self):
            other = threading.Thread(target=lambda: jax.jit(lambda v: v * (salt + 1.0)).lower(x)
                                     .compile())  # fmt: skip
            other.start()
            other.join()
            return served.lower(x).compile()

    again, fresh = program_store.compile_lowered(LoweredBesideAnotherCompile())
    assert again.runtime_executable() is compiled.runtime_executable() and not fresh


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_policy_from_outside_the_package_is_compiled_not_stored(store, monkeypatch):
    keyed = []
    real = program_store.program_key

    def spy(identity, args):
        key = real(identity, args)
        kind = identity[0] if isinstance(identity[0], str) else identity[0][0]
        keyed.append((kind, key is not None))
        return key

    monkeypatch.setattr(program_store, "program_key", spy)
    coop = get_policy("coop")
    mine = Policy("mine", coop.init, _coop_user_act, "coop, defined in a test module")
    result = evaluate([mine], suite=load_suite().select(PAIR), progress=False)
    assert len(result.route_table) == 2  # it ran
    assert result.runs[0].program.startswith("split")
    # only the programs that do not depend on the policy can be keyed: the world's, not the
    # policy's own
    assert set(keyed) == {("finalize", True), ("initial_states", True), ("world", True),
                          ("policy-step", False)}  # fmt: skip


def _attention_elsewhere(*args, **kwargs):
    """A function from outside the package and its libraries (here: a test module)."""


def test_a_structure_that_names_a_function_by_its_address_is_keyed_by_its_name():
    """JAX writes a tree node's static data that holds a function by its memory address, which
    changes from process to process (a flax NNX model's parameters hold their attention
    function so).  Such a structure is described node by node instead: keyed when every
    function is this package's or a keyed library's, the same key for an equal tree, and not
    keyed at all for a function from elsewhere."""
    from flax import nnx
    from jax.tree_util import Partial

    x = np.zeros(3, np.float32)
    flax_fn = (Partial(nnx.dot_product_attention), x)
    assert " at 0x" in str(jax.tree.structure(flax_fn))
    key = program_store.program_key(("t",), flax_fn)
    assert key is not None and " at 0x" not in program_store.structure_text(
        jax.tree.structure(flax_fn))  # fmt: skip
    assert program_store.program_key(("t",), (Partial(nnx.dot_product_attention), x)) == key
    other = (Partial(nnx.dot_product_attention), x, x)
    assert program_store.program_key(("t",), other) not in (None, key)
    assert program_store.program_key(("t",), (Partial(_attention_elsewhere), x)) is None
    # a learned model's parameters (a flax NNX model: its attention function, tree structures
    # nested in its static data): keyed, and alike for two loads of the checkpoint
    learned = get_policy("learned-closed-loop")
    keys = {program_store.program_key(("t",), (learned.init(jax.random.PRNGKey(i)),))
            for i in range(2)}  # fmt: skip
    assert len(keys) == 1 and None not in keys


def test_describe_accepts_package_functions_and_refuses_what_it_cannot_vouch_for(monkeypatch):
    assert program_store.describe(expert_act) == program_store.describe(expert_act)
    plain = program_store.describe(expert_act)
    monkeypatch.setattr(expert_act, "marked", True, raising=False)
    assert program_store.describe(expert_act) != plain  # function attributes count
    monkeypatch.delattr(expert_act, "marked")
    for bad in (lambda p, o: o, _coop_user_act, object(), functools.partial(_coop_user_act)):
        with pytest.raises(program_store.Unkeyable):
            program_store.describe(bad)
    # a closure is described by what it closes over
    coop = get_policy("coop")
    short = chunk_runner(coop, None, 20, DEFAULT_SETTINGS)
    assert program_store.describe(short) == program_store.describe(
        chunk_runner(coop, None, 20, DEFAULT_SETTINGS)
    )
    assert program_store.describe(short) != program_store.describe(
        chunk_runner(coop, None, 40, DEFAULT_SETTINGS)
    )
    # policies: their program (act, sensors, carry); learned models by architecture
    learned, surround = get_policy("learned-coop"), get_policy("learned-surround")
    assert program_store.describe(learned.program) != program_store.describe(surround.program)
    # arrays by their bytes, not their repr (which elides)
    a = np.zeros(5000, np.float32)
    b = a.copy()
    b[2500] = 1.0
    assert program_store.describe(a) != program_store.describe(b)


def test_everything_that_determines_a_program_changes_its_key(monkeypatch):
    args = (np.zeros((3, 2), np.float32), {"v": jnp.ones(4)})
    base = program_store.program_key(("rollout", expert_act, True, 24, 20), args)
    assert base is not None and base == program_store.program_key(
        ("rollout", expert_act, True, 24, 20), args
    )
    others = [
        program_store.program_key(("rollout", reference_act, True, 24, 20), args),
        program_store.program_key(("rollout", expert_act, False, 24, 20), args),
        program_store.program_key(("rollout", expert_act, True, 16, 20), args),
        program_store.program_key(
            ("rollout", expert_act, True, 24, 20), (np.zeros((4, 2), np.float32), args[1])
        ),
        program_store.program_key(
            ("rollout", expert_act, True, 24, 20), (np.zeros((3, 2), np.int32), args[1])
        ),
        program_store.program_key(
            ("rollout", expert_act, True, 24, 20), (args[0], {"w": jnp.ones(4)})
        ),
    ]
    flags = os.environ.get("XLA_FLAGS", "")
    monkeypatch.setenv("XLA_FLAGS", flags + " --xla_cpu_enable_fast_math=false")
    others.append(program_store.program_key(("rollout", expert_act, True, 24, 20), args))
    monkeypatch.undo()
    monkeypatch.setattr(program_store, "code_fingerprint", lambda: "edited")
    others.append(program_store.program_key(("rollout", expert_act, True, 24, 20), args))
    assert None not in others
    assert len({base, *others}) == len(others) + 1
    assert program_store.program_key(("rollout", _coop_user_act), args) is None



def test_a_value_jit_places_itself_keys_as_the_array_jit_makes_of_it():
    """``jit`` runs one program whether a leaf is a NumPy value, a Python number or the array on
    the default device that ``jit`` would make of it, so the store finds one entry for all of
    them (a planner constant changed with ``np.float32`` in a notebook loads the program a run
    with the default parameters stored); weak types, dtypes and shapes still tell programs
    apart."""
    ident = ("rollout", expert_act, True, 24, 20)

    def key(leaf):
        return program_store.program_key(ident, ({"v": leaf},))

    same = [
        (np.float32(2.0), jnp.float32(5.0)),
        (np.zeros((2, 3), np.float64), jnp.zeros((2, 3), jnp.float32)),  # float64 -> float32
        (2.5, jnp.asarray(1.0)),  # a Python float: weakly typed float32
        (3, jnp.asarray(7)),  # a Python int: weakly typed int32
        (True, jnp.asarray(False)),
    ]
    for host, device in same:
        assert key(host) == key(device), (host, device)
    apart = [key(jnp.float32(1.0)), key(1.0), key(jnp.int32(1)), key(np.zeros(2, np.float32))]
    assert len(set(apart)) == len(apart)  # strong vs weak, float vs int, shape

def test_an_unreadable_entry_is_deleted_and_reported_missing(store):
    (store / "deadbeef.program").write_bytes(b"not a program")
    assert program_store.load("deadbeef") is None
    assert not (store / "deadbeef.program").exists()
    assert program_store.load("absent") is None


def test_a_freshly_compiled_program_round_trips_through_the_store(store):
    salt = float(np.random.default_rng().uniform(1.0, 2.0))  # a program no run compiled before
    x = np.linspace(0.0, 1.0, 7, dtype=np.float32)
    compiled, fresh = program_store.compile_lowered(jax.jit(lambda v: jnp.sin(v) * salt).lower(x))
    assert fresh
    assert program_store.save("k", compiled)
    loaded = program_store.load("k")
    np.testing.assert_array_equal(np.asarray(loaded(x)), np.asarray(compiled(x)))


def test_a_program_run_from_memory_stays_recently_used_in_the_store(store):
    """A program every evaluation of a process runs from memory (the world program, say) is
    used as much as one loaded from disk: each use marks its entry, so pruning removes the
    one-off programs saved after it, not it."""
    salt = float(np.random.default_rng().uniform(1.0, 2.0))  # a program no run compiled before
    fn = jax.jit(lambda v: jnp.cos(v) * salt)
    x = np.linspace(0.0, 1.0, 5, dtype=np.float32)
    ident = ("rollout", expert_act, round(salt * 1e9))
    programs.executable(fn, x, identity=ident)
    (entry,) = store.glob("*.program")
    old = time.time() - 3600
    os.utime(entry, (old, old))
    programs.executable(fn, x, identity=ident)  # found in memory
    assert entry.stat().st_mtime > old + 3000
    for i in range(3):  # programs saved after it, never used again
        p = store / f"later{i}.program"
        p.write_bytes(b"x")
        os.utime(p, (old + 60 + i, old + 60 + i))
    program_store.prune(store, keep=1)
    assert list(store.glob("*.program")) == [entry]


def _after_an_edit(monkeypatch) -> None:
    """The package as if a file of it had been edited (every program key changes), in a new
    process (nothing compiled in memory)."""
    monkeypatch.setattr(program_store, "code_fingerprint", lambda: "edited")
    monkeypatch.setattr(programs, "_EXECUTABLES", collections.OrderedDict())


def test_after_an_edit_an_unchanged_program_is_found_by_what_it_lowers_to(store, monkeypatch):
    """Every key changes with the package, but a program that lowers to what it did is loaded
    from the earlier entry (not compiled: JAX's cache would serve it, and a program that cache
    serves cannot be stored), kept under the new key, and a later process of the edited package
    loads it by that key without lowering it."""
    salt = float(np.random.default_rng().uniform(1.0, 2.0))  # a program no run compiled before
    fn = jax.jit(lambda v: jnp.tanh(v) * salt)
    x = np.linspace(0.0, 1.0, 6, dtype=np.float32)
    ident = ("rollout", expert_act, round(salt * 1e9))
    before = np.asarray(programs.executable(fn, x, identity=ident)(x))
    assert len(list(store.glob("*.program"))) == len(list(store.glob("*.lowered"))) == 1

    _after_an_edit(monkeypatch)
    real = program_store.compile_lowered
    monkeypatch.setattr(program_store, "compile_lowered",
                        lambda lowered: pytest.fail("compiled again"))  # fmt: skip
    spent: dict = {}
    after = programs.executable(fn, x, identity=ident, timings=spent)
    assert spent["program load"] > 0.0 and spent["XLA compile"] == 0.0
    np.testing.assert_array_equal(np.asarray(after(x)), before)
    assert len(list(store.glob("*.program"))) == 2

    monkeypatch.setattr(programs, "_EXECUTABLES", collections.OrderedDict())
    spent = {}
    again = programs.executable(fn, x, identity=ident, timings=spent)
    assert spent["trace + lower"] == 0.0 and spent["program load"] > 0.0
    np.testing.assert_array_equal(np.asarray(again(x)), before)
    monkeypatch.setattr(program_store, "compile_lowered", real)


def test_after_an_edit_a_changed_or_removed_program_is_compiled(store, monkeypatch):
    salt = float(np.random.default_rng().uniform(1.0, 2.0))
    x = np.linspace(0.0, 1.0, 6, dtype=np.float32)
    ident = ("rollout", expert_act, round(salt * 1e9))
    programs.executable(jax.jit(lambda v: jnp.tanh(v) * salt), x, identity=ident)
    compiled = []
    real = program_store.compile_lowered
    monkeypatch.setattr(program_store, "compile_lowered",
                        lambda lowered: compiled.append(1) or real(lowered))  # fmt: skip

    _after_an_edit(monkeypatch)  # the edit changed what the program lowers to
    changed = jax.jit(lambda v: jnp.tanh(v) * salt + 1.0)
    out = programs.executable(changed, x, identity=ident)(x)
    np.testing.assert_allclose(np.asarray(out), np.tanh(x) * salt + 1.0, rtol=1e-6)
    assert compiled == [1]

    for entry in store.glob("*.program"):  # the edit kept the program, the store lost it
        entry.unlink()
    monkeypatch.setattr(program_store, "code_fingerprint", lambda: "edited again")
    monkeypatch.setattr(programs, "_EXECUTABLES", collections.OrderedDict())
    out = programs.executable(changed, x, identity=ident)(x)
    np.testing.assert_allclose(np.asarray(out), np.tanh(x) * salt + 1.0, rtol=1e-6)
    assert compiled == [1, 1]


def _entries(folder: Path, sizes: dict[str, int], suffix: str = ".program") -> None:
    """Entries named after ``sizes`` (bytes each, sparse: nothing is written), used in that
    order (the last most recently)."""
    now = time.time()
    for i, (name, size) in enumerate(sizes.items()):
        p = folder / f"{name}{suffix}"
        with open(p, "wb") as fh:
            fh.truncate(size)
        os.utime(p, (now - 100 + i, now - 100 + i))


def test_prune_keeps_the_most_recently_used(tmp_path):
    _entries(tmp_path, {f"p{i}": 1 for i in range(5)})
    removed = program_store.prune(tmp_path, keep=2)
    assert sorted(p.name for p in removed) == ["p0.program", "p1.program", "p2.program"]
    assert sorted(p.name for p in tmp_path.glob("*.program")) == ["p3.program", "p4.program"]


def test_prune_keeps_the_most_recently_used_within_a_byte_budget(tmp_path):
    """Entries are kept from the most recently used back while their sizes fit the budget;
    the first one that does not, and every older one, are removed (small old entries do not
    outlive a large newer one); the most recent is kept even when it alone is over."""
    _entries(tmp_path, {"old_small": 10, "big": 60, "mid": 30, "new": 20})
    removed = program_store.prune(tmp_path, max_bytes=55)
    assert sorted(p.name for p in removed) == ["big.program", "old_small.program"]
    assert sorted(p.name for p in tmp_path.glob("*.program")) == ["mid.program", "new.program"]
    assert program_store.prune(tmp_path, max_bytes=5) == [tmp_path / "mid.program"]
    assert [p.name for p in tmp_path.glob("*.program")] == ["new.program"]


def test_a_study_of_many_stress_cells_keeps_every_cells_programs(store):
    """The store's own budget, as :func:`~lantern_jax.io.program_store.save` prunes after a
    write: a study of 40 stress cells (each three programs of 7, 15 and 0.4 MB, measured on
    ``ego``'s first PE cell) written after the world program keeps every program (a count of
    32 programs kept ten such cells), and the values beside them are bounded apart."""
    assert program_store.MAX_STORED_BYTES >= 40 * 23 * 2**20
    sizes = {"world": 8 * 2**20}
    for c in range(40):
        sizes |= {f"hard{c}": 7 * 2**20, f"soft{c}": 15 * 2**20, f"pairs{c}": 400 * 2**10}
    _entries(store, sizes)
    assert program_store._write(store, "last", ("last", b""), ".program")
    assert len(list(store.glob("*.program"))) == len(sizes) + 1
    _entries(store, {f"v{i}": 10 for i in range(program_store.MAX_STORED_VALUES + 5)}, ".value")
    assert program_store._write(store, "newest", ("newest", 1), ".value")
    kept = {p.stem for p in store.glob("*.value")}
    assert len(kept) == program_store.MAX_STORED_VALUES and "newest" in kept and "v0" not in kept


def test_the_store_is_off_with_the_compilation_cache():
    was = jax.config.jax_enable_compilation_cache
    try:
        jax.config.update("jax_enable_compilation_cache", False)
        assert program_store.store_dir() is None
        assert not program_store.save("k", None)
        assert program_store.load("k") is None
    finally:
        jax.config.update("jax_enable_compilation_cache", was)


def test_static_settings_change_the_key_and_traced_ones_do_not():
    """Settings are arguments: their static part (tick windows) is in the arguments' tree
    structure, so a change is another key; a traced value (a threshold, a text of the bank) runs
    the same stored program with the new value; a bank past 128 texts has tables of another
    shape, another key."""
    args = (DEFAULT_SETTINGS,)
    base = program_store.program_key(("finalize",), args)
    window = DEFAULT_SETTINGS.replace(scoring=DEFAULT_SETTINGS.scoring.replace(react_window_s=3.0))
    bank = DEFAULT_SETTINGS.bank.with_text("PE", "non_actionable", "Road works ahead.")
    closing = DEFAULT_SETTINGS.replace(
        scoring=DEFAULT_SETTINGS.scoring.replace(closing_min_mps=2.0)
    )
    large = bank
    while len(large) <= 128:
        large = large.with_text(-1, "non_actionable", f"Road works {len(large)} km ahead.")
    assert program_store.program_key(("finalize",), (window,)) != base
    key = program_store.program_key(("finalize",), (DEFAULT_SETTINGS.replace(bank=bank),))
    assert key == base
    assert program_store.program_key(("finalize",), (closing,)) == base
    key = program_store.program_key(("finalize",), (DEFAULT_SETTINGS.replace(bank=large),))
    assert key != base


def test_an_edited_package_file_changes_the_key(tmp_path, monkeypatch):
    """A module edited (and reloaded in a notebook) is new code: the fingerprint of the
    package's files changes with a file's bytes."""
    edited = tmp_path / "module.py"
    edited.write_text("X = 1\n")
    files = program_store._package_files()
    monkeypatch.setattr(program_store, "_package_files", lambda: [*files, edited])
    monkeypatch.setattr(program_store, "_fingerprint", _unrooted_fingerprint)
    args = (np.zeros(3, np.float32),)
    before = program_store.program_key(("finalize",), args)
    assert program_store.program_key(("finalize",), args) == before
    edited.write_text("X = 22\n")  # other bytes (and size)
    assert program_store.program_key(("finalize",), args) != before


def _unrooted_fingerprint(signature: tuple) -> str:
    """``program_store._fingerprint`` for files outside the package folder too."""
    import hashlib

    h = hashlib.sha256()
    for name, _, _ in signature:
        h.update(name.encode() + b"\0" + Path(name).read_bytes())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------
# values kept beside the programs: the world signature, observation shapes, built worlds
# ---------------------------------------------------------------------------------------------
def test_a_value_round_trips_and_a_swapped_or_damaged_one_is_deleted(store):
    key = program_store.value_key("test", "a")
    assert key is not None and key != program_store.value_key("test", "b")
    assert program_store.value_key("test", "<function f at 0x7f00>") is None  # an address
    assert program_store.save_value(key, {"x": np.arange(3)})
    np.testing.assert_array_equal(program_store.load_value(key)["x"], np.arange(3))
    other = program_store.value_key("test", "b")
    (store / f"{key}.value").rename(store / f"{other}.value")  # swapped under another name
    assert program_store.load_value(other) is None
    assert not (store / f"{other}.value").exists()
    (store / f"{key}.value").write_bytes(b"\x80not a pickle")
    assert program_store.load_value(key) is None and not (store / f"{key}.value").exists()
    assert program_store.load_value("absent") is None


def test_the_world_signature_is_kept_and_a_stale_one_is_computed_again(store, monkeypatch):
    """A new process (no signature in memory) reads the signature the store keeps, equal to a
    fresh computation; an entry whose layouts do not match the batch is not used."""
    from lantern_jax.sim import engine, split
    from lantern_jax.sim.packing import Layout
    from lantern_jax.sim.settings import default_settings

    execs = engine.build_new_executions(load_suite().select(PAIR))
    one = jax.tree.map(lambda x: jax.ShapeDtypeStruct(np.shape(x)[1:], x.dtype), execs.scenarios)
    settings = default_settings()
    monkeypatch.setattr(split, "_SIGNATURES", {})
    fresh = split.world_signature(one, settings, 48)
    assert list(store.glob("*.value"))  # kept
    monkeypatch.setattr(split, "_SIGNATURES", {})
    computed = []
    real = split._new_signature
    monkeypatch.setattr(split, "_new_signature", lambda *a: computed.append(1) or real(*a))
    assert split.world_signature(one, settings, 48) == fresh and not computed  # read back
    (key,) = [p.stem for p in store.glob("*.value")]
    program_store.save_value(key, fresh.__class__(48, Layout.of({"x": np.zeros(2)}), *(
        fresh.state, fresh.observation, fresh.privileged, fresh.settings)))  # fmt: skip
    monkeypatch.setattr(split, "_SIGNATURES", {})
    assert split.world_signature(one, settings, 48) == fresh and computed == [1]


def test_built_worlds_are_kept_for_the_package_families_only(store, monkeypatch):
    """The built-in families' worlds are read back equal, leaf for leaf; a suite holding a
    family registered from outside the package is never kept (its code is not in the key)."""
    from lantern_jax.sim import engine

    suite = load_suite().select(["pe_0001", "vc_0001"])
    monkeypatch.setattr(engine, "_BUILT_EXECUTIONS", collections.OrderedDict())
    built = engine.build_executions(suite)
    assert len(list(store.glob("*.value"))) == 1
    monkeypatch.setattr(engine, "_BUILT_EXECUTIONS", collections.OrderedDict())
    monkeypatch.setattr(engine, "build_new_executions", lambda *a: pytest.fail("built again"))
    again = engine.build_executions(suite)
    assert again.pair_ids == built.pair_ids and again.max_ticks == built.max_ticks
    for a, b in zip(jax.tree.leaves(again.scenarios), jax.tree.leaves(built.scenarios),
                    strict=True):  # fmt: skip
        np.testing.assert_array_equal(a, b)
    monkeypatch.setattr(engine, "FAMILIES", ("VC",))  # PE as if it came from outside
    monkeypatch.setattr(engine, "_BUILT_EXECUTIONS", collections.OrderedDict())
    with pytest.raises(pytest.fail.Exception, match="built again"):
        engine.build_executions(suite)


def test_abstract_equals_eval_shape_and_is_read_back(store, monkeypatch):
    fn = functools.partial(jnp.tile, reps=3)
    x = jax.ShapeDtypeStruct((2, 5), jnp.float32)
    want = jax.eval_shape(fn, x)
    monkeypatch.setattr(programs, "_BUILT", collections.OrderedDict())
    assert programs.abstract("tile3", fn, x, parts=("reps=3",)) == want
    monkeypatch.setattr(programs, "_BUILT", collections.OrderedDict())
    monkeypatch.setattr(jax, "eval_shape", lambda *a: pytest.fail("traced again"))
    assert programs.abstract("tile3", fn, x, parts=("reps=3",)) == want
