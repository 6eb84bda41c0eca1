"""Stress-testing comparison and gradient quality, per family and policy, on adversarial tracks.

For every family and policy: one pair (the family's first whose nominal scene the expert drives
with margin, so that a plausible failure can exist at all), the adversary space of its hazard
(16 knots of 0.5 s, 32 dimensions; in Obstacle Reveal the van that reveals the static hazard),
and gradient search, random search and CMA-ES run interleaved in this process on the same
budget of rollouts per restart (every kind counted).  Per cell it reports:

* the **rare-failure share**: the share of uniformly random draws the policy passes (random
  search's own draws; a cell is *rare* when >= 90 %);
* per method: share of restarts with a verified plausible failure, median rollouts to the first
  (a restart without one counts as beyond the budget), the same at **equal wall-clock** (every
  method cut at the shortest method's search time), distinct failures;
* whether gradient search meets the goal: median rollouts to the first failure <= 1/2 of random
  search's and <= CMA-ES's, and the same in seconds at equal wall-clock (and the same for the
  hybrid method, draws then descent, when ``--methods`` names it);
* gradient quality: cosine between the pathwise gradient and central finite differences of the
  soft objective along random directions, at random points of the space.

Prints the tables, the machine's load, and writes ``comparison.csv``, ``cells.csv``,
``gradient_quality.csv`` into ``--out``::

    python benchmarks/bench_stress.py --budget-rollouts 64 \\
        --policies coop,learned-distance-onset-only
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

from lantern_jax.apps.stress import report
from lantern_jax.apps.stress.verify import Verifier
from lantern_jax.core.constants import FAMILIES
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite

RARE_PASS_SHARE = 0.9  # a cell is "rare" when the policy passes this share of random draws


def add_suite_argument(ap: argparse.ArgumentParser) -> None:
    """``--suite FILE``: run on another suite than the built-in one (see :func:`chosen_suite`)."""
    ap.add_argument("--suite", default=None, help="a suite file (default: the built-in suite; "
                    "lantern-jax suite --regenerate PATH --seed N writes a fresh one)")  # fmt: skip


def chosen_suite(args: argparse.Namespace):
    """The suite ``--suite`` names (:func:`add_suite_argument`), else the built-in one."""
    return load_suite() if args.suite is None else load_suite(args.suite)


def pick_pair(suite, family: str, cfg: report.StressConfig, policy, pair_id: str | None = None):
    """The family's first pair (or the pair ``pair_id``) whose nominal scene the expert drives
    with margin and on which the configured space can be built (a space with background
    vehicles needs one near the ego's route)."""
    for pair in (p for p in suite.pairs if p.family == family):
        if pair_id is not None and pair.pair_id != pair_id:
            continue
        try:
            problem = report.make_problem(pair, policy, None, cfg)
        except ValueError as e:
            print(f"{pair.pair_id}: {e}", flush=True)
            continue
        nominal = Verifier(problem, batch=cfg.restarts)(
            np.zeros((cfg.restarts, problem.space.dim), np.float32)
        )
        if nominal.expert_ok[0]:
            return pair
    return None


def censored_median(x: np.ndarray, cap: float = math.inf) -> float:
    """Median over restarts; not found (NaN) or beyond ``cap`` counts as infinite."""
    x = np.where(np.isnan(x) | (x > cap), np.inf, x)
    return float(np.median(x))


def cell_rows(traces, problem) -> tuple[pd.DataFrame, dict]:
    """The per-method rows of one cell and its verdict."""
    table = report.comparison_table(traces, problem)
    common_s = min(t.seconds[-1] for t in traces)
    by = {t.method: t for t in traces}
    table["equal_s"] = common_s
    table["found_within_equal_s"] = [report.found_within(t, seconds=common_s) for t in traces]
    table["median_s_at_equal_s"] = [censored_median(t.first_seconds, common_s) for t in traces]
    table["median_rollouts"] = [censored_median(t.first_rollouts) for t in traces]
    verdict = {}
    rows = table.set_index("method")
    for name in ("gradient", "hybrid"):
        if not {name, "random", "cmaes"} <= set(by):
            continue
        g, r, c = (rows.loc[m] for m in (name, "random", "cmaes"))
        prefix = "" if name == "gradient" else "hybrid_"
        for goal, col in (
            ("rollouts_goal", "median_rollouts"),
            ("wallclock_goal", "median_s_at_equal_s"),
        ):
            verdict[prefix + goal] = bool(
                np.isfinite(g[col]) and g[col] <= 0.5 * r[col] and g[col] <= c[col]
            )
    return table, verdict


#: The per-method columns each cell prints.
PRINTED = ["method", "failure_rate", "failure_rate_lo", "failure_rate_hi", "median_rollouts",
           "found_within_equal_s", "median_s_at_equal_s", "distinct_failures",
           "policy_pass_share", "rejected_expert", "rejected_adversary", "rollouts", "search_s"]


def run_cell(suite, name: str, fam: str, cfg: report.StressConfig, pair_id: str | None = None,
             per_restart: list | None = None):  # fmt: skip
    """One cell: the family's first pair the expert drives with margin, every method of
    ``cfg`` on it.  Returns ``(problem, per-method table, cell row)``, or None when no pair of
    the family qualifies; prints the cell.  The cell row needs random search among the
    methods (its draws give the pass share and the plausible-failure share).  ``per_restart``,
    when given, receives a row per method and restart: the rollouts to its first plausible
    failure (NaN where it found none)."""
    policy = get_policy(name)
    t0 = time.perf_counter()
    pair = pick_pair(suite, fam, cfg.resolved(), policy, pair_id)
    if pair is None:
        print(f"\n{fam} {name}: no pair whose nominal scene the expert drives with margin")
        return None
    problem, traces = report.stress_test(pair, policy, cfg, suite=suite, progress=True)
    table, verdict = cell_rows(traces, problem)
    if per_restart is not None:
        per_restart += [dict(method=t.method, restart=r, first_rollouts=t.first_rollouts[r])
                     for t in traces for r in range(t.restarts)]  # fmt: skip
    random_row = table.set_index("method").loc["random"]
    pass_share = float(random_row["policy_pass_share"])
    cell = dict(
        policy=name, family=fam, pair=pair.pair_id, dim=problem.space.dim,
        nominal_cus=problem.info["nominal_cus"],
        nominal_policy_failed=problem.info["nominal_policy_failed"],
        random_draws=int(random_row["verified"]), policy_pass_share=pass_share,
        plausible_failure_share=float(random_row["plausible_failure_share"]),
        rare=pass_share >= RARE_PASS_SHARE, compile_s=problem.info["compile_s"],
        load_1min=os.getloadavg()[0], **verdict,
    )  # fmt: skip
    print(
        f"\n{fam} {name} {pair.pair_id}, {problem.space.dim} dimensions (pass share of random "
        f"draws {pass_share:.3f}; {time.perf_counter() - t0:.0f} s incl. compile "
        f"{problem.info['compile_s']:.0f} s) {verdict}"
    )
    print(table[PRINTED].to_string(index=False, float_format=lambda x: f"{x:.2f}"), flush=True)
    return problem, table.assign(policy=name, family=fam, pair=pair.pair_id), cell


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget-rollouts", type=int, default=64)
    ap.add_argument("--budget-s", type=float, default=900.0)
    ap.add_argument("--policies", default="coop,learned-distance-onset-only")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument(
        "--methods", default="gradient,random,cmaes", help="of gradient, random, cmaes, hybrid"
    )
    ap.add_argument("--actors", default="hazard")
    ap.add_argument("--knots", type=int, default=16)
    ap.add_argument("--restarts", type=int, default=8)
    ap.add_argument(
        "--horizon-s",
        type=float,
        default=20.0,
        help="one soft horizon for every family (one program per policy)",
    )
    ap.add_argument("--quality-points", type=int, default=4, help="0: no gradient check")
    ap.add_argument("--out", default="runs/bench_stress")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite()
    cfg = report.StressConfig(
        space="adversary",
        actors=tuple(args.actors.split(",")),
        knots=args.knots,
        restarts=args.restarts,
        budget_s=args.budget_s,
        budget_rollouts=args.budget_rollouts,
        horizon_s=args.horizon_s,
        methods=tuple(args.methods.split(",")),
    )
    load0 = os.getloadavg()
    t_all = time.perf_counter()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, load {load0[0]:.1f} (1 min) "
        f"{load0[1]:.1f} (5 min); budget {args.budget_rollouts} rollouts per restart, "
        f"{args.restarts} restarts, {args.knots} knots",
        flush=True,
    )
    comps, cells, quality = [], [], []
    for name in args.policies.split(","):
        for fam in args.families.split(","):
            got = run_cell(suite, name, fam, cfg)
            if got is None:
                continue
            problem, table, cell = got
            cells.append(cell)
            comps.append(table)
            if args.quality_points > 0:
                points = np.random.default_rng(7).normal(
                    0.0, 0.5, (args.quality_points, problem.space.dim)
                )
                q = report.gradient_quality(
                    problem, points, 0.0, 1, directions=8, batch=args.restarts
                )
                quality.append(q.assign(family=fam, policy=name))
                print(
                    f"gradient vs finite differences (cosine): {np.round(q['cos_first'], 3)}",
                    flush=True,
                )
            pd.concat(comps).to_csv(out / "comparison.csv", index=False)
            pd.DataFrame(cells).to_csv(out / "cells.csv", index=False)
            if quality:
                pd.concat(quality).to_csv(out / "gradient_quality.csv", index=False)
    load1 = os.getloadavg()
    print(
        f"\ntotal {time.perf_counter() - t_all:.0f} s; load at the end {load1[0]:.1f} (1 min) "
        f"{load1[1]:.1f} (5 min)"
    )
    print(pd.DataFrame(cells).to_string(index=False))
    if quality:
        by = ["policy", "family"]
        qual = pd.concat(quality).groupby(by)["cos_first"].agg(["mean", "min"])
        print("\nGradient quality (cosine with central finite differences, 8 directions per point)")
        print(qual.to_string(float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
