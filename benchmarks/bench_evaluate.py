"""Whole-suite evaluation timing for one policy: compile, wall time after compile,
scenario-ticks/s and peak memory.

The timed call is exactly what ``evaluate`` runs
(:func:`lantern_jax.apps.evaluation.run_executions`): every pair of the suite under Route A with
warning, Route A without warning and Route B (3 x 120 executions for ``lantern-v3``) in one jitted,
vmapped rollout that stops when every execution has ended (large batches: a fixed number of slots,
refilled with waiting executions as earlier ones end, all stepped by one compiled program).

Usage::

    python benchmarks/bench_evaluate.py [--policy coop] [--suite lantern-v3] [--repeats 3]
    python benchmarks/bench_evaluate.py --path split   # the world program beside the policy's
    python benchmarks/bench_evaluate.py --compile-cache /tmp/cc   # twice: cold, then warm
                                        # (the warm run loads the program store's programs)
    LANTERN_JAX_CPU_DEVICES=1 python benchmarks/bench_evaluate.py   # one device only
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import time

from lantern_jax.cli import expose_cpu_cores
from lantern_jax.core.constants import SUITE_ID  # noqa: E402

expose_cpu_cores()  # one XLA CPU device per core (LANTERN_JAX_CPU_DEVICES=1 to disable)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim.engine import build_executions, run_executions  # noqa: E402


def peak_rss_mb() -> float:
    """Peak resident memory of this process, MB (Linux ru_maxrss is in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--suite", default=SUITE_ID)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--path", default="fused", choices=("fused", "split"),
                    help="the fused program, or the world program with the policy's own "
                    "(lantern_jax.sim.split)")  # fmt: skip
    ap.add_argument(
        "--compile-cache",
        default="off",
        metavar="DIR|off",
        help="JAX's persistent compilation cache folder, which also holds the program store "
        "(lantern_jax.io.program_store; run twice to see a warm start); default off: a cold "
        "compile",
    )
    args = ap.parse_args()
    jax.config.update("jax_enable_compilation_cache", args.compile_cache != "off")
    if args.compile_cache != "off":
        jax.config.update("jax_compilation_cache_dir", args.compile_cache)

    suite = load_suite(args.suite)
    t0 = time.perf_counter()
    execs = build_executions(suite)
    t_build = time.perf_counter() - t0
    policy = get_policy(args.policy)
    params = policy.init(jax.random.PRNGKey(0))
    t0 = time.perf_counter()
    run = {"path": args.path}
    first: dict[str, float] = {}
    final, t_compile = run_executions(
        policy, execs.scenarios, params, execs.max_ticks, timings=first, **run
    )
    walls, cpus = [], []
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        final, _ = run_executions(policy, execs.scenarios, params, execs.max_ticks, **run)
        jax.block_until_ready(final)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    wall = float(np.min(walls))
    ticks = np.asarray(final.tick)
    stepped = int(ticks.max())
    cache = args.compile_cache
    n = ticks.shape[0]

    print(f"machine: {platform.machine()} {os.cpu_count()} cores, {platform.platform()}")
    print(f"jax {jax.__version__} on {jax.default_backend()}, {jax.device_count()} device(s)")
    print(f"suite {suite.suite_id}: {len(suite.pairs)} pairs, {n} executions, "
          f"policy {args.policy}, {args.path} path")  # fmt: skip
    print(f"persistent compilation cache: {cache}")
    print(f"build worlds        {t_build:8.2f} s")
    lower, xla, load = first["trace + lower"], first["XLA compile"], first["program load"]
    print(f"compile             {t_compile:8.2f} s  (trace + lower {lower:.2f} s, XLA compile "
          f"or cache load {xla:.2f} s, program store load {load:.2f} s; one program per "
          f"policy)")  # fmt: skip
    print(f"first run           {first['rollout']:8.2f} s  (the call that compiled)")
    print(f"wall after compile  {wall:8.2f} s  (best of {args.repeats}: "
          f"{', '.join(f'{w:.2f}' for w in walls)})")  # fmt: skip
    print(f"CPU after compile   {float(np.min(cpus)):8.2f} s  (process CPU time, all threads; "
          f"on a shared machine a steadier measure than wall time)")  # fmt: skip
    print(f"longest execution   {stepped:8d} ticks (horizon cap {execs.max_ticks})")
    useful = int(ticks.sum()) / wall
    print(f"useful ticks/s      {useful:8,.0f}   (ticks before each execution ended)")
    print(f"peak memory         {peak_rss_mb():8.0f} MB (process RSS)")


if __name__ == "__main__":
    main()
