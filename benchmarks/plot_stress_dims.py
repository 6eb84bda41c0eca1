"""The dimension study of every stress cell in one figure (``docs/stress.md``).

Reads ``comparison.csv`` from the result folders of ``bench_stress_dims.py`` and draws, per cell
(one column each): above, the share of restarts that found a verified plausible failure, with
its bootstrap interval, against the adversary space's dimension, one line per method at the
series' budget (64 rollouts per restart), and the same share with four times the budget (256)
as hollow markers at the largest dimension; below, the median rollouts to the first plausible
failure where it is defined (at least half the restarts found one), filled at 64 rollouts per
restart and hollow at 256.  Where a folder has ``restarts.csv``, shares and medians count the
failures found within the budget (CMA-ES's last generation can pass it).  A folder's budget is
read from its rows; a method measured in two folders of one budget is drawn from the first.
Without ``--cell`` it draws the documented cells (:data:`DOCUMENTED`) and prints, per cell,
every method's share and median at the largest dimension with 256 rollouts per restart (the
page's table)::

    python benchmarks/plot_stress_dims.py --out docs/_static/stress_dims.png
    python benchmarks/plot_stress_dims.py --out runs/mine.png \\
        --cell "learned-closed-loop PE" runs/bench_stress_dims runs/bench_stress_dims_r256
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd

BOOTSTRAP = 10_000  # resamples of the restarts for an interval
METHODS = ("gradient", "hybrid", "random", "cmaes")  # colours C0..C3, as bench_stress_dims


def _at_budget(rows: pd.DataFrame, restarts: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with the share of successful restarts, its interval and the median rollouts to
    the first failure counted within the budget (CMA-ES verifies a whole generation at a time,
    so its last one can pass the budget), from ``restarts.csv``'s rollouts to each first."""
    rows = rows.copy()
    rng = np.random.default_rng(0)
    for i, r in rows.iterrows():
        first = restarts[(restarts["method"] == r["method"]) & (restarts["dim"] == r["dim"])]
        first = first["first_rollouts"].to_numpy(float)
        if first.size == 0:
            continue
        first = np.where(first <= r["budget"], first, np.inf)  # NaN (none found) -> inf too
        ok = np.isfinite(first)
        boot = rng.choice(ok, (BOOTSTRAP, ok.size)).mean(axis=1)
        rows.loc[i, ["failure_rate", "failure_rate_lo", "failure_rate_hi"]] = (
            ok.mean(), *np.percentile(boot, [2.5, 97.5]))  # fmt: skip
        rows.loc[i, "median_rollouts"] = float(np.median(first))
    return rows


#: the cells of ``docs/stress.md``'s figure and table: title -> result folders (first wins)
DOCUMENTED = {
    "learned-closed-loop PE": ["stress_dims_learned_pe", "stress_dims_learned_pe_r256"],
    "learned-closed-loop VC": ["stress_dims_learned_vc", "stress_dims_learned_vc256",
                               "stress_dims_learned_vc256_r256",
                               "stress_dims_learned_vc256_r256_hybrid",
                               "stress_dims_learned_vc256_r256_cmaes"],
    "learned-closed-loop OR": ["stress_dims_learned_or", "stress_dims_learned_or256_r256",
                               "stress_dims_learned_or256_r256_cmaes"],
    "coop RTY": ["stress_dims_coop_rty", "stress_dims_coop_rty256_r256",
                 "stress_dims_coop_rty256_r256_cmaes"],
}  # fmt: skip
RESULTS = Path(__file__).resolve().parent / "results"


def largest(rows: pd.DataFrame) -> dict[str, str]:
    """Per method, at the largest dimension with 256 rollouts per restart: ``"k/n, median"``
    (``none`` where under half the restarts found a plausible failure), as the page's table
    writes it."""
    big = rows[rows["budget"] == 256]
    big = big[big["dim"] == big["dim"].max()]
    out = {}
    for _, r in big.iterrows():
        n = int(r["restarts"])
        med = r["median_rollouts"]
        med = f"{med:.0f}" if math.isfinite(med) else "none"
        out[r["method"]] = f"{round(r['failure_rate'] * n)}/{n}, {med}"
    return out


def load(folders: list[Path]) -> pd.DataFrame:
    """Every comparison row of ``folders``, one per (budget, method, dimension), first wins."""
    parts = []
    for folder in folders:
        rows = pd.read_csv(folder / "comparison.csv")
        rows["budget"] = rows["rollouts"].map(lambda r: 256 if r > 128 else 64)
        if (folder / "restarts.csv").is_file():
            rows = _at_budget(rows, pd.read_csv(folder / "restarts.csv"))
        parts.append(rows)
    rows = pd.concat(parts, ignore_index=True)
    return rows.drop_duplicates(["budget", "method", "dim"], keep="first")


def figure(cells: dict[str, pd.DataFrame], path: Path) -> None:
    """The figure described in the module docstring, written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(cells), figsize=(3.6 * len(cells), 6.4), squeeze=False,
                             sharex="col")  # fmt: skip
    for col, (name, rows) in enumerate(cells.items()):
        top, bottom = axes[0, col], axes[1, col]
        dims = sorted(rows["dim"].unique())
        for i, method in enumerate(METHODS):
            colour = f"C{i}"
            series = rows[(rows["method"] == method) & (rows["budget"] == 64)].sort_values("dim")
            if len(series):
                top.plot(series["dim"], series["failure_rate"], marker="o", color=colour,
                         label=method)  # fmt: skip
                top.fill_between(series["dim"], series["failure_rate_lo"],
                                 series["failure_rate_hi"], color=colour, alpha=0.12)  # fmt: skip
                med = series[series["median_rollouts"].map(math.isfinite)]
                bottom.plot(med["dim"], med["median_rollouts"], marker="o", color=colour)
            large = rows[(rows["method"] == method) & (rows["budget"] == 256)]
            offset = 1.0 + 0.04 * (i - 1.5)  # side by side at one dimension
            top.scatter(large["dim"] * offset, large["failure_rate"], facecolors="none",
                        edgecolors=colour, s=60, zorder=3)  # fmt: skip
            med = large[large["median_rollouts"].map(math.isfinite)]
            bottom.scatter(med["dim"] * offset, med["median_rollouts"], facecolors="none",
                           edgecolors=colour, s=60, zorder=3)  # fmt: skip
        top.set_title(name, fontsize=10)
        top.set_ylim(-0.02, 1.02)
        bottom.set_yscale("log")
        bottom.set_ylim(8, 300)
        for ax in (top, bottom):
            ax.set_xscale("log", base=2)
            ax.set_xticks(dims, [str(d) for d in dims])
            ax.set_xlim(dims[0] / 1.4, dims[-1] * 1.4)
            ax.grid(alpha=0.3)
        bottom.set_xlabel("dimension of the adversary space")
    axes[0, 0].set_ylabel("restarts with a plausible failure")
    axes[1, 0].set_ylabel("median rollouts to the first\n(where half the restarts found one)")
    axes[0, 0].legend(fontsize=8, title="filled: 64 rollouts per restart\nhollow: 256",
                      title_fontsize=7)  # fmt: skip
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", nargs="+", action="append", metavar=("NAME", "FOLDER"),
                    help="a cell's title and its bench_stress_dims.py result folders "
                    "(default: the documented cells, DOCUMENTED)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=Path("runs/stress_dims.png"))
    args = ap.parse_args()
    cells = {}
    given = args.cell or [[name, *(RESULTS / f for f in folders)]
                          for name, folders in DOCUMENTED.items()]  # fmt: skip
    for name, *folders in given:
        if not folders:
            ap.error(f"--cell {name!r}: no result folder")
        cells[name] = load([Path(f) for f in folders])
        print(f"{name}: {largest(cells[name])}")
    figure(cells, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
