"""Compare two route-level CSVs (``route_level_results.csv``) written by ``lantern-jax evaluate``.

Prints how many cells differ at all, and checks the promise of a behaviour-preserving change:
identical ids and gates, CUS equal to 4 decimals, continuous columns within a tolerance
(default 1e-5).  Exit code 0 when the promise holds, 1 otherwise.

    python benchmarks/compare_route_tables.py before.csv after.csv [--tol 1e-5]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

KEYS = ["model", "condition", "pair_id"]


def compare(before: pd.DataFrame, after: pd.DataFrame, tol: float) -> tuple[bool, list[str]]:
    """Compare two route tables; returns (promise holds, report lines)."""
    lines = []
    if list(before.columns) != list(after.columns):
        return False, [f"columns differ: {set(before.columns) ^ set(after.columns)}"]
    b = before.set_index(KEYS).sort_index()
    a = after.set_index(KEYS).sort_index()
    if not b.index.equals(a.index):
        return False, ["row keys (model, condition, pair_id) differ"]
    ok = True
    total_cells, differing = 0, 0
    for col in b.columns:
        x, y = b[col], a[col]
        total_cells += len(x)
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
            xv, yv = x.to_numpy(np.float64), y.to_numpy(np.float64)
            same = (xv == yv) | (np.isnan(xv) & np.isnan(yv))
            n_diff = int((~same).sum())
            differing += n_diff
            if n_diff:
                both = ~(np.isnan(xv) | np.isnan(yv))
                nan_mismatch = int((np.isnan(xv) != np.isnan(yv)).sum())
                max_abs = float(np.max(np.abs(xv[both] - yv[both]))) if both.any() else 0.0
                lines.append(f"{col}: {n_diff} differ, max |diff| {max_abs:.3g}, "
                             f"NaN mismatches {nan_mismatch}")
                if nan_mismatch:
                    ok = False
                if col.startswith("gate_") or col in ("controller_fault", "coincident_onset"):
                    ok = False
                elif col == "CUS":
                    ok &= bool(np.all(np.round(xv[both], 4) == np.round(yv[both], 4)))
                else:
                    ok &= max_abs <= tol
        else:
            n_diff = int((x.astype(str) != y.astype(str)).sum())
            differing += n_diff
            if n_diff:
                lines.append(f"{col}: {n_diff} differ (text)")
                ok = False
    lines.insert(0, f"{differing} of {total_cells} cells differ")
    return ok, lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--tol", type=float, default=1e-5)
    args = ap.parse_args()
    ok, lines = compare(pd.read_csv(args.before), pd.read_csv(args.after), args.tol)
    print("\n".join(lines))
    print("promise holds" if ok else "PROMISE BROKEN")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
