"""What one stress cell waits for before its search starts: the compile, and where it goes.

Runs :func:`lantern_jax.apps.stress.report.stress_test` on one cell (the first pair of
``--family`` under ``--policy``, the adversary space, ``--restarts`` restarts, ``--methods``) with
a budget of 8 rollouts per restart, JAX's persistent cache off (with ``--cache DIR``: on, in
``DIR``, the program store with it, as the command line runs), and prints the ``compiled in``
time it reports (the nominal scene's verification and every method's programs) with XLA's
compile, tracing and lowering summed over every program (and over the threads that compile
them), and the machine's load.  Run it once per code version, the versions interleaved, to
compare them::

    python benchmarks/bench_stress_compile.py --family PE --policy ego

A cell run again in a new process (another seed, budget or method list) is
``--cache DIR`` twice with the same ``DIR``: the second run is what a rerun waits for.
"""

from __future__ import annotations

import argparse
import collections
import os
import platform
import time

import jax
from jax import monitoring

EVENTS = {
    "XLA": "/jax/core/compile/backend_compile_duration",
    "trace": "/jax/core/compile/jaxpr_trace_duration",
    "lower": "/jax/core/compile/jaxpr_to_mlir_module_duration",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", default="PE")
    ap.add_argument("--policy", default="ego")
    ap.add_argument("--methods", default="random,cmaes,gradient", help="comma-separated")
    ap.add_argument("--restarts", type=int, default=4)
    ap.add_argument("--cache", default=None, metavar="DIR",
                    help="JAX's persistent cache and the program store in DIR (default: off)")
    args = ap.parse_args()
    if args.cache is None:
        jax.config.update("jax_enable_compilation_cache", False)
    else:
        from lantern_jax.core.jax_setup import CACHE_DIR_ENV, configure_compile_cache

        os.environ[CACHE_DIR_ENV] = args.cache
        configure_compile_cache(True)
    seconds: dict[str, float] = collections.defaultdict(float)
    count = collections.Counter()

    def listen(event: str, duration: float, **kwargs) -> None:
        seconds[event] += duration
        count[event] += 1

    monitoring.register_event_duration_secs_listener(listen)
    try:
        from lantern_jax.apps.stress import report
    except ImportError:  # the package's layout before lantern_jax.apps, to time older versions
        from lantern_jax.stress import report
    from lantern_jax.scenarios.suite import load_suite

    suite = load_suite()
    pair = next(p for p in suite.pairs if p.family == args.family)
    cfg = report.StressConfig(
        space="adversary", budget_s=600.0, budget_rollouts=8, restarts=args.restarts,
        methods=tuple(args.methods.split(",")),
    )
    t0 = time.perf_counter()
    problem, _ = report.stress_test(pair, args.policy, cfg, suite=suite, progress=False)
    total = time.perf_counter() - t0
    print(f"machine: {platform.machine()} {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; "
          f"jax {jax.__version__}; XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}")  # fmt: skip
    print(f"{pair.pair_id} {args.policy} ({args.methods}): compiled in "
          f"{problem.info['compile_s']:.1f} s (the whole call {total:.1f} s); "
          + ", ".join(f"{k} {seconds[e]:.1f} s" for k, e in EVENTS.items())
          + f" ({count[EVENTS['XLA']]} programs; cache {args.cache or 'off'})")  # fmt: skip


if __name__ == "__main__":
    main()
