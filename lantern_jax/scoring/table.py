"""Route-level results: one row per (model, condition, pair), its schema, validation and files.

The column set, order, dtypes, units and missing-value rules live in
``lantern_jax/data/route_level_schema.json`` (:func:`load_schema`); gate columns are ints
(1 = passed, 0 = failed), times are seconds from execution start, ``NaN`` marks undefined values.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.core import family_codes
from lantern_jax.core.constants import (
    FAMILIES,
    GATE_COLUMN_NAMES,
    GATE_COLUMNS,
    GATE_NAMES,
    WARNING_CONDITION,
)
from lantern_jax.io.files import atomic_write
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components import HAZARD_COMPONENTS
from lantern_jax.scoring.cus import compiled_pair_components
from lantern_jax.scoring.metrics import ROUTE_COLUMNS, ExecutionMetrics
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings
from lantern_jax.scoring.user_metrics import Metric
from lantern_jax.types.world import pad_rows

#: The columns that identify a row (each combination exactly once).
KEY_COLUMNS = ("model", "condition", "pair_id")


def load_schema() -> dict:
    """The route-level schema (``lantern_jax/data/route_level_schema.json``) as a dict."""
    text = resources.files("lantern_jax").joinpath("data/route_level_schema.json").read_text()
    return json.loads(text)


def schema_columns() -> list[tuple[str, str]]:
    """``[(name, dtype), ...]`` in table order; dtype is ``string``, ``int64`` or ``float64``."""
    return [(c["name"], c["dtype"]) for c in load_schema()["columns"]]


def route_schema(metrics: Sequence[dict] = ()) -> dict:
    """The schema of a route table whose rows hold user metrics besides the schema's columns.

    Args:
        metrics: each metric as a manifest records it (``name``, ``unit``, ``description``;
            :meth:`lantern_jax.scoring.user_metrics.Metric.record`), in column order.
    """
    schema = load_schema()
    for m in metrics:
        metric = Metric(m["name"], None, None, None, m.get("unit", "-"), m.get("description", ""))
        schema["columns"] += metric.columns()
    return schema


def metric_columns(a: ExecutionMetrics, b: ExecutionMetrics, metrics: Sequence[Metric],
                   ) -> dict[str, np.ndarray]:  # fmt: skip
    """The route table's columns of the user metrics (``<name>`` Route A, ``B_<name>`` Route B),
    float64, in the order of ``metrics``."""
    taken = {c for c, _ in schema_columns()}
    clash = sorted(taken & {c for m in metrics for c in (m.name, f"B_{m.name}")})
    if clash:
        raise ValueError(f"build_route_table: user metric column(s) {clash} are schema columns")
    if len(a.metrics) != len(metrics) or len(b.metrics) != len(metrics):
        raise ValueError(f"build_route_table: the metrics hold {len(a.metrics)} user metric "
                         f"value(s), the settings name {len(metrics)}")  # fmt: skip
    out = {}
    for m, va, vb in zip(metrics, a.metrics, b.metrics, strict=True):
        out[m.name] = np.asarray(va, np.float64)
        out[f"B_{m.name}"] = np.asarray(vb, np.float64)
    return out


def _per_row(name: str, value: Any, n: int) -> list:
    if isinstance(value, str) or np.ndim(value) == 0:
        return [value] * n
    out = list(value)
    if len(out) != n:
        raise ValueError(f"build_route_table: {name} has {len(out)} entries, expected {n}")
    return out


def _flags(values: Any, n: int) -> np.ndarray:
    """(n,) int64 0/1 column from booleans (None = all 0)."""
    if values is None:
        return np.zeros(n, np.int64)
    return np.broadcast_to(np.asarray(values, bool), (n,)).astype(np.int64)


def _family_codes(families: Any, n: int) -> list[str]:
    codes = []
    for f in _per_row("families", families, n):
        if isinstance(f, str):
            if not family_codes.is_known(f):
                known = family_codes.codes()
                raise ValueError(f"build_route_table: unknown family {f!r}; known: {known}")
            codes.append(f)
        else:
            codes.append(family_codes.code(f))
    return codes


def _batched(
    metrics_a: ExecutionMetrics, metrics_b: ExecutionMetrics
) -> tuple[ExecutionMetrics, ExecutionMetrics, int]:
    """NumPy copies of the Route A and Route B metrics with one leading axis, and its length."""
    a = jax.tree.map(np.asarray, metrics_a)
    b = jax.tree.map(np.asarray, metrics_b)
    n = int(np.shape(a.progress)[0]) if np.ndim(a.progress) else 1
    if np.ndim(a.progress) == 0:
        a = jax.tree.map(lambda x: x[None], a)
        b = jax.tree.map(lambda x: x[None], b)
    if np.shape(b.progress)[0] != n:
        raise ValueError(
            f"build_route_table: {n} Route A executions but {np.shape(b.progress)[0]} Route B"
        )
    return a, b, n


def _family_d_safe(codes: list[str]) -> np.ndarray:
    """(n,) m, the built-in families' clearance normalisers: the deprecated default of
    :func:`build_route_table` (a registered family has none)."""
    other = sorted(set(codes) - set(FAMILIES))
    if other:
        raise ValueError(f"build_route_table: pass d_safe for registered families {other}")
    warnings.warn(
        "build_route_table without d_safe is deprecated: pass the scenes' "
        "ExecutionConfig.d_safe",
        DeprecationWarning,
        stacklevel=3,
    )
    return np.asarray([thresholds.D_SAFE_BY_FAMILY[FAMILIES.index(f)] for f in codes], np.float32)


#: The route table's columns it fills itself from its arguments (the row's identity, the
#: warning delivery and the scene's clearance normaliser); every other column of the schema is
#: measured: :data:`MEASURED_COLUMNS`.
ARGUMENT_COLUMNS = ("model", "condition", "pair_id", "family", "weather", "t_warn_on_s",
                    "d_safe_m", "hazard_hidden_at_warning", "hazard_hidden_before_warning",
                    "warning_ticks", "warning_delivered")  # fmt: skip


def _measured_column_sources() -> dict[str, tuple[str, str]]:
    """Every measured column of the route table -> its source: ``("A" | "B", ExecutionMetrics
    field)`` (:data:`~lantern_jax.scoring.metrics.ROUTE_COLUMNS`, from the context and the
    component table), or ``("pair", key)`` for a pair component (each hazard term's ``SCORE``,
    the gates, ``CUS``); raises unless they and :data:`ARGUMENT_COLUMNS` are the schema's
    columns, each once."""
    sources = dict(ROUTE_COLUMNS)
    pair_columns = {m.SCORE: m.SCORE for m in HAZARD_COMPONENTS.values()}
    pair_columns.update({GATE_COLUMNS[g]: g for g in GATE_NAMES}, CUS="CUS")
    for name, key in pair_columns.items():
        if name in sources:
            raise AssertionError(f"route-table column {name!r} has two sources")
        sources[name] = ("pair", key)
    schema = [c for c, _ in schema_columns()]
    own, measured = set(ARGUMENT_COLUMNS), set(sources)
    if len(set(schema)) != len(schema) or set(schema) != own | measured or own & measured:
        missing, extra = sorted(set(schema) - own - measured), sorted(measured - set(schema))
        raise AssertionError(f"route-table schema columns {missing} have no source, {extra} are "
                             "not in the schema")  # fmt: skip
    return sources


#: Measured route-table column -> ``("A" | "B", ExecutionMetrics field)`` or ``("pair", key of
#: the pair components)``, derived from the component table (checked against the schema when
#: this module is imported).
MEASURED_COLUMNS = _measured_column_sources()


def _measured_columns(a: ExecutionMetrics, b: ExecutionMetrics, comps: dict) -> dict:
    """The columns measured by the rollouts and the scorer (:data:`MEASURED_COLUMNS`), as the
    schema's dtypes (NumPy metrics with leading axis n; the pair components float64)."""
    dtypes = dict(schema_columns())
    routes = {"A": a, "B": b}
    out = {}
    for name, (source, key) in MEASURED_COLUMNS.items():
        value = comps[key] if source == "pair" else getattr(routes[source], key)
        out[name] = np.asarray(value).astype(np.dtype(dtypes[name]))
    return out


#: Rows the route table's components are computed in at a time: a table is padded to a
#: multiple (repeats of its rows, dropped after; every row's components are its own), so
#: the built-in suite (120 pairs) and every subset of it share one compiled program.
COMPONENT_ROWS = 128


def route_components(a: ExecutionMetrics, b: ExecutionMetrics, d_safe: np.ndarray,
                settings: ScoringSettings) -> dict[str, np.ndarray]:  # fmt: skip
    """The components, gates and CUS of ``n`` matched pairs, as the route table holds them
    (float64 NumPy arrays): :data:`~lantern_jax.scoring.cus.compiled_pair_components`,
    computed in blocks of :data:`COMPONENT_ROWS` rows.

    Args:
        a, b: Route A and Route B metrics, NumPy, leading axis ``n``.
        d_safe: (n,) m, clearance normalisers.
        settings: the scoring settings.
    """
    (a, b, d_safe), n = pad_rows((a, b, np.asarray(d_safe, np.float32)), COMPONENT_ROWS)
    comps = compiled_pair_components(a, b, d_safe, settings)
    return {k: np.asarray(v, np.float64)[:n] for k, v in comps.items()}


def build_route_table(
    metrics_a: ExecutionMetrics,
    metrics_b: ExecutionMetrics,
    *,
    model: str | Sequence[str],
    condition: str | Sequence[str],
    pair_ids: Sequence[str],
    families: Sequence[str] | Sequence[int],
    weathers: Sequence[str],
    t_warn_on: Any = None,
    d_safe: Any = None,
    warning_ticks: Any = None,
    hidden_at_warning: Any = None,
    hidden_before_warning: Any = None,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> pd.DataFrame:
    """Route-level DataFrame from batched per-execution metrics.

    Args:
        metrics_a: Route A metrics, every field with leading axis ``n`` (numpy or jax arrays).
        metrics_b: the matched Route B metrics, same leading axis.
        model, condition: one string for all rows or one per row.
        pair_ids, families (codes or indices), weathers: one entry per row.
        t_warn_on: (n,) s, start of warning delivery (``NaN`` = none).  Default: ``t_ref_s`` for
            rows of the warning condition (``constants.WARNING_CONDITION``), ``NaN`` otherwise.
        d_safe: (n,) m, clearance normalisers (the scenes' ``ExecutionConfig.d_safe``).  Left
            out, the built-in families' values are used (2 m PE/OR, else 3 m; deprecated, for
            one release; a registered family's must be given).
        warning_ticks: (n,) int, ticks at which a warning was delivered on Route A
            (default 0).
        hidden_at_warning, hidden_before_warning: (n,) bool, the Route A hazard was hidden from
            the front camera at the warning point / for the whole approach up to it (see the
            schema); default False (0) for every row.
        settings: the scoring settings of the components and the CUS.

    Returns:
        DataFrame with the schema's columns in order (see :func:`validate_route_table`).
    """
    a, b, n = _batched(metrics_a, metrics_b)
    fam = _family_codes(families, n)
    conds = [str(c) for c in _per_row("condition", condition, n)]
    if d_safe is None:
        d_safe = _family_d_safe(fam)
    d_safe = np.broadcast_to(np.asarray(d_safe, np.float64), (n,))
    comps = route_components(a, b, d_safe, settings)
    if t_warn_on is None:
        warned = np.asarray([c == WARNING_CONDITION for c in conds])
        t_warn_on = np.where(warned, np.asarray(a.t_ref_s, np.float64), np.nan)
    shown = np.broadcast_to(
        np.asarray(0 if warning_ticks is None else warning_ticks, np.int64), (n,)
    )
    data = {
        "model": [str(m) for m in _per_row("model", model, n)],
        "condition": conds,
        "pair_id": [str(p) for p in _per_row("pair_ids", pair_ids, n)],
        "family": fam,
        "weather": [str(w) for w in _per_row("weathers", weathers, n)],
        **_measured_columns(a, b, comps),
        "t_warn_on_s": np.broadcast_to(np.asarray(t_warn_on, np.float64), (n,)),
        "d_safe_m": d_safe.copy(),
        "hazard_hidden_at_warning": _flags(hidden_at_warning, n),
        "hazard_hidden_before_warning": _flags(hidden_before_warning, n),
        "warning_ticks": shown,
        "warning_delivered": (shown > 0).astype(np.int64),
    }
    df = pd.DataFrame(data)
    for name, dtype in schema_columns():
        if dtype == "string":
            df[name] = df[name].astype(object)
    df = df[[c for c, _ in schema_columns()]]
    extra = metric_columns(a, b, settings.metrics)
    return pd.concat([df, pd.DataFrame(extra, index=df.index)], axis=1) if extra else df


def _dtype_ok(series: pd.Series, dtype: str) -> bool:
    if dtype == "int64":
        return pd.api.types.is_integer_dtype(series)
    if dtype == "float64":
        return pd.api.types.is_float_dtype(series)
    return pd.api.types.is_string_dtype(series) or (
        series.dtype == object and all(isinstance(v, str) for v in series)
    )


def validate_route_table(df: pd.DataFrame, require_same_pairs: bool = True) -> pd.DataFrame:
    """Check a route-level table against the schema; return it unchanged if it is valid.

    Checks: every schema column present and in schema order (extra columns may follow), dtypes,
    known family codes, gate values in {0, 1}, CUS in [0, 100], each (model, condition, pair_id)
    exactly once, every pair with both its Route A and Route B data (``A_progress`` and
    ``B_progress`` not ``NaN``), and (``require_same_pairs``) the same pair set in every
    (model, condition) group.

    Raises:
        ValueError: naming the missing columns, the wrongly typed columns or the offending pairs.
    """
    cols = schema_columns()
    names = [c for c, _ in cols]
    missing = [c for c in names if c not in df.columns]
    if missing:
        raise ValueError(f"route table: missing column(s) {missing}")
    if list(df.columns[: len(names)]) != names:
        raise ValueError(
            f"route table: columns out of order; expected the schema order {names}, "
            f"got {list(df.columns)}"
        )
    bad = [f"{c} (expected {d}, got {df[c].dtype})" for c, d in cols if not _dtype_ok(df[c], d)]
    if bad:
        raise ValueError(f"route table: wrong dtype for column(s) {bad}")

    def pairs(mask: Any) -> list[str]:
        rows = df.loc[mask, list(KEY_COLUMNS)]
        return ["/".join(map(str, r)) for r in rows.itertuples(index=False)]

    known = family_codes.codes()
    unknown = sorted(set(df["family"]) - set(known))
    if unknown:
        raise ValueError(f"route table: unknown family code(s) {unknown}; known: {known}")
    for g in (*GATE_COLUMN_NAMES, "hazard_hidden_at_warning", "hazard_hidden_before_warning"):
        off = ~df[g].isin([0, 1])
        if off.any():
            raise ValueError(f"route table: {g} must be 0 or 1; offending rows {pairs(off)}")
    cus = df["CUS"]
    off = cus.isna() | (cus < 0) | (cus > 100)
    if off.any():
        raise ValueError(f"route table: CUS must lie in [0, 100]; offending rows {pairs(off)}")
    dup = df.duplicated(list(KEY_COLUMNS), keep=False)
    if dup.any():
        raise ValueError(
            f"route table: duplicate (model, condition, pair_id) rows {sorted(set(pairs(dup)))}"
        )
    for col, route in (("A_progress", "Route A"), ("B_progress", "Route B")):
        off = df[col].isna()
        if off.any():
            raise ValueError(f"route table: pair(s) lacking their {route} execution {pairs(off)}")
    if require_same_pairs and len(df):
        all_pairs = set(df["pair_id"])
        for key, g in df.groupby(["model", "condition"], sort=True):
            lacking = sorted(all_pairs - set(g["pair_id"]))
            if lacking:
                raise ValueError(
                    f"route table: model/condition {'/'.join(key)} lacks pair(s) {lacking}"
                )
    return df


def schema_path_for(path: str | os.PathLike) -> Path:
    """Where :func:`write_route_table` puts the schema: ``<name>.schema.json`` next to the CSV."""
    p = Path(path)
    return p.with_name(p.stem + ".schema.json")


def write_route_table(df: pd.DataFrame, path: str | os.PathLike,
                      metrics: Sequence[dict] = ()) -> Path:  # fmt: skip
    """Validate ``df`` and write it as CSV atomically, with the schema JSON next to it.

    Args:
        df: the route table.
        path: the CSV's path.
        metrics: the user metrics its rows hold (as a manifest records them), described in the
            schema after its columns (:func:`route_schema`).

    Returns:
        The CSV path.  The schema goes to :func:`schema_path_for` ``(path)``.
    """
    validate_route_table(df)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(p, df.to_csv(index=False))
    atomic_write(schema_path_for(p), json.dumps(route_schema(metrics), indent=2) + "\n")
    return p


def read_route_table(path: str | os.PathLike) -> pd.DataFrame:
    """Read a CSV written by :func:`write_route_table` with the schema's dtypes restored."""
    cols = schema_columns()
    dtypes = {c: (object if d == "string" else d) for c, d in cols}
    df = pd.read_csv(path, dtype=dtypes, keep_default_na=False, na_values=["", "NaN", "nan"])
    return df


#: The reproducibility promise across batch composition (a pair alone or inside a larger suite,
#: the group size of the evaluation) and CPU device count: ids, gates and every discrete column
#: identical; CUS and every continuous column within ``REPRODUCIBLE_ATOL +
#: REPRODUCIBLE_RTOL * |value|`` (in the column's unit).  XLA compiles a differently shaped batch
#: into a different program whose float32 rounding may differ in the last bits, and the closed
#: loop carries such a difference forward: measured on lantern-v2 between groups of 360 and of
#: 90 executions, at most 7.6e-5 CUS points, 1.5e-5 m of clearance and 1.2e-4 s on a 24 s
#: time-to-collision (5e-6 of the value, hence the relative term).  The same batch on the same
#: machine reproduces bit for bit.
REPRODUCIBLE_ATOL = 1e-4
REPRODUCIBLE_RTOL = 1e-5


def compare_route_tables(
    before: pd.DataFrame, after: pd.DataFrame, atol: float = REPRODUCIBLE_ATOL
) -> tuple[bool, list[str]]:
    """Compare two route tables row by row (keyed by model, condition, pair).

    Returns:
        ``(promise holds, report lines)``: the promise is that both have the same columns and
        rows, identical text and integer (gate, flag, count) columns, NaN in the same places,
        and float columns within ``atol + REPRODUCIBLE_RTOL * |before|``; the lines count the
        cells that differ at all.
    """
    if list(before.columns) != list(after.columns):
        return False, [f"columns differ: {sorted(set(before.columns) ^ set(after.columns))}"]
    b = before.set_index(list(KEY_COLUMNS)).sort_index()
    a = after.set_index(list(KEY_COLUMNS)).sort_index()
    if not b.index.equals(a.index):
        return False, ["row keys (model, condition, pair_id) differ"]
    ok, lines, differing = True, [], 0
    for col in b.columns:
        x, y = b[col], a[col]
        if pd.api.types.is_float_dtype(x) or pd.api.types.is_float_dtype(y):
            xv, yv = x.to_numpy(np.float64), y.to_numpy(np.float64)
            nan_x, nan_y = np.isnan(xv), np.isnan(yv)
            same = (xv == yv) | (nan_x & nan_y)
            n_diff = int((~same).sum())
            unequal = ~same & ~(nan_x | nan_y)  # equal infinities are the same, not inf - inf
            max_abs = float(np.max(np.abs(xv[unequal] - yv[unequal]), initial=0.0))
            if n_diff:
                lines.append(f"{col}: {n_diff} differ, max |diff| {max_abs:.3g}, "
                             f"NaN mismatches {int((nan_x != nan_y).sum())}")  # fmt: skip
            bound = atol + REPRODUCIBLE_RTOL * np.abs(xv[unequal])
            ok &= bool((nan_x == nan_y).all()) and bool(
                (np.abs(xv[unequal] - yv[unequal]) <= bound).all()
            )
        else:
            n_diff = int((x.astype(str) != y.astype(str)).sum())
            if n_diff:
                lines.append(f"{col}: {n_diff} differ (exact column)")
            ok &= n_diff == 0
        differing += n_diff
    return ok, [f"{differing} of {b.size} cells differ", *lines]
