"""The bootstrap behind every interval (``lantern_jax.scoring.uncertainty``) and the paired
comparison (``lantern_jax.report.compare``), on synthetic route tables whose answers are known."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from lantern_jax.core.constants import FAMILIES
from lantern_jax.report.compare import across_suites, check_shared_pairs, compare_runs
from lantern_jax.scoring import uncertainty as u
from lantern_jax.scoring.aggregate import family_scores

EFFECT = 5.0  # CUS points the warning adds on every pair (before noise)
PAIR_SD = 20.0  # spread of the pairs' own difficulty: the part a paired difference cancels
NOISE_SD = 2.0  # per-condition noise


def synthetic_routes(seed: int = 0, per_family: int = 20, model: str = "m") -> pd.DataFrame:
    """Route rows of one model under both conditions: each pair has its own difficulty, the
    warning adds ``EFFECT`` points, and each condition adds a little noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for f in FAMILIES:
        for i in range(per_family):
            base = 50.0 + PAIR_SD * rng.standard_normal()
            for cond, shift in (("warning", EFFECT), ("no-warning", 0.0)):
                cus = base + shift + NOISE_SD * rng.standard_normal()
                rows.append(dict(model=model, condition=cond, pair_id=f"{f.lower()}_{i:04d}",
                                 family=f, CUS=cus))  # fmt: skip
    return pd.DataFrame(rows)


def slow_family_bootstrap(df: pd.DataFrame, resamples: int, seed: int) -> np.ndarray:
    """(resamples, F + 1) family means and their average, pair by pair in plain Python."""
    rng = np.random.default_rng(seed)
    by_family = {f: df.loc[df["family"] == f, "CUS"].to_numpy() for f in FAMILIES}
    out = np.empty((resamples, len(FAMILIES) + 1))
    for b in range(resamples):
        means = []
        for f in FAMILIES:
            x = by_family[f]
            picks = [x[rng.integers(0, len(x))] for _ in range(len(x))]
            means.append(sum(picks) / len(picks))
        out[b] = [*means, sum(means) / len(means)]
    return out


def family_iv(df: pd.DataFrame, seed: int = u.SEED) -> pd.DataFrame:
    """The family table's intervals, indexed by (model, condition)."""
    res = u.table_resampling(df, seed=seed)
    return u.family_intervals(df, res).set_index(["model", "condition"])


def test_family_interval_equals_a_slow_numpy_bootstrap_of_the_route_csv(tmp_path):
    path = tmp_path / "route_level_results.csv"
    synthetic_routes().to_csv(path, index=False)
    df = pd.read_csv(path)
    got = family_iv(df).loc[("m", "warning")]
    slow = slow_family_bootstrap(df[df["condition"] == "warning"], u.RESAMPLES, seed=12345)
    q = (1.0 - u.CONFIDENCE) / 2.0
    lo, hi = np.percentile(slow, [100 * q, 100 * (1 - q)], axis=0)
    # Monte Carlo error of a bootstrap quantile: sqrt(q (1 - q) / B) / density at it, with the
    # density of a normal of the replicates' spread; two independent estimates differ by sqrt(2)
    # of it, allowed 4 standard errors.
    z = 1.959964
    se = math.sqrt(q * (1 - q) / u.RESAMPLES) / (math.exp(-z * z / 2) / math.sqrt(2 * math.pi))
    for k, col in enumerate(u.FAMILY_COLUMNS):
        tol = 4.0 * math.sqrt(2.0) * se * slow[:, k].std()
        assert got[f"{col}_lo"] == pytest.approx(lo[k], abs=tol), col
        assert got[f"{col}_hi"] == pytest.approx(hi[k], abs=tol), col
        assert got[f"{col}_n"] == (len(df) // 2 if col == u.OVERALL else len(df) // 12)


def test_paired_gain_interval_is_narrower_than_the_unpaired_one():
    df = synthetic_routes()
    gain = family_iv(df).loc[("m", u.GAIN)]
    paired = gain["Overall_hi"] - gain["Overall_lo"]
    # Unpaired: each condition's pairs drawn independently of the other's.
    res1, res2 = u.table_resampling(df, seed=1), u.table_resampling(df, seed=2)
    rep = {}
    for cond, res in (("warning", res1), ("no-warning", res2)):
        v, _ = u.pair_matrix(df[df["condition"] == cond], res, "CUS")
        rep[cond] = u.by_family(res, v)[:, -1, 0]
    lo, hi = u.interval(rep["warning"] - rep["no-warning"])
    unpaired = float(hi - lo)
    # Pair difficulty (sd 20) cancels in the paired difference; only the noise (sd 2 per
    # condition) is left, so the paired interval is about sqrt(2) * 2 / sqrt(2 * 20**2 + 2 * 2**2)
    # ~ 1/10 of the unpaired one.
    assert paired < 0.25 * unpaired
    assert gain["Overall_lo"] < EFFECT < gain["Overall_hi"]


def test_the_same_seed_gives_the_same_intervals_and_another_seed_others():
    df = synthetic_routes()
    pd.testing.assert_frame_equal(family_iv(df, seed=7), family_iv(df, seed=7))
    assert not family_iv(df, seed=7).equals(family_iv(df, seed=8))


def test_draws_are_stratified_by_family_and_independent_of_row_order():
    df = synthetic_routes(per_family=7)
    res = u.table_resampling(df, resamples=50, seed=3)
    for f in FAMILIES:
        assert (res.weights[:, res.family_mask(f)].sum(axis=1) == 7).all(), f
    shuffled = u.table_resampling(df.sample(frac=1.0, random_state=0), resamples=50, seed=3)
    np.testing.assert_array_equal(res.weights, shuffled.weights)


def test_interval_of_a_constant_is_that_constant_and_small_cells_count_their_pairs():
    df = synthetic_routes(per_family=3)
    df["CUS"] = 40.0
    iv = family_iv(df)
    row = iv.loc[("m", "warning")]
    assert row["PE_lo"] == row["PE_hi"] == 40.0 and row["PE_n"] == 3 < u.MIN_N
    gain = iv.loc[("m", u.GAIN)]
    assert gain["Overall_lo"] == gain["Overall_hi"] == 0.0


def test_intervals_contain_the_tables_point_estimates():
    df = synthetic_routes()
    iv = family_iv(df)
    points = family_scores(df)
    for cond in ("warning", "no-warning"):
        for col in u.FAMILY_COLUMNS:
            est = points.loc[("m", cond), col]
            assert iv.loc[("m", cond), f"{col}_lo"] < est < iv.loc[("m", cond), f"{col}_hi"]


# ---------------------------------------------------------------------------- paired comparison
def test_compare_against_itself_gives_zero_with_p_one():
    df = synthetic_routes()
    table = compare_runs(df, df.copy())
    assert (table["difference"] == 0.0).all()
    assert (table["lo"] == 0.0).all() and (table["hi"] == 0.0).all()
    assert (table["p"] == 1.0).all()
    assert list(table["condition"].unique()) == ["warning", "no-warning", u.GAIN]
    assert set(table.loc[table["family"] == "PE", "n"]) == {20}


def test_compare_finds_a_shift_on_every_pair():
    a = synthetic_routes(model="a")
    b = a.assign(model="b", CUS=a["CUS"] - 3.0)  # a beats b by exactly 3 on every pair
    table = compare_runs(a, b).set_index(["condition", "family"])
    row = table.loc[("warning", "Overall")]
    assert row["difference"] == pytest.approx(3.0)
    assert row["lo"] == pytest.approx(3.0) and row["hi"] == pytest.approx(3.0)
    assert row["p"] == pytest.approx(1.0 / (1.0 + u.RESAMPLES))  # no replicate reaches 0
    assert table.loc[(u.GAIN, "Overall"), "difference"] == pytest.approx(0.0, abs=1e-9)


def test_compare_refuses_sides_without_the_same_pairs():
    a = synthetic_routes()
    b = a[a["pair_id"] != "pe_0003"]
    with pytest.raises(ValueError, match="pe_0003"):
        check_shared_pairs(a, b)
    with pytest.raises(ValueError, match="do not share their pairs"):
        compare_runs(a, b)


def test_across_suites_gives_mean_and_spread_per_cell():
    tables = []
    for k, overall in enumerate((70.0, 74.0, 78.0)):
        t = pd.DataFrame([dict(model="m", condition="warning", **{f: 60.0 + k for f in FAMILIES},
                               Overall=overall)])  # fmt: skip
        tables.append(t)
    out = across_suites(tables).iloc[0]
    assert out["Overall"] == pytest.approx(74.0) and out["Overall_sd"] == pytest.approx(4.0)
    assert out["PE"] == pytest.approx(61.0) and out["PE_sd"] == pytest.approx(1.0)
    assert out["Overall_min"] == 70.0 and out["Overall_max"] == 78.0 and out["suites"] == 3


def test_sample_interval_of_a_plain_sample():
    """Tables whose unit is not a suite pair (restarts of a search, routes of a diagnostic)."""
    lo, hi, n = u.sample_interval(np.ones(8))
    assert lo == hi == 1.0 and n == 8
    lo, hi, n = u.sample_interval(np.r_[np.zeros(20), np.ones(20)])
    assert lo < 0.5 < hi and n == 40
    # the binomial standard error of 0.5 over 40 restarts is 0.079: a 95 % interval ~ +-0.155
    assert hi - lo == pytest.approx(2 * 1.96 * math.sqrt(0.25 / 40), abs=0.05)
    lo, hi, n = u.sample_interval(np.array([[1.0, np.nan], [3.0, 2.0]]))
    assert list(n) == [2, 1] and hi[1] == lo[1] == 2.0
