"""Tables and files of an evaluation.

* :func:`format_family_table` / :func:`format_decomposition` render the per-family CUS table
  (with each model's paired warning gain) and the CUS decomposition for the terminal (or, with
  ``tablefmt="github"``, as Markdown).
* :func:`write_outputs` writes every file of an evaluation into one folder as a whole set
  (staged beside the folder and moved into place together, so a reader or a kill never sees a
  mix of two runs' files; :mod:`lantern_jax.files`):

  =================================== =========================================================
  ``route_level_results.csv``         one row per (model, condition, pair), schema order
  ``route_level_results.schema.json`` units, dtypes and missing-value rules of that CSV
  ``family_cus.csv`` / ``.md``        per-family CUS and Overall, warning-gain rows included
  ``decomposition.csv`` / ``.md``     components, Gate Pass and per-gate failure rates (%)
  ``run_record.json``                 what this run was, not what it found: the command line
                                      and each policy's compile and rollout seconds
  ``reproducibility_manifest.json``   suite hash, seeds, policy parameter hashes, package
                                      versions, devices, ablation, and the SHA-256 of every
                                      file above but the run record (written last)
  =================================== =========================================================

Every file but the run record depends only on the inputs and the results (fixed float format,
no timestamps, no wall times), so the same inputs on the same machine give byte-identical
files, the manifest included (:func:`split_manifest` moves what is a record of one run out of
it).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from tabulate import tabulate

from lantern_jax import family_codes
from lantern_jax.files import StagedFolder, atomic_write, check_target_folder
from lantern_jax.scoring import uncertainty
from lantern_jax.scoring.aggregate import DECOMPOSITION_COLUMNS
from lantern_jax.scoring.table import schema_path_for, write_route_table
from lantern_jax.scoring.uncertainty import CONFIDENCE, MIN_N, interval_columns

if TYPE_CHECKING:
    from lantern_jax.ablations import AblationResult
    from lantern_jax.evaluation import EvalResult

ROUTE_CSV = "route_level_results.csv"
FAMILY_CSV = "family_cus.csv"
DECOMPOSITION_CSV = "decomposition.csv"
FAMILY_MD = "family_cus.md"
DECOMPOSITION_MD = "decomposition.md"
MANIFEST_JSON = "reproducibility_manifest.json"
RUN_RECORD_JSON = "run_record.json"
#: Keys of a manifest (at any depth) that record this run rather than what it computed: they go
#: to the run record (:func:`split_manifest`).
RUN_RECORD_KEYS = ("seconds_compile", "seconds_run")

#: Every file :func:`write_outputs` writes, in writing order (the manifest, which names the
#: others, last).
OUTPUT_FILES = (
    ROUTE_CSV,
    schema_path_for(ROUTE_CSV).name,
    FAMILY_CSV,
    DECOMPOSITION_CSV,
    FAMILY_MD,
    DECOMPOSITION_MD,
    RUN_RECORD_JSON,
    MANIFEST_JSON,
)

FAMILY_COLUMNS = uncertainty.FAMILY_COLUMNS


def family_columns(df: pd.DataFrame) -> tuple[str, ...]:
    """The family columns of a family or premise table: the six, then the registered families
    among its columns (:func:`lantern_jax.family_codes.table_codes`), then ``Overall``
    (:data:`FAMILY_COLUMNS` for a table of the six)."""
    return (*family_codes.table_codes(df.columns), "Overall")


GAIN_CONDITION = uncertainty.GAIN
FLAG = "*"  # marks a cell averaging fewer than uncertainty.MIN_N pairs
CONDITION_ORDER = ("warning", "no-warning", GAIN_CONDITION)
CSV_FLOAT_FORMAT = "%.6f"
MISSING = "-"


# ---------------------------------------------------------------------------------------------
# terminal / Markdown tables
# ---------------------------------------------------------------------------------------------
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


def ordered_tables(result: EvalResult) -> tuple[pd.DataFrame, pd.DataFrame]:
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
    df: pd.DataFrame, tablefmt: str = "simple", intervals: pd.DataFrame | None = None
) -> str:
    """Per-family CUS table as text.

    Args:
        df: :attr:`EvalResult.family_table` (columns ``model, condition, PE, VC, OR, LWW, RWW,
            RTY, Overall``; CUS points 0..100).
        tablefmt: a tabulate format (``"simple"`` for the terminal, ``"github"`` for Markdown).
        intervals: the family table's intervals (``EvalResult.intervals.family``); each cell
            then reads ``79.6 [76.1, 82.9]`` and the headers carry the pairs per cell.

    Returns:
        One row per ``model (condition)``, one decimal; ``warning gain`` rows carry a sign;
        ``-`` marks a family without pairs; :data:`FLAG` a cell of fewer than ``MIN_N`` pairs.
    """
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
    """The premise table (:func:`lantern_jax.evaluation.premise_table`) as text: one row per
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


def with_interval_columns(
    points: pd.DataFrame, intervals: pd.DataFrame | None, keys: Sequence[str],
    columns: Sequence[str],
) -> pd.DataFrame:  # fmt: skip
    """A table's point estimates with each column's ``_lo, _hi, _n`` right after it (the
    result files' layout); ``points`` unchanged without intervals.

    Args:
        points: the table (``keys`` and ``columns``).
        intervals: its interval table (``keys`` and ``<c>_lo, <c>_hi, <c>_n``), or None.
        keys: the row keys shared by both.
        columns: the value columns, in order.

    Raises:
        ValueError: when a row of ``points`` has no interval row.
    """
    if intervals is None:
        return points
    keys = list(keys)
    merged = points.merge(intervals, on=keys, how="left", validate="one_to_one")
    lacking = merged[merged[interval_columns(columns[0])[0]].isna()
                     & merged[interval_columns(columns[0])[2]].isna()]  # fmt: skip
    if len(lacking):
        raise ValueError(f"intervals: no row for {lacking[keys].to_dict('records')}")
    order = [k for k in points.columns if k not in columns]
    for c in columns:
        order += [c, *interval_columns(c)]
    out = merged[order]
    for c in columns:
        out = out.astype({interval_columns(c)[2]: "int64"})
    return out


def format_tables(result: EvalResult) -> str:
    """The main command's three tables of an evaluation, with their intervals and legend: the
    per-family CUS, the decomposition (Route B efficiency beside it) and the premise."""
    m = result.manifest
    fam, dec = ordered_tables(result)
    iv = result.intervals
    parts = [
        f"Per-family CUS  (suite {m['suite_id']}, {m['num_pairs']} pairs, "
        f"ablation {m['ablation']}; warning gain = warning - no-warning)",
        format_family_table(fam, intervals=iv.family if iv else None),
        "",
        "CUS decomposition  (components: mean x 100; Gate Pass and gate failures: % of pairs; "
        "Route B efficiency beside the CUS: B-Time/Exp. % of the expert's time, B-Slow s "
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
# files
# ---------------------------------------------------------------------------------------------
def _csv_bytes(df: pd.DataFrame) -> bytes:
    df = df.copy()
    for c in df.columns:
        if pd.api.types.is_float_dtype(df[c]):
            df[c] = df[c] + 0.0  # no "-0.000000"
    return df.to_csv(index=False, float_format=CSV_FLOAT_FORMAT, lineterminator="\n").encode()


def _jsonable(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"manifest: value of type {type(x).__name__} is not JSON-serialisable")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def split_manifest(manifest: dict) -> tuple[dict, dict]:
    """Separate what is reproducible from what is a record of this run.

    Args:
        manifest: an evaluation's or ablation run's manifest.

    Returns:
        ``(reproducible, record)``: the manifest without the :data:`RUN_RECORD_KEYS` (at any
        depth), and those keys at the same places (list items keep their ``name``).
    """

    def split(obj: Any) -> tuple[Any, Any]:
        if isinstance(obj, dict):
            keep, rec = {}, {}
            for k, v in obj.items():
                if k in RUN_RECORD_KEYS:
                    rec[k] = v
                    continue
                keep[k], sub = split(v)
                if sub:
                    rec[k] = sub
            if rec and "name" in obj:
                rec = {"name": obj["name"], **rec}
            return keep, rec
        if isinstance(obj, list):
            parts = [split(v) for v in obj]
            recs = [r for _, r in parts]
            return [k for k, _ in parts], recs if any(recs) else None
        return obj, None

    keep, rec = split(manifest)
    return keep, rec


def _how_written(stage: StagedFolder, record: dict | None) -> dict:
    """The run record's entries, with why the set is written into its folder file by file
    when it is (:attr:`lantern_jax.files.StagedFolder.in_place`)."""
    return {**(record or {}), **({"written_in_place": stage.in_place} if stage.in_place else {})}


def _write_manifests(out: Path, manifest: dict, record: dict | None, written: list[Path],
                     name: str) -> None:  # fmt: skip
    """The run record (``record`` plus what :func:`split_manifest` takes out of ``manifest``),
    then the manifest ``name`` with the SHA-256 of every file in ``written``."""
    reproducible, timings = split_manifest(manifest)
    run = {**(record or {}), **timings}
    text = json.dumps(run, indent=2, default=_jsonable, allow_nan=False) + "\n"
    atomic_write(out / RUN_RECORD_JSON, text.encode())
    reproducible["files"] = [
        dict(name=p.name, sha256=_sha256(p), bytes=p.stat().st_size) for p in written
    ]
    text = json.dumps(reproducible, indent=2, default=_jsonable, allow_nan=False) + "\n"
    atomic_write(out / name, text.encode())


def _markdown(title: str, note: str, table: str) -> bytes:
    return f"# {title}\n\n{note}\n\n{table}\n".encode()


def check_output_folder(out_dir: str | os.PathLike) -> Path:
    """Check that ``out_dir`` can receive a result set, before an evaluation is started.

    Nothing existing is changed (a probe folder is created and removed beside it, or inside it
    when the set will be written in place, :func:`lantern_jax.files.in_place_reason`).

    Args:
        out_dir: the output folder (may not exist yet).

    Returns:
        The resolved folder path.

    Raises:
        lantern_jax.files.OutputFolderError: when it is a file, lies under a file, or cannot be
            written.
    """
    return check_target_folder(out_dir)


def _write_set(result: EvalResult, out: Path, extra_manifest: dict | None,
               run_record: dict | None) -> None:  # fmt: skip
    """Write every file of a result set into the (staging) folder ``out``."""
    route = write_route_table(result.route_table, out / ROUTE_CSV)
    written = [route, schema_path_for(route)]

    fam, dec = ordered_tables(result)
    iv = result.intervals
    keys = ("model", "condition")
    fam_iv, dec_iv = (iv.family, iv.decomposition) if iv is not None else (None, None)
    for name, df, ivs, cols in (
        (FAMILY_CSV, fam, fam_iv, family_columns(fam)),
        (DECOMPOSITION_CSV, dec, dec_iv, DECOMPOSITION_COLUMNS),
    ):
        table = with_interval_columns(df, ivs, keys, cols)
        written.append(atomic_write(out / name, _csv_bytes(table)))

    m = result.manifest
    where = (
        f"Suite `{m.get('suite_id', '?')}` ({m.get('num_pairs', '?')} pairs), "
        f"ablation `{m.get('ablation', 'none')}`."
    )
    legend = (
        f" {interval_note(m.get('intervals'))}; the CSV has each column's `_lo`, `_hi` and `_n`."
        if iv is not None
        else ""
    )
    written.append(
        atomic_write(
            out / FAMILY_MD,
            _markdown(
                "Per-family CUS",
                f"{where} Mean CUS (0-100) per family; Overall is the macro-average over "
                f"families. `warning gain` = warning - no-warning.{legend}",
                format_family_table(fam, tablefmt="github", intervals=fam_iv),
            ),
        )
    )
    written.append(
        atomic_write(
            out / DECOMPOSITION_MD,
            _markdown(
                "CUS decomposition",
                f"{where} Components are means x 100 over available pairs; Gate Pass and the "
                "gate columns (-A: Route A, -B: Route B) are percentages of pairs; B-Time/Exp. "
                "(Route B time to completion, % of the expert's on the same pair) and B-Slow "
                "(s below half the reference speed with nothing justifying it) measure Route "
                f"B efficiency beside the CUS, not in it.{legend}",
                format_decomposition(dec, tablefmt="github", intervals=dec_iv),
            ),
        )
    )

    manifest = dict(result.manifest)
    manifest.update(extra_manifest or {})
    _write_manifests(out, manifest, run_record, written, MANIFEST_JSON)


def write_outputs(
    result: EvalResult,
    out_dir: str | os.PathLike,
    extra_manifest: dict | None = None,
    run_record: dict | None = None,
) -> dict[str, Path]:
    """Write every file of an evaluation (see the module docstring) as one whole set.

    The files are written into a hidden staging folder beside ``out_dir`` and moved into place
    together (:class:`lantern_jax.files.StagedFolder`): ``out_dir`` holds either the previous
    complete set or the new one, even if the process is killed.  The result files of an
    existing ``out_dir`` are replaced; its other entries (other files, sub-folders) are kept.
    Leftovers of an interrupted earlier write are cleaned first.

    Args:
        result: from :func:`lantern_jax.evaluation.evaluate`.
        out_dir: output folder (created if needed).
        extra_manifest: more entries for the reproducibility manifest (they must be the same
            for the same inputs).
        run_record: more entries for the run record (e.g. the command line).

    Returns:
        File name -> path, for every file written (:data:`OUTPUT_FILES`).

    Raises:
        ValueError: when the route-level table does not satisfy its schema (nothing is
            written).
        lantern_jax.files.OutputFolderError: when ``out_dir`` cannot receive the set.
    """
    with StagedFolder(out_dir, OUTPUT_FILES) as stage:
        _write_set(result, stage.path, extra_manifest, _how_written(stage, run_record))
        stage.commit()
    out = Path(out_dir)
    return {name: out / name for name in OUTPUT_FILES}


# ---------------------------------------------------------------------------------------------
# the ablation table (``lantern-jax ablations --policy NAME``)
# ---------------------------------------------------------------------------------------------
ABLATION_CSV = "ablations.csv"
ABLATION_MD = "ablations.md"
ABLATION_ROUTE_CSV = "ablation_route_level_results.csv"
ABLATION_MANIFEST = "ablations_manifest.json"
#: Every file :func:`write_ablation_outputs` writes (the manifest last).
ABLATION_FILES = (
    ABLATION_CSV,
    ABLATION_MD,
    ABLATION_ROUTE_CSV,
    schema_path_for(ABLATION_ROUTE_CSV).name,
    RUN_RECORD_JSON,
    ABLATION_MANIFEST,
)


def format_ablation_table(
    df: pd.DataFrame,
    condition: str = "warning",
    tablefmt: str = "simple",
    intervals: pd.DataFrame | None = None,
) -> str:
    """The ablation table (one row per model and variant) of one condition as text.

    Args:
        df: :attr:`lantern_jax.ablations.AblationResult.table`.
        condition: the condition to show (the paper's table is the warning condition).
        tablefmt: a tabulate format.
        intervals: :attr:`~lantern_jax.ablations.AblationResult.intervals`; each cell then
            reads ``79.6 ±3.4`` (half the interval's width), :data:`FLAG` below ``MIN_N`` pairs,
            and a ``Pairs`` column is added.
    """
    from lantern_jax.ablations import TABLE_COLUMNS

    sub = df[df["condition"] == condition]
    multi = sub["model"].nunique() > 1
    records = sub.to_dict("records")
    labels = [f"{r['label']} ({r['model']})" if multi else r["label"] for r in records]
    keys = ("model", "condition", "variant")
    return _pm_table(records, labels, intervals, keys, TABLE_COLUMNS, "Variant", tablefmt)


def write_ablation_outputs(
    result: AblationResult,
    out_dir: str | os.PathLike,
    extra_manifest: dict | None = None,
    run_record: dict | None = None,
) -> dict[str, Path]:
    """Write the ablation table (CSV, Markdown), every variant's route-level rows (with the
    schema), a run record and a manifest as one whole set
    (:class:`lantern_jax.files.StagedFolder`; the arguments as :func:`write_outputs`).

    Returns:
        File name -> path, for every file of :data:`ABLATION_FILES`.
    """
    with StagedFolder(out_dir, ABLATION_FILES) as stage:
        out = stage.path
        route = write_route_table(result.route_table, out / ABLATION_ROUTE_CSV)
        written = [route, schema_path_for(route)]
        from lantern_jax.ablations import TABLE_COLUMNS

        keys = ("model", "condition", "variant")
        table = with_interval_columns(result.table, result.intervals, keys, TABLE_COLUMNS)
        written.append(atomic_write(out / ABLATION_CSV, _csv_bytes(table)))
        m = result.manifest
        legend = (
            f" {interval_note(m.get('intervals'))}; the CSV has each column's `_lo`, `_hi` and "
            "`_n`."
            if result.intervals is not None
            else ""
        )
        note = (
            f"Suite `{m.get('suite_id', '?')}` ({m.get('num_pairs', '?')} pairs), warning "
            "condition. CUS: Overall (macro-average over families); A-Prog., Ant., Rec.: means "
            "x 100; Event Exp.: % of Route A executions whose event began; Coll.-A, Block-A: % "
            f"of pairs failing the gate.{legend}"
        )
        text = format_ablation_table(result.table, tablefmt="github", intervals=result.intervals)
        md = _markdown("Ablations", note, text)
        written.append(atomic_write(out / ABLATION_MD, md))
        manifest = dict(m)
        manifest.update(extra_manifest or {})
        _write_manifests(out, manifest, _how_written(stage, run_record), written,
                         ABLATION_MANIFEST)  # fmt: skip
        stage.commit()
    target = Path(out_dir)
    return {name: target / name for name in ABLATION_FILES}
