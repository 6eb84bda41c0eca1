"""Why plain gradient descent loses ground when background vehicles join the adversary space.

On one cell (a policy, a family's pair, a space of :data:`bench_stress_dims.SPACES` with the
hazard and background vehicles), plain descent runs three ways, interleaved in one process on
the same problem, verifier, starting points and budget of rollouts per restart:

* ``gradient``: as the stress test runs it, every dimension moved;
* ``held-random``: the background vehicles' dimensions keep the random start every restart
  draws (the same as ``gradient``'s) and are never moved: the hazard's descent alone, in the
  scene the random start made;
* ``held-zero``: the background vehicles' dimensions start at 0 (their scripted motion) and
  are never moved: the hazard-only descent, in the larger space's problem (its watch, its
  horizon).

So ``gradient`` against ``held-random`` measures what moving the background vehicles by descent
costs or gives, and ``held-random`` against ``held-zero`` what their random start does.  Per
iteration and restart it records the verified candidate (policy failed, plausible failure, hard
CUS) and, for ``gradient``, the share of the gradient's norm on the background vehicles'
dimensions and the distance each block moved from its start.  Prints the success rates with
bootstrap intervals over restarts of each difference against ``gradient``, and per iteration the
share of iterates the policy fails; writes ``iterates.csv``, ``restarts.csv`` and
``comparison.csv`` into ``--out``::

    python benchmarks/bench_held_descent.py --policy learned-closed-loop --family VC --space 384 \\
        --restarts 16 --budget-rollouts 64
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd
from bench_stress import add_suite_argument, cell_rows, chosen_suite, pick_pair
from bench_stress_dims import SPACES

from lantern_jax.apps.stress import report, search
from lantern_jax.policies.registry import get_policy

BOOTSTRAP = 4000  # resamples of the restarts for each interval
LEVEL = 0.95


class Descent(search.GradientSearch):
    """Plain descent that records each iteration into ``rows``.  ``background`` (a boolean
    mask) marks the background vehicles' dimensions; with ``hold`` they keep their start
    (``start="random"``: the draw every restart makes; ``"zero"``: 0) and neither move nor
    enter the smoothing noise."""

    def __init__(self, name: str, background: np.ndarray, hold: bool, start: str, rows: list,
                 *args, **kwargs):  # fmt: skip
        super().__init__(*args, **kwargs)
        self.name, self.rows = name, rows
        self.background = np.asarray(background, bool)
        self.held = self.background if hold else np.zeros_like(self.background)
        self.trace = search.Trace(name, self.restarts)
        if start == "zero":
            self.z[:, self.held] = 0.0
        self.opt_state = self.opt.init(self.z)
        self.z0 = self.z.copy()
        self._g = None

    def _eps(self) -> np.ndarray:
        eps = super()._eps()
        eps[..., self.held] = 0.0
        return eps

    def _gradient(self, est, z, eps) -> np.ndarray:
        g = super()._gradient(est, z, eps)
        self._g = g.copy()  # before holding: where the descent would go
        g[:, self.held] = 0.0
        return g

    def _verify(self, values, owner, cost, per_restart):
        verdict = super()._verify(values, owner, cost, per_restart)
        bg, g = self.background, self._g
        norm = np.linalg.norm(g, axis=1)
        moved = self.z - self.z0
        policy_failed = verdict.failed if verdict.policy_failed is None else verdict.policy_failed
        for r in range(self.restarts):
            self.rows.append(dict(
                method=self.name, iteration=len(self.trace.seconds) - 1, restart=r,
                policy_failed=bool(policy_failed[r]), plausible_failure=bool(verdict.failed[r]),
                expert_ok=bool(verdict.expert_ok[r]), cus=float(verdict.cus[r]),
                grad_share_background=float(np.linalg.norm(g[r, bg]) / max(norm[r], 1e-30)),
                moved_hazard=float(np.linalg.norm(moved[r, ~bg])),
                moved_background=float(np.linalg.norm(moved[r, bg])),
            ))  # fmt: skip
        return verdict


def bootstrap_difference(a: np.ndarray, b: np.ndarray, rng: np.random.Generator) -> tuple:
    """Share of restarts that found a failure in ``a`` minus in ``b`` (bool arrays over
    restarts, resampled apart), with its percentile interval."""
    da = rng.choice(a, (BOOTSTRAP, a.size)).mean(axis=1)
    db = rng.choice(b, (BOOTSTRAP, b.size)).mean(axis=1)
    lo, hi = np.percentile(da - db, [50 * (1 - LEVEL), 50 * (1 + LEVEL)])
    return float(a.mean() - b.mean()), float(lo), float(hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="learned-closed-loop")
    ap.add_argument("--family", default="VC")
    ap.add_argument("--pair", default=None, help="a pair id (default: the family's first that "
                    "qualifies, as bench_stress_dims.py picks it)")  # fmt: skip
    ap.add_argument("--space", default="384", help="a space of bench_stress_dims.SPACES with "
                    "background vehicles")  # fmt: skip
    ap.add_argument("--restarts", type=int, default=16)
    ap.add_argument("--budget-rollouts", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/held_descent")
    add_suite_argument(ap)
    args = ap.parse_args()
    actors, knots, knot_s, background = SPACES[args.space]
    if "background" not in actors:
        ap.error(f"--space: {args.space} has no background vehicles")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    suite = chosen_suite(args)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}; suite {suite.suite_id}", flush=True)  # fmt: skip
    cfg = report.StressConfig(
        space="adversary", actors=actors, knots=knots, knot_s=knot_s, background=background,
        restarts=args.restarts, budget_s=1e9, budget_rollouts=args.budget_rollouts,
        methods=("gradient",), seed=args.seed,
    ).resolved()  # fmt: skip
    policy = get_policy(args.policy)
    pair = pick_pair(suite, args.family, cfg, policy, args.pair)
    if pair is None:
        raise SystemExit(f"{args.family}: no pair qualifies")
    rows: list[dict] = []

    def variants(problem, verifier):
        dim, hazard_dims = problem.space.dim, 2 * knots
        bg = np.arange(dim) >= hazard_dims
        common = (problem, verifier, cfg.restarts, cfg.seed, cfg.lr, cfg.sigma, cfg.samples,
                  cfg.init_z)  # fmt: skip
        return [Descent("gradient", bg, False, "random", rows, *common),
                Descent("held-random", bg, True, "random", rows, *common),
                Descent("held-zero", bg, True, "zero", rows, *common)]  # fmt: skip

    cfg_none = dataclasses.replace(cfg, methods=())
    t0 = time.perf_counter()
    problem, traces = report.stress_test(pair, policy, cfg_none, suite=suite, extra=variants)
    print(f"\n{pair.pair_id}, {problem.space.dim} dimensions, {time.perf_counter() - t0:.0f} s; "
          f"load {os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    table, _ = cell_rows(traces, problem)
    per_restart = pd.DataFrame([dict(method=t.method, restart=r, first_rollouts=t.first_rollouts[r])
                                for t in traces for r in range(t.restarts)])  # fmt: skip
    iterates = pd.DataFrame(rows)
    rng = np.random.default_rng(0)
    found = {m: ~np.isnan(g["first_rollouts"].to_numpy())
             for m, g in per_restart.groupby("method", sort=False)}  # fmt: skip
    diffs = [bootstrap_difference(found[m], found["gradient"], rng) for m in table["method"]]
    table["minus_gradient"] = [d[0] for d in diffs]
    table["minus_gradient_lo"] = [d[1] for d in diffs]
    table["minus_gradient_hi"] = [d[2] for d in diffs]
    table.to_csv(out / "comparison.csv", index=False)
    per_restart.to_csv(out / "restarts.csv", index=False)
    iterates.to_csv(out / "iterates.csv", index=False)
    cols = ["method", "failure_rate", "failure_rate_lo", "failure_rate_hi", "median_rollouts",
            "minus_gradient", "minus_gradient_lo", "minus_gradient_hi", "policy_pass_share",
            "rejected_adversary", "search_s"]  # fmt: skip
    print(table[cols].to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    by_it = iterates.groupby(["method", "iteration"]).agg(
        policy_failed=("policy_failed", "mean"), plausible=("plausible_failure", "mean"),
        cus=("cus", "median"), grad_share_background=("grad_share_background", "median"),
        moved_hazard=("moved_hazard", "median"), moved_background=("moved_background", "median"),
    ).reset_index()  # fmt: skip
    by_it.to_csv(out / "by_iteration.csv", index=False)
    pick = by_it[by_it["iteration"] % 4 == 3]
    print(pick.to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
