"""Stress-testing comparison and gradient quality, per family and policy.

For every family and policy: the comparison table of gradient search, random search and
CMA-ES at equal wall-clock budget (``lantern_jax.stress.report.comparison_table``), and the
agreement between each gradient estimate and finite differences of the smoothed surrogate
(cosine similarity over random directions) without smoothing (sigma 0) and with the default
smoothing.  Prints both tables and writes them as CSV into ``--out``.

    python benchmarks/bench_stress.py --budget-s 60 --policies ego,coop --out runs/bench_stress
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

from lantern_jax.constants import FAMILIES
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.stress.report import (
    StressConfig,
    comparison_table,
    gradient_quality,
    stress_test,
)
from lantern_jax.stress.space import search_space


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget-s", type=float, default=60.0)
    ap.add_argument("--policies", default="ego,coop")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--restarts", type=int, default=8)
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--quality-points", type=int, default=4)
    ap.add_argument("--out", default="runs/bench_stress")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite()
    cfg = StressConfig(budget_s=args.budget_s, restarts=args.restarts, samples=args.samples)
    comps, quality = [], []
    print(f"machine: {platform.machine()} {os.cpu_count()} cores; budget {args.budget_s:g} s")
    for policy in args.policies.split(","):
        for fam in args.families.split(","):
            pair = next(p for p in suite.pairs if p.family == fam)
            t0 = time.perf_counter()
            problem, traces = stress_test(pair, policy, cfg, suite=suite, progress=False)
            table = comparison_table(traces).assign(family=fam, policy=policy)
            comps.append(table)
            print(f"\n{fam} {policy} ({time.perf_counter() - t0:.0f} s incl. compile)")
            print(table.drop(columns=["family", "policy"]).to_string(index=False))
            space = search_space(fam)
            points = np.random.default_rng(7).normal(0, 1, (args.quality_points, space.dim))
            for sigma in (0.0, cfg.sigma):
                q = gradient_quality(problem, points, sigma, args.samples)
                quality.append(q.mean().to_frame().T.assign(family=fam, policy=policy,
                                                            sigma=sigma))  # fmt: skip
    comp = pd.concat(comps, ignore_index=True)
    qual = pd.concat(quality, ignore_index=True)
    comp.to_csv(out / "comparison.csv", index=False)
    qual.to_csv(out / "gradient_quality.csv", index=False)
    print("\nGradient quality (mean cosine with finite differences over random directions)")
    print(qual.to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
