"""Every cell of recorded stress comparisons as one Markdown table.

Reads the ``comparison*.csv`` and ``cells*.csv`` files that ``bench_stress.py`` writes (one or
more result folders) and prints, per policy, family and method: the share of restarts that
found a verified plausible failure (with its bootstrap interval over restarts), the median
rollouts to the first failure (a restart without one counts as beyond the budget, so a median
of ``-`` means fewer than half the restarts found one), the median seconds to the first at
equal wall-clock (every method cut at the shortest method's search time in that run), the
distinct failures found within the budget, and the share of its candidates the policy passed.
A method measured in two folders (random search and CMA-ES rerun beside the hybrid method, with
the same seeds) is shown once, from the first folder that has it; seconds compare only between
methods of one run (one folder), rollouts between all::

    python benchmarks/stress_cells.py benchmarks/results/stress_adversary_cpu \\
        benchmarks/results/stress_adversary_hybrid
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pandas as pd

METHOD_ORDER = ("gradient", "hybrid", "random", "cmaes")


def _number(x: float, fmt: str) -> str:
    """``x`` formatted, ``-`` when it is missing or infinite."""
    return "-" if x is None or not math.isfinite(float(x)) else format(float(x), fmt)


def load(folders: list[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """All comparison rows (first folder wins per policy, family, method) and all cells."""
    comps, cells = [], []
    for folder in folders:
        comps += [pd.read_csv(f) for f in sorted(folder.glob("comparison*.csv"))]
        cells += [pd.read_csv(f) for f in sorted(folder.glob("cells*.csv"))]
    comp = pd.concat(comps).drop_duplicates(["policy", "family", "method"], keep="first")
    cell = pd.concat(cells).drop_duplicates(["policy", "family"], keep="first")
    return comp, cell


def markdown(comp: pd.DataFrame, cell: pd.DataFrame) -> str:
    """The Markdown table, one row per policy, family and method."""
    fams = list(dict.fromkeys(cell["family"]))
    rank = {m: i for i, m in enumerate(METHOD_ORDER)}
    comp = comp.assign(
        _f=comp["family"].map(fams.index), _m=comp["method"].map(lambda m: rank.get(m, 99))
    ).sort_values(["policy", "_f", "_m"], kind="stable")
    cell = cell.set_index(["policy", "family"])
    lines = [
        "| policy | family | random draws it passes | method | restarts with a failure "
        "| median rollouts to the first | median s to the first (equal wall-clock) "
        "| distinct failures | candidates it passed |",
        "|---|---|---:|---|---|---:|---:|---:|---:|",
    ]
    for _, r in comp.iterrows():
        c = cell.loc[(r["policy"], r["family"])]
        found = round(r["failure_rate"] * r["restarts"])
        share = f"{found}/{int(r['restarts'])}"
        if found:
            share += f" [{r['failure_rate_lo']:.2f}, {r['failure_rate_hi']:.2f}]"
        passes = f"{100 * c['policy_pass_share']:.0f} %"
        if c["nominal_policy_failed"]:
            passes += " (nominal fails)"
        rollouts = _number(r["median_rollouts"], ".0f")
        seconds = _number(r["median_s_at_equal_s"], ".1f")
        lines.append(
            f"| `{r['policy']}` | {r['family']} | {passes} | {r['method']} | {share} "
            f"| {rollouts} | {seconds} | {int(r['distinct_failures'])} "
            f"| {100 * r['policy_pass_share']:.0f} % |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path, help="bench_stress.py result folders")
    args = ap.parse_args()
    print(markdown(*load(args.folders)))


if __name__ == "__main__":
    main()
