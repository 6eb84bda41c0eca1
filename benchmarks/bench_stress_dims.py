"""Stress testing against the dimension of the adversary space: where, if anywhere, gradients
overtake sampling.

For one policy and family (the family's first pair whose nominal scene the expert drives with
margin), every method runs on the same budget of rollouts per restart over a series of
adversary spaces of growing dimension (:data:`SPACES`).  The tracks of every space cover the
same seconds after each actor's start (finer knots, more actors), so what grows is the number
of directions, not how long the adversary acts:

* ``32``: the hazard, 16 knots of 0.5 s;
* ``128``: the hazard, 64 knots of 0.125 s;
* ``320``: the hazard, an action per tick (160 knots of ``DT`` = 0.05 s);
* ``384``: the hazard and two background vehicles, 64 knots of 0.125 s each (where the scene
  has them; the dimension reached is the one reported);
* ``960``: the hazard and two background vehicles, an action per tick each (where the scene has
  them: 640 with one);
* ``king``: KING's own setting (:mod:`lantern_jax.apps.stress.king`): the hazard and three
  background vehicles (KING's four adversaries), an action every 0.25 s (its 4 Hz) for 64
  steps (16 s) each: 512 dimensions where the scene has the vehicles.  It covers twice the
  seconds of the others, so it is a cell of its own, not a point of the dimension series.

Per-tick controls are the finest a track takes (a knot of one tick), so over the series' 8 s
the dimension grows further only with more actors: 2,048 dimensions would need four tracked
actors with per-tick controls over 12.8 s (:data:`lantern_jax.core.constants.MAX_KNOTS` = 256
knots), more actors than the families' scenes hold near the ego's route.

Per space it reports, per method: the share of restarts with a verified plausible failure (with
its bootstrap interval over restarts) and the median rollouts to the first; per space: random
search's share of plausible failures among its uniform draws.  Writes ``comparison.csv`` and
``cells.csv`` (with ``space``), ``restarts.csv`` (each method's and restart's rollouts to its
first plausible failure, empty where it found none: what intervals of differences and of medians
resample) and ``dims.png`` (success rate against dimension, one line per method, and random
search's plausible-failure share of its draws) into ``--out``::

    python benchmarks/bench_stress_dims.py --policy learned-closed-loop --family PE \\
        --restarts 16 --budget-rollouts 64

``--suite FILE`` runs the cells on another suite (a fresh one: ``lantern-jax suite --regenerate
FILE --seed N``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import pandas as pd
from bench_stress import add_suite_argument, chosen_suite, run_cell

from lantern_jax.apps.stress import report
from lantern_jax.apps.stress.king import KING_KNOT_S
from lantern_jax.core.constants import DT

#: name -> (actor groups, knots per track, s per knot, background vehicles)
SPACES = {
    "32": (("hazard",), 16, 0.5, 1),
    "128": (("hazard",), 64, 0.125, 1),
    "320": (("hazard",), 160, DT, 1),
    "384": (("hazard", "background"), 64, 0.125, 2),
    "960": (("hazard", "background"), 160, DT, 2),
    "king": (("hazard", "background"), 64, KING_KNOT_S, 3),
}


def figure(comp: pd.DataFrame, cells: pd.DataFrame, path: Path) -> None:
    """Left: the share of restarts with a plausible failure (with its interval) against the
    space's dimension, one line per method.  Right: random search's share of plausible failures
    among its uniform draws (what sampling's cost per failure follows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for method, g in comp.groupby("method", sort=False):
        g = g.sort_values("dim")
        line = ax1.plot(g["dim"], g["failure_rate"], marker="o", label=method)[0]
        ax1.fill_between(g["dim"], g["failure_rate_lo"], g["failure_rate_hi"], alpha=0.15,
                         color=line.get_color())  # fmt: skip
    c = cells.sort_values("dim")
    ax2.plot(c["dim"], 100 * c["plausible_failure_share"], marker="o", color="C2")
    dims = sorted(comp["dim"].unique())
    for ax in (ax1, ax2):
        ax.set_xscale("log", base=2)
        ax.set_xticks(dims, [str(d) for d in dims])
        ax.set_xlim(dims[0] / 1.3, dims[-1] * 1.3)
        ax.set_xlabel("dimension of the adversary space")
    budget = int(comp["rollouts"].min())
    ax1.set_ylabel(f"restarts with a plausible failure ({budget} rollouts)")
    ax1.set_ylim(-0.02, 1.02)
    ax1.legend()
    ax2.set_ylabel("plausible failures among uniform draws (%)")
    ax2.set_ylim(bottom=0)
    pairs = comp[["policy", "family"]].drop_duplicates().itertuples(index=False)
    fig.suptitle(", ".join(f"{p} {f}" for p, f in pairs))
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="learned-closed-loop")
    ap.add_argument("--family", default="PE")
    ap.add_argument("--spaces", default=",".join(SPACES), help=f"of {', '.join(SPACES)}")
    ap.add_argument("--methods", default="gradient,hybrid,random,cmaes")
    ap.add_argument("--restarts", type=int, default=16)
    ap.add_argument("--budget-rollouts", type=int, default=64)
    ap.add_argument("--budget-s", type=float, default=1800.0)
    ap.add_argument("--horizon-s", type=float, default=20.0)
    ap.add_argument("--pair", default=None, help="the pair (default: the family's first the "
                    "expert drives with margin)")
    ap.add_argument("--watch", default="hazard", choices=("hazard", "all"),
                    help="the actors the surrogate and the verification watch (docs/stress.md)")
    ap.add_argument("--actor-temperature", type=float, default=None, metavar="M",
                    help="m, the surrogate's soft minimum over the watched actors (default: "
                    "the surrogate's temperature; docs/stress.md)")  # fmt: skip
    add_suite_argument(ap)
    ap.add_argument("--out", default="runs/bench_stress_dims")
    ap.add_argument("--plot-only", action="store_true",
                    help="draw dims.png again from the CSV files in --out, run nothing")
    args = ap.parse_args()
    out = Path(args.out)
    if args.plot_only:
        figure(pd.read_csv(out / "comparison.csv"), pd.read_csv(out / "cells.csv"),
               out / "dims.png")  # fmt: skip
        return
    names = args.spaces.split(",")
    if "random" not in args.methods.split(","):  # run_cell's cell row reads its draws
        ap.error("--methods: must include random (the cell's pass share and plausible-failure "
                 "share are random search's draws)")  # fmt: skip
    bad = [n for n in names if n not in SPACES]
    if bad:
        ap.error(f"--spaces: {', '.join(bad)} not of {', '.join(SPACES)}")
    out.mkdir(parents=True, exist_ok=True)
    suite = chosen_suite(args)
    load0 = os.getloadavg()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load {load0[0]:.1f} (1 min); "
          f"{args.policy} {args.family}, {args.restarts} restarts, {args.budget_rollouts} "
          f"rollouts per restart, methods {args.methods}, suite {suite.suite_id}, "
          f"actor temperature {args.actor_temperature or 'default'}",
          flush=True)  # fmt: skip
    comps, cells, per_restart = [], [], []
    t_all = time.perf_counter()
    for name in names:
        actors, knots, knot_s, background = SPACES[name]
        cfg = report.StressConfig(
            space="adversary", actors=actors, knots=knots, knot_s=knot_s, background=background,
            restarts=args.restarts, budget_s=args.budget_s, budget_rollouts=args.budget_rollouts,
            horizon_s=args.horizon_s, methods=tuple(args.methods.split(",")), watch=args.watch,
            actor_temperature=args.actor_temperature,
        )  # fmt: skip
        rows: list[dict] = []
        got = run_cell(suite, args.policy, args.family, cfg, args.pair, per_restart=rows)
        if got is None:
            break
        problem, table, cell = got
        comps.append(table.assign(space=name, dim=problem.space.dim))
        cells.append(dict(cell, space=name))
        per_restart += [dict(r, space=name, dim=problem.space.dim) for r in rows]
        pd.concat(comps).to_csv(out / "comparison.csv", index=False)
        pd.DataFrame(cells).to_csv(out / "cells.csv", index=False)
        pd.DataFrame(per_restart).to_csv(out / "restarts.csv", index=False)
    if not comps:
        return
    comp, cell_table = pd.concat(comps), pd.DataFrame(cells)
    figure(comp, cell_table, out / "dims.png")
    cols = ["dim", "method", "failure_rate", "failure_rate_lo", "failure_rate_hi",
            "median_rollouts", "rollouts", "search_s"]  # fmt: skip
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s; load at the end "
          f"{os.getloadavg()[0]:.1f} (1 min)")  # fmt: skip
    print(comp[cols].to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    print(cell_table[["space", "dim", "policy_pass_share", "plausible_failure_share",
                               "compile_s"]].to_string(index=False))  # fmt: skip


if __name__ == "__main__":
    main()
