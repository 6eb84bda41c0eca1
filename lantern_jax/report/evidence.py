"""A result folder is evidence: it is read only after every file has been checked against the
manifest written with it, and two folders are compared only under one protocol.

:func:`read_result_set` opens a folder written by ``lantern-jax evaluate`` (or ``ablations``)
-- or its route-level CSV -- and refuses, in one line naming the file and the field:

* a folder without its manifest, or a manifest that is not the JSON object the writer wrote;
* a file the manifest lists that is missing, has another size (cut short, grown) or another
  SHA-256 (changed after it was written);
* a route table outside its schema (:func:`lantern_jax.scoring.table.validate_route_table`:
  columns, dtypes, CUS in [0, 100] and not NaN, gates 0/1, one row per model, condition and
  pair, both routes of every pair);
* fewer or more rows than the manifest's policies, conditions and pairs make.

:func:`protocol_differences` names what differs between two result sets' protocols (suite
hash, ablation, every recorded setting, tick length, horizon); :func:`version_differences`
the package versions, which change no protocol but are worth a line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import pandas as pd

from lantern_jax.report.outputs import (
    ABLATION_MANIFEST,
    ABLATION_ROUTE_CSV,
    MANIFEST_JSON,
    ROUTE_CSV,
)
from lantern_jax.scoring.table import read_route_table, validate_route_table
from lantern_jax.sim.settings import normalised_record

#: Route-level CSVs a result folder may hold, with the manifest beside each.
RESULT_FILES = ((ROUTE_CSV, MANIFEST_JSON), (ABLATION_ROUTE_CSV, ABLATION_MANIFEST))
#: Manifest entries that define the protocol of a result set (two sets compared must agree).
PROTOCOL_KEYS = ("suite_id", "suite_sha256", "ablation", "conditions", "dt_s", "max_ticks",
                 "settings")  # fmt: skip
#: Packages whose versions a comparison names when they differ.
VERSION_KEYS = ("lantern-jax", "jax", "jaxlib", "numpy", "python")


class ResultSetError(ValueError):
    """A result folder that cannot be taken as evidence; the message names the file and why."""


@dataclasses.dataclass
class ResultSet:
    """A checked result set."""

    csv: Path  # its route-level CSV
    manifest: dict  # its manifest (every file checked against it)
    table: pd.DataFrame  # the route-level rows (schema checked)

    @property
    def folder(self) -> Path:
        """The folder that holds it."""
        return self.csv.parent


def locate(path: str | os.PathLike) -> tuple[Path, Path]:
    """The route-level CSV of a result folder (or the CSV itself) and its manifest's path.

    Raises:
        ResultSetError: when there is no route-level CSV there.
    """
    p = Path(path)
    if p.is_file():
        for csv, manifest in RESULT_FILES:
            if p.name == csv:
                return p, p.with_name(manifest)
        names = " or ".join(c for c, _ in RESULT_FILES)
        raise ResultSetError(f"{path}: not a route-level CSV of a result set ({names})")
    for csv, manifest in RESULT_FILES:
        if (p / csv).is_file():
            return p / csv, p / manifest
    names = " or ".join(c for c, _ in RESULT_FILES)
    raise ResultSetError(f"{path}: no result set there (expected a folder with {names})")


def _manifest(path: Path, csv: Path) -> dict:
    if not path.is_file():
        raise ResultSetError(
            f"{csv}: no {path.name} beside it; a result set is read only with the manifest "
            "written with it (it records every file's SHA-256 and the protocol)"
        )
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ResultSetError(f"{path}: not a readable manifest ({type(e).__name__}: {e})") from None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("files"), list):
        raise ResultSetError(f"{path}: not a result set's manifest (no list of files)")
    return manifest


def check_files(folder: Path, manifest: dict, manifest_path: Path, needed: str) -> None:
    """Check every file the manifest lists against its size and SHA-256; ``needed`` must be
    among them.

    Raises:
        ResultSetError: naming the first file that is missing, changed or cut short.
    """
    listed = {}
    for entry in manifest["files"]:
        ok = isinstance(entry, dict) and isinstance(entry.get("name"), str)
        ok = ok and isinstance(entry.get("sha256"), str) and isinstance(entry.get("bytes"), int)
        if not ok or "/" in entry["name"] or entry["name"] in ("", ".", ".."):
            raise ResultSetError(f"{manifest_path}: files: malformed entry {entry!r}")
        listed[entry["name"]] = entry
    if needed not in listed:
        raise ResultSetError(f"{manifest_path}: files: {needed} is not listed; the manifest is "
                             "not the one written with it")  # fmt: skip
    for name, entry in listed.items():
        path = folder / name
        if not path.is_file():
            raise ResultSetError(f"{path}: missing (the manifest lists it)")
        raw = path.read_bytes()
        if len(raw) != entry["bytes"]:
            raise ResultSetError(
                f"{path}: {len(raw)} bytes, the manifest records {entry['bytes']} (cut short or "
                "changed after it was written)"
            )
        if hashlib.sha256(raw).hexdigest() != entry["sha256"]:
            raise ResultSetError(
                f"{path}: its SHA-256 is not the one the manifest records (changed after it "
                "was written)"
            )


def _expected_rows(manifest: dict) -> int | None:
    """Rows the route table must hold: policies x conditions x pairs (None when the manifest
    does not say)."""
    policies, conditions, pairs = (manifest.get(k) for k in ("policies", "conditions", "num_pairs"))
    if isinstance(policies, list) and isinstance(conditions, list) and isinstance(pairs, int):
        return len(policies) * len(conditions) * pairs
    return None


def read_result_set(path: str | os.PathLike) -> ResultSet:
    """Open a result set as evidence (the module docstring).

    Args:
        path: a result folder, or its route-level CSV.

    Raises:
        ResultSetError: naming the file and what is wrong with it.
    """
    csv, manifest_path = locate(path)
    manifest = _manifest(manifest_path, csv)
    check_files(csv.parent, manifest, manifest_path, csv.name)
    try:
        table = read_route_table(csv)
        validate_route_table(table)
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise ResultSetError(f"{csv}: {e}") from None
    want = _expected_rows(manifest)
    if want is not None and len(table) != want:
        raise ResultSetError(f"{csv}: {len(table)} rows, the manifest's policies, conditions "
                             f"and pairs make {want}")  # fmt: skip
    return ResultSet(csv, manifest, table)


def _flat(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: value}


def protocol_differences(a: dict, b: dict) -> list[str]:
    """What differs between two manifests' protocols (:data:`PROTOCOL_KEYS`, settings field by
    field), one line each; empty when they agree.  A settings record written before 2026-12-08
    names the actors' rule only where it was not that day's default; it is compared as the rule
    it ran under (:func:`lantern_jax.sim.settings.normalised_record`)."""

    def protocol(m: dict) -> dict:
        out = {k: m.get(k) for k in PROTOCOL_KEYS}
        if isinstance(out.get("settings"), dict):
            try:
                out["settings"] = normalised_record(out["settings"])
            except (TypeError, ValueError):  # not a record this package wrote: compared as is
                pass
        return out

    fa = _flat(protocol(a))
    fb = _flat(protocol(b))
    out = []
    for key in sorted(set(fa) | set(fb)):
        va, vb = fa.get(key), fb.get(key)
        if va != vb:
            out.append(f"{key}: {va!r} vs {vb!r}")
    return out


def version_differences(a: dict, b: dict) -> list[str]:
    """The package versions (:data:`VERSION_KEYS`) that differ between two manifests."""
    pa, pb = a.get("packages") or {}, b.get("packages") or {}
    return [f"{k}: {pa.get(k)} vs {pb.get(k)}" for k in VERSION_KEYS if pa.get(k) != pb.get(k)]
