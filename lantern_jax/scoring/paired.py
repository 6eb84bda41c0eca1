"""Paired differences between two route tables, with their bootstrap uncertainty.

:func:`compare_runs` — two policies of one result set, or one policy in two result sets over
the same pairs: per family and overall, the paired difference of mean CUS under every shared
condition and of the warning gain, with its bootstrap interval and a paired bootstrap p-value
(:mod:`lantern_jax.scoring.uncertainty`: both sides resampled with the same draws, so a pair's
own difficulty cancels).  :func:`check_shared_pairs` refuses two sides that do not hold the same
pairs.  The command line's ``compare`` and the HTML report
(:mod:`lantern_jax.report.page`) both use it; :mod:`lantern_jax.report.compare` formats it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from lantern_jax.scoring.uncertainty import (
    FAMILY_COLUMNS,
    GAIN,
    NO_WARNING,
    RESAMPLES,
    SEED,
    WARNING,
    by_family,
    family_counts,
    interval,
    p_value,
    pair_matrix,
    table_resampling,
)

#: Columns of :func:`compare_runs`'s table.
COMPARE_COLUMNS = ("condition", "family", "n", "a", "b", "difference", "lo", "hi", "p")


def check_shared_pairs(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Refuse two route tables that do not hold the same pairs (ids and families).

    Raises:
        ValueError: naming pairs found on one side only, or listed under two families.
    """
    fa = a.drop_duplicates("pair_id").set_index("pair_id")["family"]
    fb = b.drop_duplicates("pair_id").set_index("pair_id")["family"]
    only_a, only_b = sorted(set(fa.index) - set(fb.index)), sorted(set(fb.index) - set(fa.index))
    if only_a or only_b:
        raise ValueError(
            f"the two sides do not share their pairs: only in the first {only_a[:8]}"
            f"{' ...' if len(only_a) > 8 else ''}, only in the second {only_b[:8]}"
            f"{' ...' if len(only_b) > 8 else ''}"
        )
    both = fa.index
    differ = [p for p in both if fa[p] != fb[p]]
    if differ:
        raise ValueError(f"pairs listed under different families on the two sides: {differ}")


def _conditions(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    """Conditions of both tables, in ``a``'s order."""
    shared = set(b["condition"])
    return [c for c in dict.fromkeys(a["condition"]) if c in shared]


def compare_runs(
    a: pd.DataFrame, b: pd.DataFrame, seed: int = SEED, resamples: int = RESAMPLES
) -> pd.DataFrame:
    """Paired difference ``a - b`` of per-family and overall mean CUS.

    Args:
        a, b: route-level rows of one model each (``condition``, ``pair_id``, ``family``,
            ``CUS``) over the same pairs.
        seed: the bootstrap's seed.
        resamples: its replicates.

    Returns:
        :data:`COMPARE_COLUMNS`: one row per shared condition (then ``warning gain`` when both
        conditions are shared) and column ``PE .. RTY, Overall``: the pairs compared ``n``,
        both means, their difference, its interval ``lo``, ``hi`` and the two-sided paired
        bootstrap p-value ``p`` (1 for a difference that is 0 on every pair).

    Raises:
        ValueError: when the sides do not share their pairs or conditions, or hold several
            models.
    """
    for side, df in (("first", a), ("second", b)):
        if df["model"].nunique() != 1:
            raise ValueError(f"the {side} side holds models {sorted(set(df['model']))}; give one")
    check_shared_pairs(a, b)
    conds = _conditions(a, b)
    if not conds:
        raise ValueError("the two sides share no condition")
    res = table_resampling(a, resamples, seed)
    va, _ = pair_matrix(a[a["condition"].isin(conds)], res, "CUS", ("condition",))
    vb, _ = pair_matrix(b[b["condition"].isin(conds)], res, "CUS", ("condition",))
    order_a = list(dict.fromkeys(a.loc[a["condition"].isin(conds), "condition"]))
    order_b = list(dict.fromkeys(b.loc[b["condition"].isin(conds), "condition"]))
    va = va[:, [order_a.index(c) for c in conds]]
    vb = vb[:, [order_b.index(c) for c in conds]]
    labels = list(conds)
    if WARNING in conds and NO_WARNING in conds:
        w, nw = conds.index(WARNING), conds.index(NO_WARNING)
        va = np.concatenate([va, va[:, w : w + 1] - va[:, nw : nw + 1]], axis=1)
        vb = np.concatenate([vb, vb[:, w : w + 1] - vb[:, nw : nw + 1]], axis=1)
        labels.append(GAIN)
    values = np.concatenate([va, vb, va - vb], axis=1)
    g = len(labels)
    reps = by_family(res, values)  # (B, F + 1, 3 G)
    est = by_family(res, values, np.ones((1, len(res.pair_ids))))[0]  # (F + 1, 3 G)
    diff = reps[:, :, 2 * g :]
    lo, hi = interval(diff)
    p = p_value(diff, est[:, 2 * g :])
    n = family_counts(res, values[:, 2 * g :])
    rows = []
    for j, cond in enumerate(labels):
        for k, col in enumerate(FAMILY_COLUMNS):
            rows.append((cond, col, int(n[k, j]), est[k, j], est[k, g + j], est[k, 2 * g + j],
                         lo[k, j], hi[k, j], p[k, j]))  # fmt: skip
    return pd.DataFrame(rows, columns=list(COMPARE_COLUMNS))
