"""Uncertainty of every table: pair-level bootstrap intervals, paired differences and p-values.

A suite is a sample of route pairs, so every figure the project prints is an estimate.  This
module owns how its uncertainty is measured (the one home of :data:`CONFIDENCE`,
:data:`RESAMPLES`, :data:`SEED` and :data:`MIN_N`):

* **The unit of resampling is the pair.**  A :class:`Resampling` draws, for every replicate,
  the pairs of each family with replacement within the family (stratified by family, as the
  suite is built: the same number of pairs per family in every replicate), from a seeded
  generator.  It is stored as a weight matrix (how often each pair is drawn in each replicate),
  so every statistic of every column is one matrix product, vectorised in NumPy.
* **Every statistic of one result set uses the same draws.**  The warning and no-warning rows of
  a model, two models, or the same model in two result sets over the same pairs are therefore
  resampled together: a difference of two cells has a *paired* interval (the pair's own
  difficulty cancels), which is what a warning gain or a comparison needs.
* **Intervals** are percentile intervals of the replicates (:data:`CONFIDENCE`, two-sided).
  A family cell resamples its family's pairs; an ``Overall`` cell is the macro-average of the
  resampled family means (stratified); a pooled cell (the decomposition) is the mean over all
  resampled pairs.  Means skip ``NaN`` as the tables do, and ``n`` counts the pairs a cell
  averages (non-``NaN``); a cell with ``n < MIN_N`` is flagged, its interval unreliable.
* **A paired p-value** (:func:`p_value`) of a difference is the share of centred replicates at
  least as far from the estimate as the estimate is from 0 (the bootstrap's null distribution
  of the difference, two-sided).

The point estimates themselves are computed by the tables as before
(:mod:`lantern_jax.scoring.aggregate`); this module adds only intervals and counts.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import pandas as pd

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES
from lantern_jax.core.constants import NO_WARNING_CONDITION as NO_WARNING
from lantern_jax.core.constants import WARNING_CONDITION as WARNING
from lantern_jax.scoring.aggregate import (
    DECOMPOSITION_COLUMNS,
    GAIN,
    GROUP_COLUMNS,
    OVERALL,
    decomposition_pair_values,
)

CONFIDENCE = 0.95  # two-sided coverage of every interval
RESAMPLES = 2000  # bootstrap replicates
SEED = 0  # seed of the resampling generator (recorded in every manifest)
MIN_N = 10  # a cell averaging fewer pairs than this is flagged
METHOD = "percentile bootstrap over route pairs, stratified by family"

FAMILY_COLUMNS = (*FAMILIES, OVERALL)


def interval_columns(column: str) -> tuple[str, str, str]:
    """The names of a column's lower bound, upper bound and count in an interval table."""
    return f"{column}_lo", f"{column}_hi", f"{column}_n"


def settings(seed: int = SEED, resamples: int = RESAMPLES) -> dict:
    """What a manifest records about the intervals (a reproducible setting, like a seed)."""
    return dict(method=METHOD, confidence=CONFIDENCE, resamples=resamples, seed=seed, min_n=MIN_N)


@dataclasses.dataclass(frozen=True)
class Resampling:
    """Seeded bootstrap draws of a set of pairs, stratified by family.

    Attributes:
        pair_ids: (n,) the pairs, sorted (draws do not depend on the order of a table's rows).
        families: (n,) family code of each pair.
        weights: (B, n) float64, how often replicate ``b`` drew pair ``j``; each row draws as
            many pairs of every family as the family has.
        seed: the generator's seed.
    """

    pair_ids: tuple[str, ...]
    families: tuple[str, ...]
    weights: np.ndarray
    seed: int

    @property
    def resamples(self) -> int:
        """B, the number of replicates."""
        return int(self.weights.shape[0])

    def family_mask(self, family: str) -> np.ndarray:
        """(n,) bool, the pairs of ``family``."""
        return np.asarray(self.families) == family

    @property
    def table_families(self) -> list[str]:
        """The family columns of the tables: the six, then the registered families drawn
        (:func:`lantern_jax.core.family_codes.table_codes`)."""
        return family_codes.table_codes(self.families)

    @property
    def table_columns(self) -> tuple[str, ...]:
        """:attr:`table_families` then ``Overall``."""
        return (*self.table_families, OVERALL)


def resampling(
    pair_ids: Sequence[str],
    families: Sequence[str],
    resamples: int = RESAMPLES,
    seed: int = SEED,
) -> Resampling:
    """Draw the bootstrap replicates of a set of pairs.

    Args:
        pair_ids: the pairs (any order; repeated ids with the same family are one pair).
        families: the stratum of each entry of ``pair_ids`` (the family code for route pairs;
            any label for other samples).
        resamples: B, the number of replicates.
        seed: seed of ``numpy.random.default_rng``.

    Returns:
        The :class:`Resampling`; strata are drawn in sorted order, each from the same
        generator, so the same pairs and seed always give the same draws.

    Raises:
        ValueError: for a pair listed under two strata.
    """
    fam_of = {}
    for p, f in zip(pair_ids, families, strict=True):
        if fam_of.setdefault(str(p), str(f)) != str(f):
            raise ValueError(f"pair {p!r} listed under families {fam_of[str(p)]} and {f}")
    ids = tuple(sorted(fam_of))
    fams = tuple(fam_of[p] for p in ids)
    rng = np.random.default_rng(seed)
    weights = np.zeros((resamples, len(ids)))
    for f in sorted(set(fams)):
        cols = np.flatnonzero(np.asarray(fams) == f)
        k = len(cols)
        draws = rng.integers(0, k, size=(resamples, k)) + k * np.arange(resamples)[:, None]
        counts = np.bincount(draws.ravel(), minlength=resamples * k).reshape(resamples, k)
        weights[:, cols] = counts
    return Resampling(pair_ids=ids, families=fams, weights=weights, seed=seed)


def sample_interval(
    values: np.ndarray,
    strata: Sequence[str] | None = None,
    seed: int = SEED,
    resamples: int = RESAMPLES,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interval of the NaN-skipping mean of each column of a plain sample (rows resampled,
    within ``strata`` when given): for tables whose unit is not a suite pair (restarts of a
    search, routes of a diagnostic).

    Args:
        values: (n,) or (n, G) the sample.
        strata: (n,) stratum of each row (default: one stratum).
        seed: the bootstrap's seed.
        resamples: its replicates.

    Returns:
        ``(lo, hi, n)``, each (G,) (or scalars for a 1-D sample); n counts non-NaN rows.
    """
    v = np.asarray(values, np.float64)
    flat = v.ndim == 1
    v = v[:, None] if flat else v
    ids = [f"{k:08d}" for k in range(len(v))]
    res = resampling(ids, ["all"] * len(v) if strata is None else list(strata), resamples, seed)
    lo, hi = interval(pooled(res, v))
    n = counts(res, v)
    return (lo[0], hi[0], n[0]) if flat else (lo, hi, n)


def table_resampling(
    route_table: pd.DataFrame, resamples: int = RESAMPLES, seed: int = SEED
) -> Resampling:
    """:func:`resampling` of the pairs of a route-level table (``pair_id``, ``family``)."""
    return resampling(route_table["pair_id"], route_table["family"], resamples, seed)


# ---------------------------------------------------------------------------------------------
# replicates of means
# ---------------------------------------------------------------------------------------------
def _weighted_means(weights: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(R, G) NaN-skipping weighted means of the columns of ``values`` (n, G) under each row of
    ``weights`` (R, n); NaN where a row gives no weight to any non-NaN value."""
    ok = ~np.isnan(values)
    sums = weights @ np.where(ok, values, 0.0)
    counts = weights @ ok.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.where(counts > 0, counts, 1.0), np.nan)


def pooled(res: Resampling, values: np.ndarray, pairs: np.ndarray | None = None) -> np.ndarray:
    """Replicates of the NaN-skipping mean over pairs.

    Args:
        res: the draws.
        values: (n, G) per-pair values in ``res.pair_ids`` order (NaN = not available).
        pairs: (n,) bool, the pairs to average (default: all).

    Returns:
        (B, G) replicate means.
    """
    w = res.weights if pairs is None else res.weights * np.asarray(pairs, np.float64)
    return _weighted_means(w, np.asarray(values, np.float64))


def by_family(res: Resampling, values: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Replicates of every family's mean and of their macro-average.

    Args:
        res: the draws.
        values: (n, G) per-pair values in ``res.pair_ids`` order.
        weights: (R, n) weights to use instead of the draws (e.g. ``ones((1, n))`` for the
            estimate on the original pairs).

    Returns:
        (R, F + 1, G) (R = B by default): the NaN-skipping mean of each family of
        :attr:`Resampling.table_families` (NaN for a family without values), then
        ``Overall``, the mean over the families with a value (the tables' macro-average).
    """
    values = np.asarray(values, np.float64)
    w = res.weights if weights is None else np.asarray(weights, np.float64)
    fam = np.stack(
        [_weighted_means(w * res.family_mask(f), values) for f in res.table_families], axis=1
    )
    kept = np.where(np.isnan(fam), 0.0, fam)
    ok = ~np.isnan(fam)
    with np.errstate(invalid="ignore", divide="ignore"):
        overall = kept.sum(axis=1) / ok.sum(axis=1)  # NaN when no family has a value
    return np.concatenate([fam, overall[:, None, :]], axis=1)


def counts(res: Resampling, values: np.ndarray, pairs: np.ndarray | None = None) -> np.ndarray:
    """(G,) int, the pairs a cell averages: non-NaN values among ``pairs`` (default all)."""
    ok = ~np.isnan(np.asarray(values, np.float64))
    if pairs is not None:
        ok = ok & np.asarray(pairs, bool)[:, None]
    return ok.sum(axis=0)


def family_counts(res: Resampling, values: np.ndarray) -> np.ndarray:
    """(F + 1, G) int, the pairs behind each family cell and (their sum) the Overall cell."""
    fam = np.stack([counts(res, values, res.family_mask(f)) for f in res.table_families])
    return np.concatenate([fam, fam.sum(axis=0, keepdims=True)])


def interval(replicates: np.ndarray, confidence: float = CONFIDENCE) -> tuple[np.ndarray, ...]:
    """Percentile interval over the replicate axis (axis 0), NaN replicates skipped.

    Returns:
        ``(lo, hi)``, each ``replicates.shape[1:]``; NaN where every replicate is NaN.
    """
    q = 100.0 * np.asarray([(1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0])
    r = np.asarray(replicates, np.float64)
    empty = np.all(np.isnan(r), axis=0)
    filled = np.where(empty[None], 0.0, r)
    lo, hi = np.nanpercentile(filled, q, axis=0)
    return np.where(empty, np.nan, lo), np.where(empty, np.nan, hi)


def p_value(replicates: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Two-sided paired bootstrap p-value of a difference being 0.

    The replicates, centred on the estimate, stand for the difference's distribution when it
    is 0; the p-value is ``(1 + #{|d* - d| >= |d|}) / (1 + B)`` over the non-NaN replicates.

    Args:
        replicates: (B, ...) replicates of the difference.
        estimate: (...) the difference on the original pairs.

    Returns:
        (...) p-values in (0, 1]; 1 for a difference that is 0 on every pair.
    """
    r = np.asarray(replicates, np.float64)
    d = np.asarray(estimate, np.float64)
    ok = ~np.isnan(r)
    extreme = (np.abs(r - d) >= np.abs(d)) & ok
    p = (1.0 + extreme.sum(axis=0)) / (1.0 + ok.sum(axis=0))
    return np.where(np.isnan(d), np.nan, np.minimum(p, 1.0))


# ---------------------------------------------------------------------------------------------
# per-pair matrices of a route table
# ---------------------------------------------------------------------------------------------
def pair_matrices(
    df: pd.DataFrame, res: Resampling, columns: Sequence[str], by: Sequence[str] = GROUP_COLUMNS
) -> tuple[np.ndarray, list[tuple]]:
    """Columns of route-level rows as (pairs x groups) matrices, built in one pass.

    Args:
        df: rows with ``pair_id``, the ``by`` columns and ``columns`` (at most one row per pair
            and group).
        res: the draws (fixes the pair order).
        columns: the value columns.
        by: the grouping columns.

    Returns:
        ``(values (C, n, G) float64 in res.pair_ids order, NaN where a group lacks the pair;
        group keys in order of first appearance)``.

    Raises:
        ValueError: for a pair given twice in one group, or a pair the draws do not hold.
    """
    keys = list(dict.fromkeys(map(tuple, df[list(by)].itertuples(index=False))))
    g_of = {k: i for i, k in enumerate(keys)}
    p_of = {p: i for i, p in enumerate(res.pair_ids)}
    try:
        rows = np.fromiter((p_of[p] for p in df["pair_id"]), int, len(df))
    except KeyError as e:
        raise ValueError(f"pair {e.args[0]!r} is not among the resampled pairs") from None
    cols = np.fromiter((g_of[k] for k in map(tuple, df[list(by)].itertuples(index=False))), int,
                       len(df))  # fmt: skip
    if len(set(zip(rows.tolist(), cols.tolist(), strict=True))) != len(df):
        raise ValueError(f"a pair appears twice in one group of {list(by)}")
    out = np.full((len(columns), len(res.pair_ids), len(keys)), np.nan)
    out[:, rows, cols] = df[list(columns)].to_numpy(np.float64).T
    return out, keys


def pair_matrix(
    df: pd.DataFrame, res: Resampling, column: str, by: Sequence[str] = GROUP_COLUMNS
) -> tuple[np.ndarray, list[tuple]]:
    """One column of route-level rows as a (pairs x groups) matrix (:func:`pair_matrices`).

    Returns:
        ``(values (n, G) float64 in res.pair_ids order, NaN where a group lacks the pair;
        group keys in order of first appearance)``.
    """
    values, keys = pair_matrices(df, res, [column], by)
    return values[0], keys


def _rows(keys: list[tuple], by: Sequence[str], columns: Sequence[str], lo, hi, n) -> list[dict]:
    """Interval-table rows: ``by`` keys, then ``<c>_lo, <c>_hi, <c>_n`` per column.

    ``lo``, ``hi``, ``n``: (C, G) arrays, column-major over ``columns`` and ``keys``."""
    rows = []
    for g, key in enumerate(keys):
        row = dict(zip(by, key, strict=True))
        for c, col in enumerate(columns):
            names = interval_columns(col)
            row.update({names[0]: lo[c, g], names[1]: hi[c, g], names[2]: int(n[c, g])})
        rows.append(row)
    return rows


def family_intervals(route_table: pd.DataFrame, res: Resampling) -> pd.DataFrame:
    """Intervals of the per-family CUS table, warning-gain rows included (paired: each gain
    replicate is the difference of the two conditions' replicates on the same draws).

    Returns:
        ``model, condition`` then ``<c>_lo, <c>_hi, <c>_n`` for c in ``PE .. RTY, Overall``;
        one row per (model, condition) of ``route_table`` and a ``warning gain`` row per model
        with both conditions.
    """
    values, keys = pair_matrix(route_table, res, "CUS")
    reps = by_family(res, values)  # (B, F + 1, G)
    n = family_counts(res, values)
    gain_keys, gain_reps, gain_n = [], [], []
    for g, (model, cond) in enumerate(keys):
        if cond == WARNING and (model, NO_WARNING) in keys:
            h = keys.index((model, NO_WARNING))
            gain_keys.append((model, GAIN))
            gain_reps.append(reps[:, :, g] - reps[:, :, h])
            gain_n.append(family_counts(res, values[:, g : g + 1] - values[:, h : h + 1])[:, 0])
    if gain_keys:
        reps = np.concatenate([reps, np.stack(gain_reps, axis=2)], axis=2)
        n = np.concatenate([n, np.stack(gain_n, axis=1)], axis=1)
    lo, hi = interval(reps)
    rows = _rows([*keys, *gain_keys], GROUP_COLUMNS, res.table_columns, lo, hi, n)
    return pd.DataFrame(rows)


def pooled_intervals(
    values: pd.DataFrame, res: Resampling, columns: Sequence[str], by: Sequence[str]
) -> pd.DataFrame:
    """Intervals of NaN-skipping means over all pairs of each group (stratified draws).

    Args:
        values: per-pair rows (``pair_id``, the ``by`` columns and ``columns``).
        res: the draws.
        columns: the value columns.
        by: the grouping columns.

    Returns:
        The ``by`` columns, then ``<c>_lo, <c>_hi, <c>_n`` for every column.
    """
    v, keys = pair_matrices(values, res, columns, by)  # (C, n, G)
    c, n, g = v.shape
    flat = v.transpose(1, 0, 2).reshape(n, c * g)  # one matrix product for every column
    lo, hi = interval(pooled(res, flat))
    shape = (c, g)
    return pd.DataFrame(
        _rows(
            keys,
            by,
            columns,
            lo.reshape(shape),
            hi.reshape(shape),
            counts(res, flat).reshape(shape),
        )
    )


def decomposition_intervals(route_table: pd.DataFrame, res: Resampling) -> pd.DataFrame:
    """Intervals of the CUS decomposition (every column pooled over the group's pairs).

    Returns:
        ``model, condition`` then ``<c>_lo, <c>_hi, <c>_n`` for every
        :data:`~lantern_jax.scoring.aggregate.DECOMPOSITION_COLUMNS`.
    """
    return pooled_intervals(
        decomposition_pair_values(route_table), res, DECOMPOSITION_COLUMNS, GROUP_COLUMNS
    )


def premise_intervals(
    route_table: pd.DataFrame, res: Resampling, rows: Sequence[tuple[str, str]]
) -> pd.DataFrame:
    """Intervals of the premise shares (% of Route A executions, all models and conditions).

    Each pair contributes the share of its executions (the same number per pair, so the mean
    over pairs is the table's pooled share); the pair is resampled, not the execution.

    Args:
        route_table: route-level rows with the premise flag columns.
        res: the draws.
        rows: ``(flag column, row label)`` of the premise table.

    Returns:
        ``measure`` then ``<c>_lo, <c>_hi, <c>_n`` for ``PE .. RTY, Overall`` (n in pairs).
    """
    out = []
    for col, label in rows:
        per_pair = 100.0 * route_table.groupby("pair_id")[col].mean()
        v = per_pair.reindex(list(res.pair_ids)).to_numpy(np.float64)[:, None]
        fam = np.stack(
            [pooled(res, v, res.family_mask(f))[:, 0] for f in res.table_families], axis=1
        )
        reps = np.concatenate([fam, pooled(res, v)], axis=1)  # Overall pools every pair
        lo, hi = interval(reps)
        n = family_counts(res, v)[:, 0]
        out += _rows([(label,)], ("measure",), res.table_columns, lo[:, None], hi[:, None],
                     n[:, None])  # fmt: skip
    return pd.DataFrame(out)


@dataclasses.dataclass
class TableIntervals:
    """Intervals of an evaluation's tables (see :func:`table_intervals`)."""

    family: pd.DataFrame  # :func:`family_intervals`
    decomposition: pd.DataFrame  # :func:`decomposition_intervals`
    premise: pd.DataFrame  # :func:`premise_intervals`
    settings: dict  # :func:`settings`


def table_intervals(
    route_table: pd.DataFrame,
    premise_rows: Sequence[tuple[str, str]],
    seed: int = SEED,
    resamples: int = RESAMPLES,
) -> TableIntervals:
    """Intervals of the family table, the decomposition and the premise table of one result
    set, all from one :class:`Resampling` of its pairs."""
    res = table_resampling(route_table, resamples, seed)
    return TableIntervals(
        family=family_intervals(route_table, res),
        decomposition=decomposition_intervals(route_table, res),
        premise=premise_intervals(route_table, res, premise_rows),
        settings=settings(seed, resamples),
    )
