"""The result files of an evaluation and of the ablation table.

* :func:`write_outputs` writes every file of an evaluation into one folder as a whole set
  (staged beside the folder and moved into place together, so a reader or a kill never sees a
  mix of two runs' files; :mod:`lantern_jax.io.files`):

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

* :func:`write_ablation_outputs` writes the ablation table's set (:data:`ABLATION_FILES`).

Every file but the run record depends only on the inputs and the results (fixed float format,
no timestamps, no wall times), so the same inputs on the same machine give byte-identical
files, the manifest included (:func:`split_manifest` moves what is a record of one run out of
it).  The tables' text is :mod:`lantern_jax.report.tables`'.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.core.constants import CONDITIONS
from lantern_jax.io.files import StagedFolder, atomic_write, check_target_folder
from lantern_jax.report.results import AblationResult, Evaluation
from lantern_jax.report.tables import (
    ABLATION_TABLE_COLUMNS,
    MISSING,
    family_columns,
    format_ablation_table,
    format_decomposition,
    format_family_table,
    interval_note,
    missing_shown,
    ordered_tables,
)
from lantern_jax.scoring.aggregate import DECOMPOSITION_COLUMNS
from lantern_jax.scoring.table import schema_path_for, write_route_table
from lantern_jax.scoring.uncertainty import interval_columns

ROUTE_CSV = "route_level_results.csv"
FAMILY_CSV = "family_cus.csv"
DECOMPOSITION_CSV = "decomposition.csv"
FAMILY_MD = "family_cus.md"
DECOMPOSITION_MD = "decomposition.md"
MANIFEST_JSON = "reproducibility_manifest.json"
RUN_RECORD_JSON = "run_record.json"
#: Keys of a manifest (at any depth) that record this run rather than what it computed: they go
#: to the run record (:func:`split_manifest`): timings, and where a user's policy file lies on
#: this machine (its name and SHA-256 stay in the manifest), and which rollout path ran.
RUN_RECORD_KEYS = ("seconds_compile", "seconds_run", "program", "source_spec", "source_path")

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

CSV_FLOAT_FORMAT = "%.6f"


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
    when it is (:attr:`lantern_jax.io.files.StagedFolder.in_place`)."""
    return {**(record or {}), **({"written_in_place": stage.in_place} if stage.in_place else {})}


def _write_manifests(out: Path, manifest: dict, extra: dict | None, record: dict | None,
                     written: list[Path], name: str) -> None:  # fmt: skip
    """The run record (``record`` plus what :func:`split_manifest` takes out of ``manifest``),
    then the manifest ``name`` (``manifest`` with the ``extra`` entries) with the SHA-256 of
    every file in ``written``."""
    reproducible, timings = split_manifest({**manifest, **(extra or {})})
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


def _legend(manifest: dict, has_intervals: bool) -> str:
    """The end of a Markdown table's note: the interval legend ("" without intervals)."""
    if not has_intervals:
        return ""
    return (
        f" {interval_note(manifest.get('intervals'))}; the CSV has each column's `_lo`, `_hi` "
        "and `_n`."
    )


def _write_route_files(route_table: pd.DataFrame, path: Path, manifest: dict) -> list[Path]:
    """Write the route-level CSV and its schema (with the user metrics the manifest's settings
    name); returns both paths."""
    metrics = manifest.get("settings", {}).get("metrics", [])
    route = write_route_table(route_table, path, metrics)
    return [route, schema_path_for(route)]


def check_output_folder(out_dir: str | os.PathLike) -> Path:
    """Check that ``out_dir`` can receive a result set, before an evaluation is started.

    Nothing existing is changed (a probe folder is created and removed beside it, or inside it
    when the set will be written in place, :func:`lantern_jax.io.files.in_place_reason`).

    Args:
        out_dir: the output folder (may not exist yet).

    Returns:
        The resolved folder path.

    Raises:
        lantern_jax.io.files.OutputFolderError: when it is a file, lies under a file, or cannot be
            written.
    """
    return check_target_folder(out_dir, owned=OUTPUT_FILES)


def _write_set(result: Evaluation, out: Path, extra_manifest: dict | None,
               run_record: dict | None) -> None:  # fmt: skip
    """Write every file of a result set into the (staging) folder ``out``."""
    written = _write_route_files(result.route_table, out / ROUTE_CSV, result.manifest)

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
    legend = _legend(m, iv is not None)
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

    _write_manifests(out, m, extra_manifest, run_record, written, MANIFEST_JSON)


def write_outputs(
    result: Evaluation,
    out_dir: str | os.PathLike,
    extra_manifest: dict | None = None,
    run_record: dict | None = None,
) -> dict[str, Path]:
    """Write every file of an evaluation (see the module docstring) as one whole set.

    The files are written into a hidden staging folder beside ``out_dir`` and moved into place
    together (:class:`lantern_jax.io.files.StagedFolder`): ``out_dir`` holds either the previous
    complete set or the new one, even if the process is killed.  The result files of an
    existing ``out_dir`` are replaced; its other entries (other files, sub-folders) are kept.
    Leftovers of an interrupted earlier write are cleaned first.

    Args:
        result: from :func:`lantern_jax.apps.evaluation.evaluate`.
        out_dir: output folder (created if needed).
        extra_manifest: more entries for the reproducibility manifest (they must be the same
            for the same inputs).
        run_record: more entries for the run record (e.g. the command line).

    Returns:
        File name -> path, for every file written (:data:`OUTPUT_FILES`).

    Raises:
        ValueError: when the route-level table does not satisfy its schema (nothing is
            written).
        lantern_jax.io.files.OutputFolderError: when ``out_dir`` cannot receive the set.
    """
    with StagedFolder(out_dir, OUTPUT_FILES) as stage:
        _write_set(result, stage.path, extra_manifest, _how_written(stage, run_record))
        stage.commit()
    out = Path(out_dir)
    return {name: out / name for name in OUTPUT_FILES}


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


def write_ablation_outputs(
    result: AblationResult,
    out_dir: str | os.PathLike,
    extra_manifest: dict | None = None,
    run_record: dict | None = None,
) -> dict[str, Path]:
    """Write the ablation table (CSV, Markdown), every variant's route-level rows (with the
    schema), a run record and a manifest as one whole set
    (:class:`lantern_jax.io.files.StagedFolder`; the arguments as :func:`write_outputs`).

    Returns:
        File name -> path, for every file of :data:`ABLATION_FILES`.
    """
    with StagedFolder(out_dir, ABLATION_FILES) as stage:
        out = stage.path
        written = _write_route_files(result.route_table, out / ABLATION_ROUTE_CSV,
                                     result.manifest)

        keys = ("model", "condition", "variant")
        table = with_interval_columns(result.table, result.intervals, keys, ABLATION_TABLE_COLUMNS)
        written.append(atomic_write(out / ABLATION_CSV, _csv_bytes(table)))
        m = result.manifest
        legend = _legend(m, result.intervals is not None)
        note = (
            f"Suite `{m.get('suite_id', '?')}` ({m.get('num_pairs', '?')} pairs), {CONDITIONS[0]} "
            "condition. CUS: Overall (macro-average over families); A-Prog., Ant., Rec.: means "
            "x 100; Event Exp.: % of Route A executions whose event began; Coll.-A, Block-A: % "
            f"of pairs failing the gate.{legend}"
        )
        text = format_ablation_table(result.table, tablefmt="github", intervals=result.intervals)
        md = _markdown("Ablations", note, text)
        written.append(atomic_write(out / ABLATION_MD, md))
        _write_manifests(out, m, extra_manifest, _how_written(stage, run_record), written,
                         ABLATION_MANIFEST)  # fmt: skip
        stage.commit()
    target = Path(out_dir)
    return {name: target / name for name in ABLATION_FILES}


def write_tables(tables: dict[str, tuple], out_dir: str | os.PathLike) -> list:
    """Write ``name.csv`` and ``name.md`` for every table as one set (other files of
    ``out_dir`` are kept; :class:`lantern_jax.io.files.StagedFolder`).

    Args:
        tables: file stem -> (title, table) or (title, table, display): the CSV holds the
            table, the Markdown the display (cells with intervals) when there is one.
        out_dir: output folder (created if needed).

    Returns:
        The paths written.
    """
    names = [f"{stem}{ext}" for stem in tables for ext in (".csv", ".md")]
    with StagedFolder(out_dir, names) as stage:
        for stem, (title, df, *display) in tables.items():
            (stage.path / f"{stem}.csv").write_text(df.to_csv(index=False, float_format="%.4g"))
            md = missing_shown(display[0] if display else df).to_markdown(
                index=False, floatfmt=".1f", missingval=MISSING
            )
            (stage.path / f"{stem}.md").write_text(f"# {title}\n\n{md}\n")
        stage.commit()
    return [os.path.join(out_dir, n) for n in names]
