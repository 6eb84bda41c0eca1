"""How far from a point the stress search's pathwise gradient holds: the cosine between it and
central finite differences of the same soft objective along random directions, at several
finite-difference step lengths (in the search's unconstrained coordinates).

A cosine near 1 at a small step says the gradient is computed right at the point; one that
falls at a larger step says the objective's slope changes within that distance, which is what a
search step (Adam, about ``lr`` per coordinate) crosses.  The defaults are the stress
notebook's cell (``coop`` on the first Right-Turn Yield pair, the hazard's track alone, 8
knots) and its two random points; ``docs/stress.md`` gives the figures::

    python benchmarks/bench_gradient_scale.py --policy coop --family RTY --knots 8 \\
        --points 2 --steps 0.05,0.02,0.01,0.005,0.002
"""

from __future__ import annotations

import argparse
import os
import platform

import numpy as np
import pandas as pd

from lantern_jax.apps.stress import report
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--family", default="RTY", help="the family's first pair of the suite")
    ap.add_argument("--actors", default="hazard")
    ap.add_argument("--knots", type=int, default=8)
    ap.add_argument("--points", type=int, default=2, help="random points (seed 7, sd 0.5)")
    ap.add_argument("--directions", type=int, default=8)
    ap.add_argument("--steps", default="0.05,0.02,0.01,0.005,0.002")
    args = ap.parse_args()
    suite = load_suite()
    pair = next(p for p in suite.pairs if p.family == args.family)
    cfg = report.StressConfig(space="adversary", actors=tuple(args.actors.split(",")),
                              knots=args.knots, restarts=args.points)  # fmt: skip
    problem = report.make_problem(pair, get_policy(args.policy), None, cfg, suite)
    points = np.random.default_rng(7).normal(0.0, 0.5, (args.points, problem.space.dim))
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}; {pair.pair_id} {args.policy}, "
          f"{problem.space.dim} dimensions")  # fmt: skip
    rows = {}
    for step in (float(s) for s in args.steps.split(",")):
        q = report.gradient_quality(problem, points, 0.0, 1, directions=args.directions,
                                    step=step, batch=args.points)  # fmt: skip
        rows[f"+/-{step:g}"] = q["cos_first"].to_numpy()
    table = pd.DataFrame(rows, index=[f"point {i}" for i in range(args.points)])
    print("cosine, pathwise gradient against central finite differences:")
    print(table.round(3).to_string())


if __name__ == "__main__":
    main()
