"""The tables of an evaluation as text, for the terminal or (``tablefmt="github"``) Markdown.

* :func:`format_family_table` / :func:`format_decomposition` / :func:`format_premise_table`
  render the per-family CUS table (with each model's paired warning gain), the CUS
  decomposition and the premise table; :func:`format_tables` all three as the ``evaluate``
  command prints them.
* :func:`format_interval`, :func:`interval_note` and :func:`interval_display`: an estimate with
  its bootstrap interval, the legend of such cells, and a table's interval columns as cells.
* :func:`format_ablation_table`: the paper's ablation table.

The result files that hold these tables are :mod:`lantern_jax.report.outputs`'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from tabulate import tabulate

from lantern_jax.core import family_codes
from lantern_jax.core.constants import CONDITIONS
from lantern_jax.report.results import Evaluation
from lantern_jax.scoring import uncertainty
from lantern_jax.scoring.aggregate import DECOMPOSITION_COLUMNS
from lantern_jax.scoring.uncertainty import CONFIDENCE, MIN_N, interval_columns

FAMILY_COLUMNS = uncertainty.FAMILY_COLUMNS


def family_columns(df: pd.DataFrame) -> tuple[str, ...]:
    """The family columns of a family or premise table: the six, then the registered families
    among its columns (:func:`lantern_jax.core.family_codes.table_codes`), then ``Overall``
    (:data:`FAMILY_COLUMNS` for a table of the six)."""
    return (*family_codes.table_codes(df.columns), "Overall")


GAIN_CONDITION = uncertainty.GAIN
FLAG = "*"  # marks a cell averaging fewer than uncertainty.MIN_N pairs
CONDITION_ORDER = (*CONDITIONS, GAIN_CONDITION)
MISSING = "-"
#: Columns of the ablation table (:func:`format_ablation_table`; 0..100).
ABLATION_TABLE_COLUMNS = ("CUS", "A-Prog.", "Event Exp.", "Ant.", "Rec.", "Coll.-A", "Block-A")


# ---------------------------------------------------------------------------------------------
# terminal / Markdown tables
# ---------------------------------------------------------------------------------------------
def missing_shown(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` for printing: every NaN or infinite number becomes ``None``, which tabulate (and
    ``DataFrame.to_markdown``) print as ``missingval=MISSING`` — a value that does not exist
    (no failure found, a share of nothing) reads as :data:`MISSING`, never ``nan`` or ``inf``."""
    out = df.astype(object)
    for c in out.columns:
        col = out[c]
        bad = col.map(lambda v: isinstance(v, float | np.floating) and not math.isfinite(v))
        out[c] = col.where(~bad.astype(bool), None)
    return out


def _fmt(value: Any, signed: bool = False) -> str:
    if value is None or (isinstance(value, float | np.floating) and math.isnan(value)):
        return MISSING
    v = round(float(value), 1) + 0.0  # + 0.0 turns -0.0 into 0.0
    return f"{v:+.1f}" if signed else f"{v:.1f}"


def _with_keys(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with ``model`` and ``condition`` as columns (they may be the index)."""
    if "model" not in df.columns or "condition" not in df.columns:
        df = df.reset_index()
    missing = [c for c in ("model", "condition") if c not in df.columns]
    if missing:
        raise ValueError(f"table: missing column(s) {missing}")
    return df


def order_rows(df: pd.DataFrame, models: list[str] | None = None) -> pd.DataFrame:
    """Rows grouped by model (``models`` order, else first appearance), conditions in the order
    warning, no-warning, warning gain, then any others alphabetically."""
    df = _with_keys(df)
    if models is None:
        models = list(dict.fromkeys(df["model"]))
    models = [*models, *sorted(set(df["model"]) - set(models))]
    m_rank = {m: i for i, m in enumerate(models)}
    others = sorted(set(df["condition"]) - set(CONDITION_ORDER))
    c_rank = {c: i for i, c in enumerate((*CONDITION_ORDER, *others))}
    if len(df) == 0:
        return df.reset_index(drop=True)
    pairs = zip(df["model"], df["condition"], strict=True)
    key = np.asarray([(m_rank[m], c_rank[c]) for m, c in pairs])
    order = np.lexsort((key[:, 1], key[:, 0]))
    return df.iloc[order].reset_index(drop=True)


def ordered_tables(result: Evaluation) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The family table and the decomposition of ``result`` with models in evaluation order and
    conditions as in :func:`order_rows` (the order of the printed and written tables)."""
    models = list(dict.fromkeys(result.route_table["model"]))
    cols = family_columns(result.family_table)
    fam = order_rows(result.family_table, models)[["model", "condition", *cols]]
    dec = order_rows(result.decomposition, models)[["model", "condition", *DECOMPOSITION_COLUMNS]]
    return fam, dec


def _label(model: str, condition: str) -> str:
    return f"{model} ({condition})"


def format_interval(
    value: Any, lo: Any, hi: Any, n: Any = None, signed: bool = False, style: str = "ci"
) -> str:
    """One estimate with its interval, as the tables print it.

    Args:
        value: the point estimate (NaN / None: :data:`MISSING`).
        lo, hi: its interval (NaN: the estimate alone).
        n: the pairs behind it; fewer than ``uncertainty.MIN_N`` appends :data:`FLAG`.
        signed: print signs (differences).
        style: ``"ci"`` for ``79.6 [76.1, 82.9]``, ``"pm"`` for ``79.6 ±3.4`` (half the
            interval's width).

    Returns:
        The cell text.
    """
    text = _fmt(value, signed)
    if text == MISSING:
        return text
    if lo is not None and hi is not None and math.isfinite(lo) and math.isfinite(hi):
        if style == "pm":
            text += f" ±{_fmt(0.5 * (float(hi) - float(lo)))}"
        else:
            text += f" [{_fmt(lo, signed)}, {_fmt(hi, signed)}]"
    if n is not None and int(n) < MIN_N:
        text += FLAG
    return text


PAIRS_STRATIFIED = "route pairs, stratified by family; differences paired"


def interval_note(settings: dict | None = None, over: str = PAIRS_STRATIFIED) -> str:
    """The legend of the interval cells.

    Args:
        settings: a manifest's ``intervals`` entry (resamples and seed are then named).
        over: what is resampled.
    """
    st = settings or {}
    how = f"; {st['resamples']} resamples, seed {st['seed']}" if "seed" in st else ""
    return (
        f"[lo, hi] / ±: {CONFIDENCE:.0%} percentile bootstrap interval over {over}{how}; "
        f"{FLAG} fewer than {MIN_N} (interval unreliable)"
    )


def _interval_rows(intervals: pd.DataFrame | None, keys: tuple[str, ...]) -> dict:
    """Interval-table rows by key tuple (empty without intervals)."""
    if intervals is None:
        return {}
    return {tuple(r[k] for k in keys): r for r in intervals.to_dict("records")}


def _counts_header(columns, rows: list[dict]) -> list[str]:
    """Column headers with ``n=`` when every row of a column averages the same pairs."""
    out = []
    for c in columns:
        ns = {r.get(interval_columns(c)[2]) for r in rows}
        out.append(f"{c} n={ns.pop()}" if len(ns) == 1 and None not in ns else c)
    return out


def _interval_cell(rec: dict, iv: dict | None, column: str, signed: bool, style: str,
                   show_n: bool) -> str:  # fmt: skip
    if iv is None:
        return _fmt(rec[column], signed)
    lo, hi, n = (iv.get(k) for k in interval_columns(column))
    text = format_interval(rec[column], lo, hi, n, signed, style)
    return f"{text} n={n}" if show_n and n is not None and text != MISSING else text


def format_family_table(
    df: pd.DataFrame | Evaluation, tablefmt: str = "simple",
    intervals: pd.DataFrame | None = None,
) -> str:  # fmt: skip
    """Per-family CUS table as text.

    Given an :class:`~lantern_jax.apps.evaluation.EvalResult`, the table as the command line prints
    it: its title (suite, pairs, ablation), the policies in the order they were given, every
    cell with its interval and the pairs per column, and the intervals' legend.

    Args:
        df: an :class:`EvalResult`, or its :attr:`EvalResult.family_table` (columns ``model,
            condition, PE, VC, OR, LWW, RWW, RTY, Overall``; CUS points 0..100).
        tablefmt: a tabulate format (``"simple"`` for the terminal, ``"github"`` for Markdown).
        intervals: the family table's intervals (``EvalResult.intervals.family``); each cell
            then reads ``79.6 [76.1, 82.9]`` and the headers carry the pairs per cell.

    Returns:
        One row per ``model (condition)``, one decimal; ``warning gain`` rows carry a sign;
        ``-`` marks a family without pairs; :data:`FLAG` a cell of fewer than ``MIN_N`` pairs.
    """
    if hasattr(df, "family_table") and hasattr(df, "manifest"):  # an EvalResult
        result, iv = df, df.intervals
        fam, _ = ordered_tables(result)
        parts = [family_title(result.manifest),
                 format_family_table(fam, tablefmt, iv.family if iv else None)]  # fmt: skip
        if iv is not None:
            parts.append(interval_note(result.manifest.get("intervals")))
        return "\n".join(parts)
    df = _with_keys(df)
    columns = family_columns(df)
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"family table: missing column(s) {missing}")
    ivs = _interval_rows(intervals, ("model", "condition"))
    rows, used = [], []
    for r in df.itertuples(index=False):
        rec = dict(zip(df.columns, r, strict=True))
        iv = ivs.get((rec["model"], rec["condition"])) if ivs else None
        used.append(iv or {})
        signed = rec["condition"] == GAIN_CONDITION
        rows.append(
            [_label(rec["model"], rec["condition"])]
            + [_interval_cell(rec, iv, c, signed, "ci", False) for c in columns]
        )
    return tabulate(
        rows,
        headers=["Model (condition)", *(_counts_header(columns, used) if ivs else columns)],
        tablefmt=tablefmt,
        disable_numparse=True,
        colalign=("left", *["right"] * len(columns)),
    )


def format_decomposition(
    df: pd.DataFrame, tablefmt: str = "simple", intervals: pd.DataFrame | None = None
) -> str:
    """CUS decomposition table as text.

    Args:
        df: :attr:`EvalResult.decomposition` (``model, condition`` as columns or index, then
            ``A-Prog. TTC Clear. Ant. Rec. B-Prog.`` (means x 100), ``Gate Pass`` (%), the
            failure rates ``Coll.-A RD-A LC-A Rule-A Block-A False Brake-B`` (%) and the Route
            B efficiency ``B-Time/Exp.`` (% of the expert's time) and ``B-Slow (s)``).
        tablefmt: a tabulate format.
        intervals: the decomposition's intervals (``EvalResult.intervals.decomposition``);
            each cell then reads ``40.9 ±3.1`` (half the interval's width), with ``n=`` where
            fewer pairs than the row's have the value, and a ``Pairs`` column is added.

    Returns:
        One row per ``model (condition)`` (warning first), one decimal; ``-`` marks a component
        that no pair has; :data:`FLAG` a cell of fewer than ``MIN_N`` pairs.
    """
    df = order_rows(df)
    missing = [c for c in DECOMPOSITION_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"decomposition table: missing column(s) {missing}")
    keys = ("model", "condition")
    records = df[[*keys, *DECOMPOSITION_COLUMNS]].to_dict("records")
    labels = [_label(r["model"], r["condition"]) for r in records]
    return _pm_table(records, labels, intervals, keys, DECOMPOSITION_COLUMNS,
                     "Model (condition)", tablefmt)  # fmt: skip


def _pm_table(
    records: list[dict], labels: list[str], intervals: pd.DataFrame | None,
    keys: tuple[str, ...], columns: Sequence[str], first: str, tablefmt: str,
) -> str:  # fmt: skip
    """A table of ``value ±half-width`` cells: one row per record, labelled; with intervals a
    ``Pairs`` column (the row's pairs) and ``n=`` on cells that average fewer pairs."""
    ivs = _interval_rows(intervals, keys)
    rows = []
    for rec, label in zip(records, labels, strict=True):
        iv = ivs.get(tuple(rec[k] for k in keys)) if ivs else None
        if iv is None:
            rows.append([label] + [_fmt(rec[c]) for c in columns])
            continue
        pairs = max(int(iv[interval_columns(c)[2]]) for c in columns)
        rows.append([label, str(pairs)] + [
            _interval_cell(rec, iv, c, False, "pm", iv[interval_columns(c)[2]] != pairs)
            for c in columns
        ])  # fmt: skip
    extra = ["Pairs"] if ivs else []
    return tabulate(
        rows,
        headers=[first, *extra, *columns],
        tablefmt=tablefmt,
        disable_numparse=True,
        colalign=("left", *["right"] * (len(extra) + len(columns))),
    )


def format_premise_table(
    df: pd.DataFrame, tablefmt: str = "simple", intervals: pd.DataFrame | None = None
) -> str:
    """The premise table (:func:`lantern_jax.apps.evaluation.premise_table`) as text: one row per
    measure (% with one decimal; with ``intervals``, ``EvalResult.intervals.premise``, also
    its interval), then the execution counts and, with intervals, the pairs resampled."""
    ivs = _interval_rows(intervals, ("measure",))
    columns = family_columns(df)
    rows = []
    for rec in df.to_dict("records"):
        if rec["measure"] == "Route A executions":
            rows.append([rec["measure"]] + [
                "-" if not math.isfinite(rec[c]) else f"{rec[c]:.0f}" for c in columns
            ])  # fmt: skip
            continue
        iv = ivs.get((rec["measure"],)) if ivs else None
        rows.append([rec["measure"]] + [
            "-" if not math.isfinite(rec[c]) else _interval_cell(rec, iv, c, False, "ci", False)
            for c in columns
        ])  # fmt: skip
    if ivs:
        first = next(iter(ivs.values()))
        rows.append(["pairs (resampled)"] + [str(first.get(interval_columns(c)[2], "-"))
                                             for c in columns])  # fmt: skip
    return tabulate(
        rows,
        headers=["", *columns],
        tablefmt=tablefmt,
        disable_numparse=True,
        colalign=("left", *["right"] * len(columns)),
    )


def interval_display(df: pd.DataFrame, columns: Sequence[str], n: str | int) -> pd.DataFrame:
    """A table with intervals as its readers see it: each of ``columns`` as
    ``59.3 [55.0, 63.1]`` (:data:`FLAG` below ``MIN_N``) and its ``_lo`` / ``_hi`` columns
    dropped (the CSV keeps the numbers).

    Args:
        df: the table, with ``<c>_lo`` and ``<c>_hi`` for every column of ``columns``.
        columns: the value columns.
        n: the column holding each row's pair count, or one count for every row.
    """
    out = df.copy()
    counts = out[n] if isinstance(n, str) else pd.Series(n, index=out.index)
    for c in columns:
        lo, hi = interval_columns(c)[:2]
        out[c] = [
            format_interval(v, a, b, k)
            for v, a, b, k in zip(out[c], out[lo], out[hi], counts, strict=True)
        ]
    return out.drop(columns=[x for c in columns for x in interval_columns(c)[:2]])


def family_title(manifest: dict) -> str:
    """The per-family CUS table's title line (suite, pairs, ablation)."""
    m = manifest
    return (f"Per-family CUS  (suite {m['suite_id']}, {m['num_pairs']} pairs, "
            f"ablation {m['ablation']}; warning gain = warning - no-warning)")  # fmt: skip


def format_tables(result: Evaluation) -> str:
    """The main command's three tables of an evaluation, with their intervals and legend: the
    per-family CUS, the decomposition (Route B efficiency beside it) and the premise."""
    m = result.manifest
    fam, dec = ordered_tables(result)
    iv = result.intervals
    parts = [
        family_title(m),
        format_family_table(fam, intervals=iv.family if iv else None),
        "",
        "CUS decomposition  (components: mean x 100; Gate Pass and gate failures: % of pairs; "
        "Route B efficiency beside the CUS: B-Time/Exp. % of the expert's time, - without the "
        "expert in the run, B-Slow s "
        "below half the reference speed unjustified)",
        format_decomposition(dec, intervals=iv.decomposition if iv else None),
        "",
        "The premise: hazard hidden from the front camera (% of Route A executions, all "
        "models and conditions)",
        format_premise_table(result.premise, intervals=iv.premise if iv else None),
    ]
    if iv is not None:
        parts.append(interval_note(m.get("intervals")))
    return "\n".join(parts)


# ---------------------------------------------------------------------------------------------
# the ablation table (``lantern-jax ablations --policy NAME``)
# ---------------------------------------------------------------------------------------------
def format_ablation_table(
    df: pd.DataFrame,
    condition: str = CONDITIONS[0],
    tablefmt: str = "simple",
    intervals: pd.DataFrame | None = None,
) -> str:
    """The ablation table (one row per model and variant) of one condition as text.

    Args:
        df: :attr:`lantern_jax.apps.ablation_table.AblationResult.table`.
        condition: the condition to show (the paper's table is the warning condition).
        tablefmt: a tabulate format.
        intervals: :attr:`~lantern_jax.apps.ablation_table.AblationResult.intervals`; each cell then
            reads ``79.6 ±3.4`` (half the interval's width), :data:`FLAG` below ``MIN_N`` pairs,
            and a ``Pairs`` column is added.
    """
    sub = df[df["condition"] == condition]
    multi = sub["model"].nunique() > 1
    records = sub.to_dict("records")
    labels = [f"{r['label']} ({r['model']})" if multi else r["label"] for r in records]
    keys = ("model", "condition", "variant")
    return _pm_table(records, labels, intervals, keys, ABLATION_TABLE_COLUMNS, "Variant", tablefmt)
