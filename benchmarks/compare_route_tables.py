"""Compare two route-level CSVs (``route_level_results.csv``) written by ``lantern-jax evaluate``.

Prints how many cells differ at all and checks the reproducibility promise
(:data:`lantern_jax.scoring.table.REPRODUCIBLE_ATOL`): identical ids, gates and discrete
columns, continuous columns within the tolerance.  Exit code 0 when it holds, 1 otherwise.

    python benchmarks/compare_route_tables.py before.csv after.csv [--atol 1e-4]
"""

from __future__ import annotations

import argparse
import sys

from lantern_jax.scoring.table import REPRODUCIBLE_ATOL, compare_route_tables, read_route_table


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--atol", type=float, default=REPRODUCIBLE_ATOL)
    args = ap.parse_args()
    before, after = read_route_table(args.before), read_route_table(args.after)
    common = [c for c in before.columns if c in after.columns]
    if len(common) < len(before.columns) or len(common) < len(after.columns):
        print(f"comparing the {len(common)} columns both files have")
    ok, lines = compare_route_tables(before[common], after[common], args.atol)
    print("\n".join(lines))
    print("promise holds" if ok else "PROMISE BROKEN")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
