"""Route-level table, its validation and files, and the suite aggregation."""

from __future__ import annotations

import json
import math
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from lantern_jax.core.constants import FAMILIES
from lantern_jax.scoring.aggregate import (
    DECOMPOSITION_COLUMNS,
    decomposition_table,
    family_scores,
    with_time_vs_reference,
)
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.table import (
    build_route_table,
    load_schema,
    read_route_table,
    schema_columns,
    schema_path_for,
    validate_route_table,
    write_route_table,
)
from lantern_jax.scoring.telemetry import fold_telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING

sys.path.insert(0, os.path.dirname(__file__))
from reference_numpy_scoring import make_trajectory  # noqa: E402

REQUIRED = [
    "model", "condition", "pair_id", "family", "weather", "A_progress", "B_progress",
    "ttc_min_s", "clearance_min_m", "t_ref_s", "t_warn_on_s", "t_event_s", "t_warn_off_s",
    "t_clear_s", "t_react_s", "recovery_latency_s", "S_ttc", "S_clear", "S_ant", "S_rec",
    "no_collision", "on_route", "in_lane", "no_red_light", "not_blocked",
    "no_false_brake", "CUS",
]  # fmt: skip


# ---------------------------------------------------------------------------------- aggregation
def _rows(model, cus_by_family):
    rows = []
    for fam, values in cus_by_family.items():
        for i, v in enumerate(values):
            rows.append({"model": model, "condition": "warning", "pair_id": f"{fam}_{i}",
                         "family": fam, "CUS": v})  # fmt: skip
    return rows


def test_family_means_and_macro_average():
    # model m1: PE (80, 60) -> 70, VC (90) -> 90, OR (0, 30, 60) -> 30, LWW 50, RWW 40, RTY 100
    # Overall = (70 + 90 + 30 + 50 + 40 + 100) / 6 = 63.333 (the pooled mean would be 56.25)
    fam = {"PE": [80, 60], "VC": [90], "OR": [0, 30, 60], "LWW": [50], "RWW": [40], "RTY": [100]}
    # model m2 lacks RTY: Overall over the five present families = (10+20+30+40+50)/5 = 30
    fam2 = {"PE": [10], "VC": [20], "OR": [30], "LWW": [40], "RWW": [50]}
    df = pd.DataFrame(_rows("m1", fam) + _rows("m2", fam2))
    out = family_scores(df)
    assert list(out.columns) == [*FAMILIES, "Overall"]
    m1 = out.loc[("m1", "warning")]
    assert [m1[f] for f in FAMILIES] == [70, 90, 30, 50, 40, 100]
    assert m1["Overall"] == pytest.approx(380 / 6)
    m2 = out.loc[("m2", "warning")]
    assert math.isnan(m2["RTY"]) and m2["Overall"] == pytest.approx(30.0)


def test_decomposition_table():
    nan = math.nan
    base = {"model": "m", "condition": "warning", "family": "PE", "CUS": 50.0}
    gates = ["no_collision", "on_route", "in_lane", "no_red_light", "not_blocked",
             "no_false_brake"]  # fmt: skip
    rows = [
        # A_prog, B_prog, S_ttc, S_clear, S_ant, S_rec, gates
        (1.0, 1.0, 0.5, 1.0, 1.0, 0.5, [1, 1, 1, 1, 1, 1]),
        (0.5, 1.0, nan, nan, nan, nan, [0, 1, 1, 1, 0, 1]),
        (1.0, 0.5, 1.0, 0.5, 0.0, nan, [1, 1, 1, 1, 1, 0]),
        (1.0, 1.0, 0.0, 0.0, 0.5, 1.0, [1, 1, 0, 1, 1, 1]),
    ]
    recs = []
    for i, (pa, pb, st, sc, sa, sr, g) in enumerate(rows):
        values = {"A_progress": pa, "B_progress": pb, "S_ttc": st, "S_clear": sc, "S_ant": sa}
        gate_values = dict(zip(gates, g, strict=True))
        # Route B efficiency: 1.0, 1.5, NaN (not completed), 1.0 times the expert's 10 s
        effic = {"B_time_s": (10.0, 15.0, nan, 10.0)[i], "B_slow_s": (0.0, 3.0, 6.0, 0.0)[i]}
        recs.append({**base, "pair_id": f"p{i}", **values, "S_rec": sr, **gate_values, **effic})
    expert = [{**r, "model": "expert", "B_time_s": 10.0} for r in recs]
    out = decomposition_table(pd.DataFrame(recs + expert))
    assert out.loc[("expert", "warning"), "B-Time/Exp."] == 100.0
    alone = decomposition_table(pd.DataFrame(recs)).loc[("m", "warning")]
    assert math.isnan(alone["B-Time/Exp."])  # no expert in the rows: no yardstick
    assert list(out.columns) == list(DECOMPOSITION_COLUMNS)
    r = out.loc[("m", "warning")]
    assert r["A-Prog."] == pytest.approx(87.5)  # (1 + .5 + 1 + 1) / 4
    assert r["TTC"] == pytest.approx(50.0)  # NaN skipped: (.5 + 1 + 0) / 3
    assert r["Clear."] == pytest.approx(50.0)  # (1 + .5 + 0) / 3
    assert r["Ant."] == pytest.approx(50.0)  # (1 + 0 + .5) / 3
    assert r["Rec."] == pytest.approx(75.0)  # (.5 + 1) / 2
    assert r["B-Prog."] == pytest.approx(87.5)
    assert r["Gate Pass"] == pytest.approx(25.0)  # only p0 passes every gate
    assert r["Coll.-A"] == pytest.approx(25.0)
    assert r["RD-A"] == 0.0 and r["Rule-A"] == 0.0
    assert r["LC-A"] == pytest.approx(25.0)
    assert r["Block-A"] == pytest.approx(25.0)
    assert r["False Brake-B"] == pytest.approx(25.0)
    assert r["B-Time/Exp."] == pytest.approx(100.0 * 3.5 / 3)  # NaN skipped: (1 + 1.5 + 1) / 3
    assert r["B-Slow (s)"] == pytest.approx(2.25)  # (0 + 3 + 6 + 0) / 4


# ------------------------------------------------------------------------------------ the table
@pytest.fixture(scope="module")
def batch_metrics():
    """Three pairs (PE clean, VC with a Route A timeout, RTY) as batched metrics."""
    trs_a = [make_trajectory(), make_trajectory(route_extra=10.0), make_trajectory()]
    trs_b = [make_trajectory(route_a=False)] * 3

    def stack(trs):
        return TickSample(**{k: jnp.asarray(np.stack([t[k] for t in trs])) for k in trs[0]})

    settings = DEFAULT_SCORING.replace(temperature=0.01)
    fold = jax.jit(jax.vmap(lambda s: finalize(fold_telemetry(s, settings), settings)))
    return fold(stack(trs_a)), fold(stack(trs_b))


def make_table(batch_metrics, model="m", condition="warning"):
    ma, mb = batch_metrics
    return build_route_table(
        ma, mb, model=model, condition=condition, pair_ids=["p0", "p1", "p2"],
        families=["PE", 1, "RTY"], weathers=["clear_day", "wet_day", "dusk"],
    )  # fmt: skip


def test_build_route_table_columns_and_values(batch_metrics):
    df = make_table(batch_metrics)
    assert list(df.columns[: len(REQUIRED)]) == REQUIRED
    assert [c for c, _ in schema_columns()] == list(df.columns)
    validate_route_table(df)
    assert list(df["family"]) == ["PE", "VC", "RTY"]
    assert df["CUS"].iloc[0] > 50 and df["CUS"].iloc[1] == 0.0  # timeout fails the block gate
    assert df["not_blocked"].tolist() == [1, 0, 1]
    assert df["no_collision"].dtype == np.int64
    # warning condition: delivery starts at the warning point
    assert np.allclose(df["t_warn_on_s"], df["t_ref_s"])
    nw = make_table(batch_metrics, condition="no_warning")
    assert nw["t_warn_on_s"].isna().all()
    assert list(df["d_safe_m"]) == [2.0, 3.0, 3.0]


def test_schema_describes_every_column():
    schema = load_schema()
    names = [c["name"] for c in schema["columns"]]
    assert names[: len(REQUIRED)] == REQUIRED
    for col in schema["columns"]:
        assert set(col) >= {"name", "dtype", "unit", "description", "missing"}
        assert col["dtype"] in ("string", "int64", "float64")


def test_validation_names_missing_column(batch_metrics):
    df = make_table(batch_metrics).drop(columns=["S_rec", "in_lane"])
    with pytest.raises(ValueError, match=r"missing column\(s\) \['S_rec', 'in_lane'\]"):
        validate_route_table(df)


def test_validation_names_wrong_dtype(batch_metrics):
    df = make_table(batch_metrics)
    df["no_red_light"] = df["no_red_light"].astype(float)
    with pytest.raises(ValueError, match="no_red_light"):
        validate_route_table(df)


def test_validation_names_pair_without_route_b(batch_metrics):
    df = make_table(batch_metrics)
    df.loc[1, "B_progress"] = np.nan
    with pytest.raises(ValueError, match=r"lacking their Route B execution \['m/warning/p1'\]"):
        validate_route_table(df)


def test_validation_names_duplicate_and_missing_pairs(batch_metrics):
    df = make_table(batch_metrics)
    dup = pd.concat([df, df.iloc[[2]]], ignore_index=True)
    with pytest.raises(ValueError, match="duplicate.*m/warning/p2"):
        validate_route_table(dup)
    two = pd.concat([df, make_table(batch_metrics, condition="no_warning").iloc[:2]])
    with pytest.raises(ValueError, match=r"m/no_warning lacks pair\(s\) \['p2'\]"):
        validate_route_table(two.reset_index(drop=True))


def test_write_and_read_round_trip(tmp_path, batch_metrics):
    df = pd.concat(
        [make_table(batch_metrics), make_table(batch_metrics, condition="no_warning")],
        ignore_index=True,
    )
    path = write_route_table(df, tmp_path / "out" / "routes.csv")
    assert path.exists() and schema_path_for(path).exists()
    assert json.loads(schema_path_for(path).read_text()) == load_schema()
    assert not [p for p in path.parent.iterdir() if p.name.endswith(".tmp")]
    back = read_route_table(path)
    validate_route_table(back)
    pd.testing.assert_frame_equal(back, df, check_dtype=False)
    assert family_scores(back).shape == (2, 7)


def test_route_b_time_relative_to_the_expert_on_the_same_pair():
    nan = math.nan
    rows = [  # (model, condition, pair, Route B time)
        ("expert", "warning", "p0", 10.0), ("expert", "no-warning", "p0", 10.0),
        ("coop", "warning", "p0", 12.0), ("coop", "no-warning", "p0", 12.0),
        ("expert", "warning", "p1", nan), ("coop", "warning", "p1", 9.0),  # expert unfinished
        ("coop", "warning", "p2", 8.0),  # no expert row
    ]  # fmt: skip
    df = pd.DataFrame(rows, columns=["model", "condition", "pair_id", "B_time_s"])
    out = with_time_vs_reference(df)
    assert list(out["B_time_vs_expert"][:4]) == [1.0, 1.0, 1.2, 1.2]
    assert out["B_time_vs_expert"][4:].isna().all()
    assert "B_time_vs_expert" not in df.columns  # the input is left as it was
