"""What building the differentiable programs costs: trace, lowering and XLA compile, in seconds.

Two programs, each built from scratch in this process (JAX's persistent cache off):

* the **stress cell's soft program** -- the surrogate's values and pathwise gradients at a
  batch of candidates (:func:`lantern_jax.apps.stress.objective.part_samples`), on the first
  pair of ``--family`` under ``--policy``, in the adversary space of ``--knots`` knots;
* the **fragility program** -- every pair's soft margin and its gradient over the knobs
  (:func:`lantern_jax.apps.stress.fragility.margin_program`), on every ``--every``-th pair of the
  built-in suite.

Prints one line per program with the machine's load; run it once per code version, the
versions interleaved, to compare them::

    python benchmarks/bench_soft_compile.py --family PE --policy ego
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import jax.numpy as jnp

from lantern_jax.apps.stress import fragility, objective, report
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import build_suite_batches, load_suite
from lantern_jax.sim.settings import default_settings


def timed_build(fn, *args) -> dict[str, float]:
    """Seconds of ``fn``'s trace, lowering and compile for ``args``."""
    t0 = time.perf_counter()
    traced = fn.trace(*args)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2 = time.perf_counter()
    lowered.compile()
    t3 = time.perf_counter()
    return {"trace": t1 - t0, "lower": t2 - t1, "compile": t3 - t2}


def stress_program(family: str, policy: str, knots: int, batch: int) -> dict[str, float]:
    """Build times of the soft program of one stress cell (``batch`` candidates per call)."""
    suite = load_suite()
    pair = next(p for p in suite.pairs if p.family == family)
    cfg = report.StressConfig(space="adversary", knots=knots).resolved()
    problem = report.make_problem(pair, get_policy(policy), None, cfg, suite)
    objective.part_samples(problem)  # registers the program under its key
    fn = objective.remember(("part_samples", True, problem.static()), lambda: None)
    pts = jnp.zeros((batch, problem.space.dim), jnp.float32)
    args = (pts, problem.data(), jnp.int32(objective.POLICY),
            problem.member(objective.POLICY, True))  # fmt: skip
    return timed_build(fn, *args) | {"horizon": problem.horizon, "dim": problem.space.dim}


def fragility_program(policy: str, every: int) -> dict[str, float]:
    """Build times of the fragility program of ``policy`` on every ``every``-th pair."""
    suite = load_suite()
    suite = suite.select([p.pair_id for p in suite.pairs][::every])
    pol = get_policy(policy)
    scen_a, _ = build_suite_batches(suite)
    boxes = fragility.knob_boxes(suite, scen_a)
    horizon = 400
    fn = fragility.margin_program(pol, boxes.names, horizon)
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    args = (f32(boxes.u0), scen_a, f32(boxes.lo), f32(boxes.hi), jnp.asarray(boxes.active),
            pol.init(jax.random.PRNGKey(0)), default_settings())  # fmt: skip
    return timed_build(fn, *args) | {"pairs": len(suite), "horizon": horizon}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", default="PE")
    ap.add_argument("--policy", default="ego")
    ap.add_argument("--knots", type=int, default=16)
    ap.add_argument("--batch", type=int, default=8, help="candidates per stress program call")
    ap.add_argument("--every", type=int, default=10, help="fragility: every n-th pair")
    ap.add_argument("--only", choices=("stress", "fragility"), default=None)
    args = ap.parse_args()
    jax.config.update("jax_enable_compilation_cache", False)
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"jax {jax.__version__}, load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    rows = []
    if args.only in (None, "stress"):
        rows.append(("stress soft program", stress_program(args.family, args.policy, args.knots,
                                                           args.batch)))  # fmt: skip
    if args.only in (None, "fragility"):
        rows.append(("fragility program", fragility_program(args.policy, args.every)))
    for name, r in rows:
        total = r["trace"] + r["lower"] + r["compile"]
        extra = ", ".join(f"{k} {v}" for k, v in r.items() if k not in ("trace", "lower",
                                                                          "compile"))  # fmt: skip
        print(f"{name}: trace {r['trace']:.1f} s, lower {r['lower']:.1f} s, "
              f"compile {r['compile']:.1f} s, total {total:.1f} s ({extra}); "
              f"load average {os.getloadavg()[0]:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
