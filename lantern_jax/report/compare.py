"""Differences between evaluations, with their uncertainty.

* :func:`compare_runs` (from :mod:`lantern_jax.scoring.paired`) — two policies of one result
  set, or one policy in two result sets over the same pairs: per family and overall, the paired
  difference of mean CUS under every shared condition and of the warning gain, with its
  bootstrap interval and a paired bootstrap p-value; :func:`format_comparison` prints it.
* :func:`across_suites` — the same table evaluated on several suites: per cell the mean over
  suites, the spread (sample standard deviation across suites) and the range.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tabulate import tabulate

from lantern_jax.io.files import StagedFolder, atomic_write
from lantern_jax.report import format_interval, ordered_tables
from lantern_jax.report.results import Evaluation
from lantern_jax.scoring.aggregate import DECOMPOSITION_COLUMNS
from lantern_jax.scoring.paired import (  # noqa: F401  (the paired comparison, re-exported)
    COMPARE_COLUMNS,
    check_shared_pairs,
    compare_runs,
)
from lantern_jax.scoring.uncertainty import FAMILY_COLUMNS, GAIN


def format_p(p: float) -> str:
    """A p-value as printed: three decimals, ``<0.001`` below."""
    if not np.isfinite(p):
        return "-"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def format_comparison(
    table: pd.DataFrame, label_a: str, label_b: str, tablefmt: str = "simple"
) -> str:
    """:func:`compare_runs`'s table as text: one row per condition and family.

    Args:
        table: from :func:`compare_runs`.
        label_a, label_b: the two sides' names (column headers).
        tablefmt: a tabulate format (``"github"`` for Markdown).
    """
    rows = []
    for r in table.to_dict("records"):
        signed = r["condition"] == GAIN
        rows.append([
            r["condition"], r["family"], str(r["n"]),
            format_interval(r["a"], None, None, None, signed),
            format_interval(r["b"], None, None, None, signed),
            format_interval(r["difference"], r["lo"], r["hi"], r["n"], signed=True),
            format_p(r["p"]),
        ])  # fmt: skip
    return tabulate(
        rows,
        headers=["Condition", "Family", "n", label_a, label_b, f"{label_a} - {label_b}", "p"],
        tablefmt=tablefmt,
        disable_numparse=True,
        colalign=("left", "left", "right", "right", "right", "right", "right"),
    )


# ---------------------------------------------------------------------------------------------
# one table over several suites
# ---------------------------------------------------------------------------------------------
def across_suites(
    tables: Sequence[pd.DataFrame],
    keys: Sequence[str] = ("model", "condition"),
    columns: Sequence[str] = FAMILY_COLUMNS,
) -> pd.DataFrame:
    """The spread of one table over several suites.

    Args:
        tables: the same table (e.g. :attr:`EvalResult.family_table`) of every suite.
        keys: the row keys (rows present in every table are kept, in the first's order).
        columns: the value columns.

    Returns:
        The ``keys``, then per column ``<c>`` (mean over suites), ``<c>_sd`` (sample standard
        deviation across suites; NaN for one suite), ``<c>_min``, ``<c>_max`` and ``suites``.
    """
    keys = list(keys)
    stacked = pd.concat([t[[*keys, *columns]] for t in tables], ignore_index=True)
    grouped = stacked.groupby(keys, sort=False)
    sizes = grouped.size()
    out = grouped[list(columns)].mean()
    for c in columns:
        out[f"{c}_sd"] = grouped[c].std(ddof=1)
        out[f"{c}_min"] = grouped[c].min()
        out[f"{c}_max"] = grouped[c].max()
    out = out[sizes == len(tables)]
    order = [x for c in columns for x in (c, f"{c}_sd", f"{c}_min", f"{c}_max")]
    out = out[order].reset_index()
    out["suites"] = len(tables)
    return out


def format_across_suites(
    table: pd.DataFrame, columns: Sequence[str] = FAMILY_COLUMNS, tablefmt: str = "simple"
) -> str:
    """:func:`across_suites` as text: ``mean ±sd`` per cell, one row per ``model (condition)``;
    ``warning gain`` rows signed; the mean alone for a single suite."""
    rows = []
    for r in table.to_dict("records"):
        signed = r["condition"] == GAIN
        cells = []
        for c in columns:
            sd = r[f"{c}_sd"]
            text = format_interval(r[c], None, None, None, signed)
            spread = format_interval(sd, None, None)
            cells.append(text if not np.isfinite(sd) else f"{text} ±{spread}")
        rows.append([f"{r['model']} ({r['condition']})", *cells])
    return tabulate(
        rows,
        headers=["Model (condition)", *columns],
        tablefmt=tablefmt,
        disable_numparse=True,
        colalign=("left", *["right"] * len(columns)),
    )


#: The files of a comparison (``lantern-jax compare --out``).
COMPARISON_MD = "comparison.md"
COMPARISON_CSV = "comparison.csv"
COMPARISON_FILES = (COMPARISON_MD, COMPARISON_CSV)


def write_comparison(table: pd.DataFrame, labels: Sequence[str], notes: Sequence[str],
                     interval: str, command: str, out: Path) -> str:  # fmt: skip
    """A paired comparison (:func:`compare_runs`) written into ``out`` as one set
    (:data:`COMPARISON_FILES`: the Markdown table with its notes and the command, the CSV).

    Args:
        table: the comparison, first minus second.
        labels: the two sides' names, first then second.
        notes: lines shown above the table (protocol or version differences).
        interval: how the intervals were computed (``report.interval_note``).
        command: the command line that made it, shown under the Markdown table.
        out: the folder.

    Returns:
        The text to print: the notes, the title, the table and how to read it.
    """
    title = f"Paired comparison of mean CUS: {labels[0]} - {labels[1]}"
    note = (f"{interval}; p: two-sided paired bootstrap p-value of a zero difference; n: pairs "
            "compared.")  # fmt: skip
    head = "".join(f"> {line}\n\n" for line in notes)
    github = format_comparison(table, *labels, tablefmt="github")
    md = f"# {title}\n\n{head}{note}\n\n{github}\n\nCommand: `{command}`\n"
    with StagedFolder(out, COMPARISON_FILES) as stage:
        atomic_write(stage.path / COMPARISON_MD, md.encode())
        csv = table.to_csv(index=False, float_format="%.6f", lineterminator="\n")
        atomic_write(stage.path / COMPARISON_CSV, csv.encode())
        stage.commit()
    return "\n".join([*notes, title, format_comparison(table, *labels), note])


#: The files of :func:`write_across_suites` (``lantern-jax evaluate --fresh-suites``).
ACROSS_MD = "across_suites.md"
ACROSS_CSV = "across_suites.csv"
ACROSS_DECOMPOSITION_CSV = "across_suites_decomposition.csv"
ACROSS_JSON = "across_suites.json"
ACROSS_FILES = (ACROSS_MD, ACROSS_CSV, ACROSS_DECOMPOSITION_CSV, ACROSS_JSON)


def write_across_suites(results: Sequence[Evaluation], record: dict, out: Path) -> str:
    """The family table and the decomposition across several suites' evaluations, written
    with the record of the suites into ``out`` as one set (:data:`ACROSS_FILES`: Markdown, two
    CSVs, the record as JSON).

    Args:
        results: one evaluation per suite, the same policies in each.
        record: what the run was (``suites``: each suite's id, seed, hash and result folder);
            written as :data:`ACROSS_JSON`.
        out: the folder.

    Returns:
        The text to print: both tables across the suites and the files written.
    """
    fam_across = across_suites([ordered_tables(r)[0] for r in results])
    dec_across = across_suites([ordered_tables(r)[1] for r in results],
                               columns=DECOMPOSITION_COLUMNS)  # fmt: skip
    ids = ", ".join(r["suite_id"] for r in record["suites"])
    title = f"Per-family CUS across {len(results)} suites ({ids})"
    note = "Each cell: mean over the suites ± the sample standard deviation across them."
    table = format_across_suites(fam_across)
    dec_table = format_across_suites(dec_across, columns=DECOMPOSITION_COLUMNS)
    md = (
        f"# {title}\n\n{note} Every suite's own tables, with their intervals, are in its "
        f"folder.\n\n{format_across_suites(fam_across, tablefmt='github')}\n\n"
        f"## CUS decomposition across the suites\n\n"
        f"{format_across_suites(dec_across, columns=DECOMPOSITION_COLUMNS, tablefmt='github')}\n"
    )
    with StagedFolder(out, ACROSS_FILES) as st:
        atomic_write(st.path / ACROSS_MD, md.encode())
        for name, df in ((ACROSS_CSV, fam_across), (ACROSS_DECOMPOSITION_CSV, dec_across)):
            text = df.to_csv(index=False, float_format="%.6f", lineterminator="\n")
            atomic_write(st.path / name, text.encode())
        atomic_write(st.path / ACROSS_JSON, (json.dumps(record, indent=2) + "\n").encode())
        st.commit()
    written = ", ".join(str(out / f) for f in ACROSS_FILES)
    return (f"{title}\n{note}\n{table}\n\nCUS decomposition across the suites\n{dec_table}"
            f"\n\nWrote {written} and one result set per suite")  # fmt: skip
