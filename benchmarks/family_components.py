"""Per-family components of a route-level results file (what the decomposition table pools).

Prints, for every (model, condition) and family: CUS, Gate Pass, TTC, clearance, anticipation,
recovery (means x 100, NaN-skipping as in the decomposition table), the Route A collision rate
and the Route B false-brake rate (% of pairs), so that a policy can be compared family by
family, e.g. the privileged ``expert`` against ``coop``::

    lantern-jax evaluate --policy all --out results/all
    python benchmarks/family_components.py results/all/route_level_results.csv
    python benchmarks/family_components.py results/all/route_level_results.csv --condition warning
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from lantern_jax.core.constants import FAMILIES, GATE_NAMES
from lantern_jax.scoring.table import read_route_table

COMPONENTS = {"TTC": "S_ttc", "Clear.": "S_clear", "Ant.": "S_ant", "Rec.": "S_rec"}


def family_components(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (model, condition, family) plus an ``all`` row per (model, condition)."""
    rows = []
    for (model, cond), g in df.groupby(["model", "condition"], sort=False):
        for fam in (*FAMILIES, "all"):
            sub = g if fam == "all" else g[g["family"] == fam]
            if sub.empty:
                continue
            gates = sub[list(GATE_NAMES)].to_numpy(float)
            row = {"model": model, "condition": cond, "family": fam, "n": len(sub)}
            cus = sub.groupby("family")["CUS"].mean()
            row["CUS"] = float(cus.mean())  # macro-average over families for "all"
            row["Gate Pass"] = 100.0 * float(np.mean(np.all(gates == 1, axis=1)))
            for name, col in COMPONENTS.items():
                x = sub[col].to_numpy(float)
                row[name] = 100.0 * float(np.nanmean(x)) if np.any(~np.isnan(x)) else np.nan
            row["Coll.-A"] = 100.0 * float(np.mean(sub["no_collision"] == 0))
            row["FB-B"] = 100.0 * float(np.mean(sub["no_false_brake"] == 0))
            rows.append(row)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", help="route_level_results.csv written by lantern-jax evaluate")
    ap.add_argument("--condition", help="only this condition (e.g. warning)")
    ap.add_argument("--model", action="append", help="only these models (repeatable)")
    args = ap.parse_args()
    df = read_route_table(args.csv)
    if args.condition:
        df = df[df["condition"] == args.condition]
    if args.model:
        df = df[df["model"].isin(args.model)]
    out = family_components(df)
    print(out.to_string(index=False, float_format=lambda x: f"{x:.1f}"))


if __name__ == "__main__":
    main()
