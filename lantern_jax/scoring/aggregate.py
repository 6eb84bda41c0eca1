"""Every table of an evaluation, built from route-level rows: the family table with its paired
warning gains, the CUS decomposition and the premise table (paper "Pair score and aggregation";
the printing and files are :mod:`lantern_jax.report`'s).

Input: a route-level DataFrame (one row per (model, condition, pair); see
:mod:`lantern_jax.scoring.table`).  Rows are grouped by ``(model, condition)``.

* Family score: mean CUS over the pairs of the family.
* Overall: equal-weight macro-average of the family scores, in ``constants.FAMILIES`` order
  (then any registered family the rows hold, :func:`lantern_jax.core.family_codes.table_codes`); a
  family with no rows in a group is ``NaN`` and is left out of that group's macro-average.
* Decomposition: pooled over all pairs of the group.  ``A-Prog.``, ``TTC``, ``Clear.``, ``Ant.``,
  ``Rec.``, ``B-Prog.`` are means x 100 of ``A_progress``, ``S_ttc``, ``S_clear``, ``S_ant``,
  ``S_rec``, ``B_progress`` that skip ``NaN`` (an unavailable component is excluded from its
  mean, not counted as 0).  ``Gate Pass`` is the percentage of pairs passing all six gates;
  ``Coll.-A``, ``RD-A``, ``LC-A``, ``Rule-A``, ``Block-A``, ``False Brake-B`` are the
  percentages of pairs failing each gate.
* Route B efficiency, beside the CUS (never inside it; :data:`EFFICIENCY_COLUMNS`):
  ``B-Time/Exp.`` is the mean x 100 of each pair's ``B_time_s`` over the privileged expert's
  on the same pair (:func:`with_time_vs_reference`; 100 = as fast as the expert; NaN when the
  rows hold no ``expert``), ``B-Slow (s)`` the mean of ``B_slow_s`` (seconds below half the
  reference speed with nothing justifying it); both skip ``NaN`` like the components.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from lantern_jax.core import family_codes
from lantern_jax.core.constants import CONDITIONS, GATE_COLUMN_NAMES

GROUP_COLUMNS = ("model", "condition")
#: The family tables' column of the macro average over families.
OVERALL = "Overall"
#: The family table's condition of a model's paired difference, warning minus no-warning.
GAIN = "warning gain"

COMPONENT_COLUMNS = {
    "A-Prog.": "A_progress",
    "TTC": "S_ttc",
    "Clear.": "S_clear",
    "Ant.": "S_ant",
    "Rec.": "S_rec",
    "B-Prog.": "B_progress",
}
#: Gate failure columns (% of pairs failing it) -> the route table's gate column, in
#: :data:`~lantern_jax.core.constants.GATE_NAMES` order.
FAILURE_COLUMNS = dict(
    zip(("Coll.-A", "RD-A", "LC-A", "Rule-A", "Block-A", "False Brake-B"), GATE_COLUMN_NAMES,
        strict=True)
)  # fmt: skip
#: The policy whose Route B time is every model's yardstick (``B-Time/Exp.``): the privileged
#: expert, which sees every actor's forecast and slows only for what is there.
EFFICIENCY_REFERENCE = "expert"
#: The per-pair ratio behind ``B-Time/Exp.`` (:func:`with_time_vs_reference`; not a route-table
#: column: it depends on the result set holding the reference).
TIME_VS_REFERENCE = "B_time_vs_expert"
#: Route B efficiency, beside the CUS: column -> (per-pair column, scale of its mean).
EFFICIENCY_COLUMNS = {
    "B-Time/Exp.": (TIME_VS_REFERENCE, 100.0),
    "B-Slow (s)": ("B_slow_s", 1.0),
}
#: Per-pair mean columns of the decomposition: column -> (route-table column, scale).
MEAN_COLUMNS = {
    **{name: (col, 100.0) for name, col in COMPONENT_COLUMNS.items()},
    **EFFICIENCY_COLUMNS,
}
DECOMPOSITION_COLUMNS = (*COMPONENT_COLUMNS, "Gate Pass", *FAILURE_COLUMNS, *EFFICIENCY_COLUMNS)


def with_time_vs_reference(df: pd.DataFrame, reference: str = EFFICIENCY_REFERENCE) -> pd.DataFrame:
    """``df`` with a ``B_time_vs_expert`` column: every row's Route B time over the reference
    policy's on the same pair (:data:`TIME_VS_REFERENCE`).

    A stateless policy's Route B is one execution per pair, shared by both conditions, so the
    reference is the pair's first ``reference`` row.

    Args:
        df: route-level rows (``model``, ``pair_id``, ``B_time_s``).
        reference: the reference model's name.

    Returns:
        A copy of ``df``; the ratio is NaN where the pair has no reference row or either
        Route B was not completed (``B_time_s`` NaN).
    """
    out = df.copy()
    ref = df.loc[df["model"] == reference].drop_duplicates("pair_id").set_index("pair_id")
    ref_time = out["pair_id"].map(ref["B_time_s"]).to_numpy(np.float64)
    out[TIME_VS_REFERENCE] = out["B_time_s"].to_numpy(np.float64) / ref_time
    return out


def _check(df: pd.DataFrame, columns: Sequence[str]) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"route table: missing column(s) {missing}")


def family_scores(df: pd.DataFrame, by: Sequence[str] = GROUP_COLUMNS) -> pd.DataFrame:
    """Per-family mean CUS and the macro-averaged Overall score.

    Args:
        df: route-level rows with ``family`` (a known code, :mod:`lantern_jax.core.family_codes`)
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
    means[OVERALL] = means[cols].mean(axis=1, skipna=True)
    means.columns.name = None
    return means.sort_index()


def decomposition_table(df: pd.DataFrame, by: Sequence[str] = GROUP_COLUMNS) -> pd.DataFrame:
    """Components (means x 100, NaN-skipping), Gate Pass (%), per-gate failure rates (%) and
    the Route B efficiency columns (NaN-skipping means).

    Returns:
        DataFrame indexed by ``by`` with columns :data:`DECOMPOSITION_COLUMNS`.
    """
    by = list(by)
    means = [col for col, _ in MEAN_COLUMNS.values() if col != TIME_VS_REFERENCE]
    _check(df, [*by, "pair_id", "B_time_s", *means, *FAILURE_COLUMNS.values()])
    df = with_time_vs_reference(df)
    rows = []
    for key, g in df.groupby(by, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(by, key, strict=True))
        for name, (col, scale) in MEAN_COLUMNS.items():
            x = g[col].to_numpy(float)
            row[name] = scale * float(np.nanmean(x)) if np.any(~np.isnan(x)) else np.nan
        gates = g[list(FAILURE_COLUMNS.values())].to_numpy(float)
        row["Gate Pass"] = 100.0 * float(np.mean(np.all(gates == 1, axis=1)))
        for name, col in FAILURE_COLUMNS.items():
            row[name] = 100.0 * float(np.mean(g[col].to_numpy(float) == 0))
        rows.append(row)
    out = pd.DataFrame(rows, columns=[*by, *DECOMPOSITION_COLUMNS])
    return out.set_index(by)


def decomposition_pair_values(df: pd.DataFrame) -> pd.DataFrame:
    """Every decomposition column as a per-pair value, so that each table cell is the
    NaN-skipping mean of its column over the group's pairs (and a bootstrap of those pairs
    resamples exactly what the cell averages).

    Args:
        df: route-level rows.

    Returns:
        ``df``'s ``model, condition, pair_id, family`` and one column per
        :data:`DECOMPOSITION_COLUMNS`: components and efficiency scaled as in the table
        (``NaN`` where unavailable), ``Gate Pass`` 100 / 0 for passing all six gates, every
        failure column 100 / 0 for failing its gate.
    """
    keys = [c for c in (*GROUP_COLUMNS, "pair_id", "family") if c in df.columns]
    df = with_time_vs_reference(df)
    out = df[keys].copy()
    for name, (col, scale) in MEAN_COLUMNS.items():
        out[name] = scale * df[col].to_numpy(float)
    gates = df[list(FAILURE_COLUMNS.values())].to_numpy(float)
    out["Gate Pass"] = 100.0 * np.all(gates == 1, axis=1)
    for name, col in FAILURE_COLUMNS.items():
        out[name] = 100.0 * (df[col].to_numpy(float) == 0)
    return out[[*keys, *DECOMPOSITION_COLUMNS]]


def family_table(route_table: pd.DataFrame) -> pd.DataFrame:
    """Per-family CUS rows for every (model, condition) plus each model's paired warning gain.

    Columns: ``model, condition, PE, VC, OR, LWW, RWW, RTY``, the registered families the
    rows hold (:func:`lantern_jax.core.family_codes.table_codes`), ``Overall``.
    """
    fam = family_scores(route_table).reset_index()
    out = []
    for model in dict.fromkeys(fam["model"]):
        sub = fam[fam["model"] == model].set_index("condition")
        for cond in CONDITIONS:
            if cond in sub.index:
                out.append({"model": model, "condition": cond, **sub.loc[cond].drop("model")})
        if all(c in sub.index for c in CONDITIONS):
            warned, plain = (sub.loc[c].drop("model") for c in CONDITIONS)
            out.append({"model": model, "condition": GAIN, **(warned - plain)})
    cols = ["model", "condition", *family_codes.table_codes(route_table["family"]), OVERALL]
    return pd.DataFrame(out)[cols]


#: The premise table's rows: (route-table column, label).
PREMISE_ROWS = (
    ("hazard_hidden_at_warning", "hidden at the warning point"),
    ("hazard_hidden_before_warning", "hidden for the whole approach"),
)


def premise_table(route_table: pd.DataFrame) -> pd.DataFrame:
    """The benchmark's premise, measured: per family, the share (%) of Route A executions
    (every model and condition in ``route_table``) whose hazard the front camera could not see
    at the warning point, and could not see at any tick of the approach up to it.

    Columns: ``measure, PE, VC, OR, LWW, RWW, RTY``, the registered families the rows hold,
    ``Overall`` (Overall pools all executions); the last row, ``Route A executions``, counts
    them per family.
    """
    families = family_codes.table_codes(route_table["family"])
    rows = []
    for col, label in PREMISE_ROWS:
        row = {"measure": label}
        for f in families:
            v = route_table.loc[route_table["family"] == f, col]
            row[f] = 100.0 * float(v.mean()) if len(v) else np.nan
        row[OVERALL] = 100.0 * float(route_table[col].mean()) if len(route_table) else np.nan
        rows.append(row)
    counts = {"measure": "Route A executions"}
    counts.update({f: float((route_table["family"] == f).sum()) for f in families})
    counts[OVERALL] = float(len(route_table))
    return pd.DataFrame([*rows, counts])
