"""Fragility radius of every pair, per policy and suite: the radius, its verification by hard
rollouts along the predicted direction, and its rank correlation with sampling.

For each policy and suite (``lantern-v3`` and, with ``--fresh-seed``, a freshly generated suite)
it runs :func:`lantern_jax.apps.stress.fragility.fragility` with ``--sampling`` draws around each
pair and prints:

* the time to compile the one margin-and-gradient program, and to compute every pair's radius;
* per family: the median radius, the mean bounded radius ``min(r, 1)`` with its interval, the
  share of pairs (passing in their own scene) with a verified failure on the predicted line,
  and among those the share found within 2 radii, with its interval;
* per family and pooled: Spearman's rank correlation of the radius with the failure rate of the
  draws around each pair, with its interval (fragile pairs, small radius, should fail more
  often: a negative correlation).

Writes ``<policy>_<suite>_*.csv`` into ``--out``::

    python benchmarks/bench_fragility.py --policies coop,learned-closed-loop --sampling 16 \\
        --fresh-seed 11
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import pandas as pd

from lantern_jax.apps.stress.fragility import fragility
from lantern_jax.scenarios.suite import load_suite


def _suites(fresh_seed: int | None, out: Path, builtin: bool) -> list:
    suites = [load_suite()] if builtin else []
    if fresh_seed is not None:
        import json

        from lantern_jax.apps.suite_generation import generate_suite

        manifest = generate_suite(seed=fresh_seed, progress=False)
        path = out / f"fresh_{fresh_seed}.json"
        path.write_text(json.dumps(manifest))
        suites.append(load_suite(path))
    return suites


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policies", default="coop", help="comma-separated policy names")
    ap.add_argument("--sampling", type=int, default=16, help="draws around each pair")
    ap.add_argument("--fresh-seed", type=int, default=None, help="also a fresh suite")
    ap.add_argument("--no-builtin", action="store_true", help="only the fresh suite")
    ap.add_argument("--condition", default="warning")
    ap.add_argument("--out", default="benchmarks/results/fragility")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load {load0[0]:.1f} (1 min)")
    pd.set_option("display.width", 200)
    for suite in _suites(args.fresh_seed, out, not args.no_builtin):
        for policy in [p.strip() for p in args.policies.split(",") if p.strip()]:
            t0 = time.perf_counter()
            r = fragility(suite, policy, args.condition, sampling=args.sampling, progress=True)
            total = time.perf_counter() - t0
            tag = f"{policy}_{suite.suite_id}"
            print(f"\n== {policy} on {suite.suite_id} ({len(suite)} pairs, {args.condition}): "
                  f"compile {r.seconds['compile']:.1f} s, radii {r.seconds['radius']:.1f} s, "
                  f"verification {r.seconds['verify']:.0f} s, sampling "
                  f"{r.seconds.get('sampling', 0):.0f} s, total {total:.0f} s")  # fmt: skip
            print(r.families.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
            if r.sampling is not None:
                print(r.sampling.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
                r.sampling.to_csv(out / f"{tag}_sampling.csv", index=False)
            r.table.to_csv(out / f"{tag}_pairs.csv", index=False)
            r.families.to_csv(out / f"{tag}_families.csv", index=False)
    print(f"load at the end {os.getloadavg()[0]:.1f} (1 min)")


if __name__ == "__main__":
    main()
