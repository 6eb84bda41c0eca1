"""Where the test run's time goes: per test, wall seconds and the JAX compilation inside it.

Runs pytest with this file as a plugin.  JAX reports every compilation through
``jax.monitoring`` (tracing to a jaxpr, lowering to StableHLO, XLA's backend compile, or the
load from the persistent cache); the plugin adds those durations up per test (fixture set-up
included) and prints, after the run, the totals, the slowest tests with their compile share and
their largest programs, the largest programs over the whole run, the seconds per test file,
every program by name (the small ones too: an eager operation compiles a program of its own per
shape) and, with ``--sites``, the package line and the test line that asked for each; and the
CPU time the run used against its wall time (how many cores were busy: a run that keeps every
core busy is shortened only by less work, not by more workers).
Subprocesses (the command-line tests, notebook kernels) are not seen by the plugin: their time
counts as the test's wall time only (their CPU time is in the run's).

Usage (from the project root; every argument goes to pytest)::

    python benchmarks/profile_tests.py                  # the default test run
    python benchmarks/profile_tests.py -m slow          # the slow tests
    python benchmarks/profile_tests.py tests/test_evaluate.py --top 10 --json times.json
    python benchmarks/profile_tests.py --workers 2 --cold   # as a fresh clone's test command
    python benchmarks/profile_tests.py --workers 2 --cold --sites   # ... and who asked for each

The tests run in this one process (``-n 0``), not in the worker processes the plain test
command starts, so the figures add up the whole run's work rather than its wall time.
``--workers N`` runs them as the test command does, in ``N`` pytest-xdist workers: each worker
loads this file as a plugin and writes its figures when it ends, and they are added up here
(the seconds are then the workers' summed test time; the run's wall time is printed apart).
That is how a program that one worker compiles because of what an earlier test in the same
worker left behind shows up.
The tests keep every compiled program in JAX's persistent cache, ``$JAX_COMPILATION_CACHE_DIR``
(``.jax_cache/`` in the project when unset, ``tests/conftest.py``; the program store lives inside
it), so a second run loads what the first compiled.  ``--cold`` gives the run an empty cache
folder of its own, removed afterwards: every program compiled afresh, as in a fresh clone.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

import jax
import pytest

BACKEND = "/jax/core/compile/backend_compile_duration"
TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
BIG_PROGRAM_S = 1.0  # s, a compilation at least this long is listed by name

#: Environment variable naming the folder where worker processes write their figures.
WORKER_DIR_ENV = "LANTERN_PROFILE_TESTS_DIR"

_current = ["(collection and session start)"]
_per_test: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
_programs: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
#: Every compilation by program name, whatever its size: event (and "n") -> seconds (count).
_by_name: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
#: With ``--sites``: XLA compilations by the line that asked for them (the innermost frame in
#: the package, and the innermost in the tests): "n" -> count, "s" -> seconds.
_sites: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
SITES_ENV = "LANTERN_PROFILE_TESTS_SITES"
_ROOT = str(Path(__file__).resolve().parents[1])


def _site() -> str:
    """The package line and the test line on the stack of the running compilation."""
    package = test = "-"
    for frame in reversed(traceback.extract_stack()):
        name = frame.filename
        if not name.startswith(_ROOT) or name.endswith("profile_tests.py"):
            continue
        where = f"{os.path.relpath(name, _ROOT)}:{frame.lineno}"
        if package == "-" and "/lantern_jax/" in name:
            package = where
        if test == "-" and "/tests/" in name:
            test = where
            break
    return f"{package}  <-  {test}"


def _listener(event: str, duration: float, **kwargs) -> None:
    """``jax.monitoring`` duration listener: charge the event to the running test."""
    if event not in (BACKEND, TRACE, LOWER):
        return
    name = str(kwargs.get("fun_name", "?"))
    acc, named = _per_test[_current[0]], _by_name[name]
    acc[event] += duration
    named[event] += duration
    if event == BACKEND:
        acc["compiles"] += 1
        named["n"] += 1
        if os.environ.get(SITES_ENV):
            site = _sites[f"{name}  {_site()}"]
            site["n"] += 1
            site["s"] += duration
        if duration >= BIG_PROGRAM_S:
            _programs[_current[0]][name] += duration


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Charge set-up, call and tear-down of ``item`` (and their compilations) to it."""
    _current[0] = item.nodeid
    t0 = time.perf_counter()
    yield
    _per_test[item.nodeid]["wall"] += time.perf_counter() - t0
    _current[0] = "(between tests)"


def pytest_configure(config):
    """Start listening once pytest has loaded the plugin."""
    jax.monitoring.register_event_duration_secs_listener(_listener)


def pytest_unconfigure(config):
    """In a pytest-xdist worker of ``--workers``: write this worker's figures for the gathering
    process (:func:`gather`)."""
    worker, folder = os.environ.get("PYTEST_XDIST_WORKER"), os.environ.get(WORKER_DIR_ENV)
    if worker and folder:
        data = {"tests": {k: dict(v) for k, v in _per_test.items()},
                "programs": {k: dict(v) for k, v in _programs.items()},
                "by_name": {k: dict(v) for k, v in _by_name.items()},
                "sites": {k: dict(v) for k, v in _sites.items()}}  # fmt: skip
        (Path(folder) / f"{worker}.json").write_text(json.dumps(data))


def gather(folder: str) -> int:
    """Add the figures the workers wrote into ``folder`` to this process's; returns how many
    workers wrote."""
    files = sorted(Path(folder).glob("*.json"))
    for path in files:
        data = json.loads(path.read_text())
        for name, values in data["tests"].items():
            _per_test[name].update(values)
        for name, values in data["programs"].items():
            _programs[name].update(values)
        for name, values in data.get("by_name", {}).items():
            _by_name[name].update(values)
        for name, values in data.get("sites", {}).items():
            _sites[name].update(values)
    return len(files)


def report(top: int) -> dict:
    """Print the breakdown; returns it as a JSON-able dict."""
    tests = {k: dict(v) for k, v in _per_test.items()}
    total = {key: sum(v.get(key, 0.0) for v in tests.values())
             for key in ("wall", BACKEND, TRACE, LOWER, "compiles")}  # fmt: skip
    big = sum(sum(p.values()) for p in _programs.values())
    n_big = sum(len(p) for p in _programs.values())
    print()
    print(f"tests {total['wall']:.0f} s wall; XLA compile {total[BACKEND]:.0f} s "
          f"({total['compiles']:.0f} programs, {n_big} of them >= {BIG_PROGRAM_S:.0f} s "
          f"taking {big:.0f} s), tracing {total[TRACE]:.0f} s, "
          f"lowering {total[LOWER]:.0f} s")  # fmt: skip
    head = f"{'wall s':>7} {'XLA s':>6} {'n':>4} {'trace+lower s':>13}"
    print(f"\n{head}  test  [largest programs, s]")
    for name, v in sorted(tests.items(), key=lambda kv: -kv[1].get("wall", 0.0))[:top]:
        progs = ", ".join(f"{p} {s:.1f}" for p, s in _programs[name].most_common(3))
        tl = v.get(TRACE, 0.0) + v.get(LOWER, 0.0)
        print(f"{v.get('wall', 0.0):7.1f} {v.get(BACKEND, 0.0):6.1f} {v.get('compiles', 0):4.0f} "
              f"{tl:13.1f}  {name}" + (f"  [{progs}]" if progs else ""))  # fmt: skip
    by_name: collections.Counter = collections.Counter()
    compiled_in: collections.Counter = collections.Counter()  # tests compiling each program
    for per_test in _programs.values():
        for prog, seconds in per_test.items():
            by_name[prog] += seconds
            compiled_in[prog] += 1
    print(f"\n{'XLA s':>7} {'tests':>5}  program (compilations >= {BIG_PROGRAM_S:.0f} s, "
          "whole run)")  # fmt: skip
    for prog, s in by_name.most_common(top):
        print(f"{s:7.1f} {compiled_in[prog]:5d}  {prog}")
    files: collections.Counter = collections.Counter()
    compile_files: collections.Counter = collections.Counter()
    for name, v in tests.items():
        files[name.split("::")[0]] += v.get("wall", 0.0)
        compile_files[name.split("::")[0]] += v.get(BACKEND, 0.0)
    print(f"\n{'wall s':>7} {'XLA s':>6}  file")
    for f, s in files.most_common(top):
        print(f"{s:7.1f} {compile_files[f]:6.1f}  {f}")
    # every program by name, small ones included: where the many short compilations come from
    spent = {k: v.get(BACKEND, 0.0) + v.get(TRACE, 0.0) + v.get(LOWER, 0.0)
             for k, v in _by_name.items()}  # fmt: skip
    print(f"\n{'s':>7} {'XLA s':>6} {'n':>5}  program name (every compilation: trace, lowering "
          "and XLA)")  # fmt: skip
    for k, s in sorted(spent.items(), key=lambda kv: -kv[1])[:top]:
        v = _by_name[k]
        print(f"{s:7.1f} {v.get(BACKEND, 0.0):6.1f} {v.get('n', 0):5.0f}  {k}")
    if _sites:
        print(f"\n{'XLA s':>7} {'n':>5}  program  package line  <-  test line (--sites)")
        for k, v in sorted(_sites.items(), key=lambda kv: -kv[1]["s"])[:top]:
            print(f"{v['s']:7.1f} {v['n']:5.0f}  {k}")
    return {"total": total, "tests": tests,
            "programs": {k: dict(v) for k, v in _programs.items()},
            "by_name": {k: dict(v) for k, v in _by_name.items()},
            "sites": {k: dict(v) for k, v in _sites.items()}}  # fmt: skip


def _cpu_seconds() -> float:
    """CPU seconds (user and system) of this process and of its ended child processes (the
    workers, the tests' subprocesses) so far."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], add_help=False)
    ap.add_argument("--top", type=int, default=25, help="tests and files listed (default 25)")
    ap.add_argument("--json", metavar="PATH", help="also write the breakdown as JSON")
    ap.add_argument("--workers", type=int, default=0, metavar="N",
                    help="run the tests in N pytest-xdist workers, as the test command does, "
                         "and gather their figures (default 0: in this process)")  # fmt: skip
    ap.add_argument("--cold", action="store_true",
                    help="an empty compile cache for this run (a fresh clone's compile)")
    ap.add_argument("--sites", action="store_true",
                    help="also list the lines that asked for the compilations (the package's "
                         "and the test's; slower: a stack walk per compilation)")  # fmt: skip
    ap.add_argument("--help-profile", action="help", help="this help (other arguments: pytest)")
    args, pytest_args = ap.parse_known_args()
    if args.sites:  # read by the listener here and in every worker
        os.environ[SITES_ENV] = "1"
    if args.cold:  # read by tests/conftest.py when pytest imports it, and by every worker
        cold = tempfile.TemporaryDirectory(prefix="profile_tests_cache_")
        os.environ["JAX_COMPILATION_CACHE_DIR"] = cold.name
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path.insert(0, here)

    t0, cpu0 = time.perf_counter(), _cpu_seconds()
    if args.workers > 0:
        # every worker loads this file by name (-p) and writes its figures into the folder
        folder = tempfile.mkdtemp(prefix="profile_tests_")
        os.environ[WORKER_DIR_ENV] = folder
        paths = [here, os.environ.get("PYTHONPATH", "")]
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
        code = pytest.main([*pytest_args, "-n", str(args.workers), "-p", "no:cacheprovider",
                            "-p", "profile_tests"])  # fmt: skip
        import profile_tests as plugin  # the module pytest loaded (-p) in this process

        workers = plugin.gather(folder)
        print(f"\ngathered the figures of {workers} worker(s); seconds below are summed over them")
    else:
        import profile_tests as plugin  # this file as a module: pytest registers its hooks

        # in this process: the listener cannot see the compilations of worker processes
        code = pytest.main([*pytest_args, "-n", "0", "-p", "no:cacheprovider"], plugins=[plugin])
    wall, cpu = time.perf_counter() - t0, _cpu_seconds() - cpu0
    print(f"\npytest exited with {int(code)} after {wall:.0f} s; CPU time {cpu:.0f} s (this "
          f"process, its workers and subprocesses: {cpu / wall:.2f} cores busy on average)")
    out = plugin.report(args.top)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return int(code)


if __name__ == "__main__":
    raise SystemExit(main())
