"""KING's recipe against the project's surrogate, at equal rollouts, on one stress cell.

KING (:mod:`lantern_jax.apps.stress.king`) and the project's gradient search differ in three
things at once: the cost (KING's least mean distance and road share; the project's soft
collision margin with its plausibility terms and the expert's part), what the gradient sees
(KING holds the ego's plans; the project differentiates through the policy) and the step
(KING's Adam step is 0.01 in the unconstrained space against the project's 0.2).  This
benchmark runs, on the same pair, space, starting points and verification, interleaved:

* ``gradient`` -- the project's surrogate and step;
* ``king`` -- KING's recipe as published (cost, held plans, step, no expert part);
* ``king_step`` -- KING's cost and held plans with the project's step (what the step alone
  changes);
* ``random`` -- uniform draws (the baseline every cell has).

It prints and writes (``--out``) the per-method table (``comparison.csv``: restarts with a
verified plausible failure and their bootstrap interval, the median rollouts to the first) and
the differences of success rates with their bootstrap intervals over restarts
(``differences.csv``; the gradient-based methods share their starting points, so their
differences are paired), and each restart's rollouts to its first failure (``restarts.csv``,
empty where it found none)::

    python benchmarks/bench_king.py --policy coop --family RTY --pair rty_0002 --space 128
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd
from bench_stress import PRINTED, add_suite_argument, cell_rows, chosen_suite, pick_pair
from bench_stress_dims import SPACES

from lantern_jax.apps.stress import report, search
from lantern_jax.policies.registry import get_policy

BOOTSTRAP = 4000  # resamples of the restarts for the differences' intervals
PAIRS = (("king", "gradient"), ("king", "random"), ("king_step", "king"),
         ("king_step", "gradient"), ("gradient", "random"))  # fmt: skip


class KingProjectStep(search.KingSearch):
    """KING's cost and held plans with the project's Adam step (``StressConfig.lr``)."""

    name = "king_step"


def differences(traces: list[search.Trace], seed: int = 0) -> pd.DataFrame:
    """Differences of the share of restarts that found a plausible failure, ``a - b``, with
    their 95 % bootstrap interval (the same resampled restarts for both methods)."""
    found = {t.method: ~np.isnan(np.asarray(t.first_rollouts)) for t in traces}
    rng = np.random.default_rng(seed)
    rows = []
    for a, b in PAIRS:
        if a not in found or b not in found:
            continue
        n = len(found[a])
        idx = rng.integers(0, n, (BOOTSTRAP, n))
        boot = found[a][idx].mean(axis=1) - found[b][idx].mean(axis=1)
        lo, hi = np.percentile(boot, [2.5, 97.5])
        rows.append(dict(a=a, b=b, difference=found[a].mean() - found[b].mean(), lo=lo, hi=hi))
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--family", default="RTY")
    ap.add_argument("--pair", default=None, help="the pair (default: the family's first the "
                    "expert drives with margin)")  # fmt: skip
    ap.add_argument("--space", default="128", help=f"of {', '.join(SPACES)}")
    add_suite_argument(ap)
    ap.add_argument("--restarts", type=int, default=16)
    ap.add_argument("--budget-rollouts", type=int, default=64)
    ap.add_argument("--budget-s", type=float, default=3600.0)
    ap.add_argument("--horizon-s", type=float, default=20.0)
    ap.add_argument("--watch", default="hazard", choices=("hazard", "all"))
    ap.add_argument("--out", default="runs/bench_king")
    args = ap.parse_args()
    if args.space not in SPACES:
        ap.error(f"--space: {args.space} not of {', '.join(SPACES)}")
    actors, knots, knot_s, background = SPACES[args.space]
    cfg = report.StressConfig(
        space="adversary", actors=actors, knots=knots, knot_s=knot_s, background=background,
        restarts=args.restarts, budget_s=args.budget_s, budget_rollouts=args.budget_rollouts,
        horizon_s=args.horizon_s, methods=("gradient", "king", "random"), watch=args.watch,
    ).resolved()  # fmt: skip
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load {load0:.1f} (1 min); "
          f"{args.policy} {args.family}, space {args.space}, {args.restarts} restarts, "
          f"{args.budget_rollouts} rollouts per restart", flush=True)  # fmt: skip
    t0 = time.perf_counter()
    suite = chosen_suite(args)
    policy = get_policy(args.policy)
    pair = pick_pair(suite, args.family, cfg, policy, args.pair)
    if pair is None:
        raise SystemExit(f"{args.family}: no pair whose nominal scene the expert drives with "
                         "margin in this space")  # fmt: skip

    def step_variant(problem, verifier):
        return [KingProjectStep(problem, verifier, cfg.restarts, cfg.seed, lr=cfg.lr,
                                init_z=cfg.init_z)]  # fmt: skip

    problem, traces = report.stress_test(pair, policy, cfg, suite=suite, extra=step_variant)
    table, _ = cell_rows(traces, problem)
    table = table.assign(policy=args.policy, family=args.family, pair=pair.pair_id,
                         space=args.space, dim=problem.space.dim, suite=suite.suite_id)  # fmt: skip
    diffs = differences(traces).assign(pair=pair.pair_id, space=args.space)
    table.to_csv(out / "comparison.csv", index=False)
    diffs.to_csv(out / "differences.csv", index=False)
    pd.DataFrame([dict(method=t.method, restart=r, first_rollouts=t.first_rollouts[r])
                  for t in traces for r in range(t.restarts)]).to_csv(  # fmt: skip
        out / "restarts.csv", index=False
    )
    fmt = lambda x: f"{x:.2f}"  # noqa: E731
    print(f"\n{args.family} {args.policy} {pair.pair_id}, {problem.space.dim} dimensions; "
          f"{time.perf_counter() - t0:.0f} s incl. compile {problem.info['compile_s']:.0f} s")
    print(table[PRINTED].to_string(index=False, float_format=fmt))
    print("\nshare of restarts with a plausible failure, a - b (bootstrap over restarts, 95 %):")
    print(diffs.to_string(index=False, float_format=fmt))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s; load at the end "
          f"{os.getloadavg()[0]:.1f} (1 min)")  # fmt: skip


if __name__ == "__main__":
    main()
