"""How far from a point the stress search's pathwise gradient holds: the cosine between it and
central finite differences of the same soft objective along random directions, at several
finite-difference step lengths (in the search's unconstrained coordinates).

A cosine near 1 at a small step says the gradient is computed right at the point; one that
falls at a larger step says the objective does something else within that distance (it
jumps, or bends), which a search step (Adam, about ``lr`` per coordinate) crosses.  The
defaults are the stress notebook's cell (``coop`` on the first Right-Turn Yield pair, the
hazard's track alone, 8 knots) and its two random points; ``docs/stress.md`` gives the figures::

    python benchmarks/bench_gradient_scale.py --policy coop --family RTY --knots 8 \\
        --points 2 --steps 0.05,0.02,0.01,0.005,0.002 --lines 3

``--lines N`` also walks N random lines through the first point (``--line-reach`` either way,
``--line-points`` evaluations) and lists where the objective jumps: where its change between
neighbouring evaluations differs from what the pathwise slope there predicts by more than
``--jump-tol``.  A finite difference whose step spans a jump measures the jump, which the
pathwise gradient does not see.
"""

from __future__ import annotations

import argparse
import os
import platform

import numpy as np
import pandas as pd

from lantern_jax.apps.stress import objective, report
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
    ap.add_argument("--lines", type=int, default=0, help="random lines through point 0")
    ap.add_argument("--line-reach", type=float, default=0.03)
    ap.add_argument("--line-points", type=int, default=31)
    ap.add_argument("--jump-tol", type=float, default=0.005)
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
    if args.lines > 0:
        walk_lines(problem, points, args)


def walk_lines(problem, points: np.ndarray, args: argparse.Namespace) -> None:
    """The objective (both parts summed) and its pathwise slope along random lines through
    ``points[0]``, evaluated ``args.points`` candidates per call (the program compiled above);
    prints each line's jumps."""
    samples = objective.part_samples(problem)
    rng = np.random.default_rng(0)
    ts = np.linspace(-args.line_reach, args.line_reach, args.line_points)
    for k in range(args.lines):
        d = rng.normal(size=problem.space.dim)
        d /= np.linalg.norm(d)
        pts = (points[0][None] + ts[:, None] * d[None]).astype(np.float32)
        padded = objective.pad_rows(pts, args.points)
        values, slopes = np.zeros(len(padded)), np.zeros(len(padded))
        for i in range(0, len(padded), args.points):
            chunk = padded[i : i + args.points, None, :]
            for part in objective.parts_of(problem):
                v, g = samples(part, chunk)
                values[i : i + args.points] += np.asarray(v)[:, 0]
                slopes[i : i + args.points] += np.asarray(g)[:, 0] @ d
        values, slopes = values[: len(pts)], slopes[: len(pts)]
        dt = ts[1] - ts[0]
        misfit = np.diff(values) - 0.5 * (slopes[1:] + slopes[:-1]) * dt
        jumps = [f"{0.5 * (ts[i] + ts[i + 1]):+.3f}: {misfit[i]:+.3f}"
                 for i in np.flatnonzero(np.abs(misfit) > args.jump_tol)]  # fmt: skip
        print(f"line {k}: slope {slopes.min():+.3f} to {slopes.max():+.3f}; value "
              f"{values.min():.3f} to {values.max():.3f}; jumps (position: size) "
              f"{', '.join(jumps) if jumps else 'none'}")  # fmt: skip


if __name__ == "__main__":
    main()
