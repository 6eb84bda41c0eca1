"""Suite-level aggregation of route-level rows (paper "Pair score and aggregation" and the CUS
decomposition table).

Input: a route-level DataFrame (one row per (model, condition, pair); see
:mod:`lantern_jax.scoring.table`).  Rows are grouped by ``(model, condition)``.

* Family score: mean CUS over the pairs of the family.
* Overall: equal-weight macro-average of the family scores, in ``constants.FAMILIES`` order
  (then any registered family the rows hold, :func:`lantern_jax.family_codes.table_codes`); a
  family with no rows in a group is ``NaN`` and is left out of that group's macro-average.
* Decomposition: pooled over all pairs of the group.  ``A-Prog.``, ``TTC``, ``Clear.``, ``Ant.``,
  ``Rec.``, ``B-Prog.`` are means x 100 of ``A_progress``, ``S_ttc``, ``S_clear``, ``S_ant``,
  ``S_rec``, ``B_progress`` that skip ``NaN`` (an unavailable component is excluded from its
  mean, not counted as 0).  ``Gate Pass`` is the percentage of pairs passing all six gates;
  ``Coll.-A``, ``RD-A``, ``LC-A``, ``Rule-A``, ``Block-A``, ``False Brake-B`` are the
  percentages of pairs failing each gate.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from lantern_jax import family_codes

GROUP_COLUMNS = ("model", "condition")

COMPONENT_COLUMNS = {
    "A-Prog.": "A_progress",
    "TTC": "S_ttc",
    "Clear.": "S_clear",
    "Ant.": "S_ant",
    "Rec.": "S_rec",
    "B-Prog.": "B_progress",
}
FAILURE_COLUMNS = {
    "Coll.-A": "gate_collision",
    "RD-A": "gate_route_deviation",
    "LC-A": "gate_lane",
    "Rule-A": "gate_rule",
    "Block-A": "gate_block",
    "False Brake-B": "gate_false_brake",
}
DECOMPOSITION_COLUMNS = (*COMPONENT_COLUMNS, "Gate Pass", *FAILURE_COLUMNS)


def _check(df: pd.DataFrame, columns: Sequence[str]) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"route table: missing column(s) {missing}")


def family_scores(df: pd.DataFrame, by: Sequence[str] = GROUP_COLUMNS) -> pd.DataFrame:
    """Per-family mean CUS and the macro-averaged Overall score.

    Args:
        df: route-level rows with ``family`` (a known code, :mod:`lantern_jax.family_codes`)
            and ``CUS``.
        by: grouping columns.

    Returns:
        DataFrame indexed by ``by`` with columns ``PE, VC, OR, LWW, RWW, RTY``, the registered
        families the rows hold, and ``Overall`` (CUS points, 0..100).
    """
    by = list(by)
    _check(df, [*by, "family", "CUS"])
    known = family_codes.codes()
    unknown = sorted(set(df["family"]) - set(known))
    if unknown:
        raise ValueError(f"route table: unknown family code(s) {unknown}; known: {known}")
    cols = family_codes.table_codes(df["family"])
    means = df.groupby([*by, "family"], sort=False)["CUS"].mean().unstack("family")
    means = means.reindex(columns=cols).astype(float)
    means["Overall"] = means[cols].mean(axis=1, skipna=True)
    means.columns.name = None
    return means.sort_index()


def decomposition_table(df: pd.DataFrame, by: Sequence[str] = GROUP_COLUMNS) -> pd.DataFrame:
    """Components (means x 100, NaN-skipping), Gate Pass (%) and per-gate failure rates (%).

    Returns:
        DataFrame indexed by ``by`` with columns :data:`DECOMPOSITION_COLUMNS`.
    """
    by = list(by)
    _check(df, [*by, *COMPONENT_COLUMNS.values(), *FAILURE_COLUMNS.values()])
    rows = []
    for key, g in df.groupby(by, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(by, key, strict=True))
        for name, col in COMPONENT_COLUMNS.items():
            x = g[col].to_numpy(float)
            row[name] = 100.0 * float(np.nanmean(x)) if np.any(~np.isnan(x)) else np.nan
        gates = g[list(FAILURE_COLUMNS.values())].to_numpy(float)
        row["Gate Pass"] = 100.0 * float(np.mean(np.all(gates == 1, axis=1)))
        for name, col in FAILURE_COLUMNS.items():
            row[name] = 100.0 * float(np.mean(g[col].to_numpy(float) == 0))
        rows.append(row)
    out = pd.DataFrame(rows, columns=[*by, *DECOMPOSITION_COLUMNS])
    return out.set_index(by)
