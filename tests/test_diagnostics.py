"""Language diagnostics: the non-actionable criterion on hand-made trajectories, the wording
table from hand-made route rows, and the non-actionable and distance tables in closed loop (on
the session's shared runner, with the reference policies)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import MODE_COOP, MODE_EGO

from lantern_jax.apps import diagnostics as dg
from lantern_jax.core.constants import DT
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scenarios.warnings import non_actionable_text_ids

T = 200  # ticks of the hand-made trajectories (10 s)


def cruise(v=8.0):
    return np.full(T, v, np.float32), np.ones(T, bool)


# ---------------------------------------------------------------------------------------------
# the criterion on hand-made trajectories
# ---------------------------------------------------------------------------------------------
def test_identical_runs_are_non_actionable():
    v, live = cruise()
    m = dg.response_metrics(v, live, v, live, 100.0, 100.0)
    assert m == dict(dv_max=0.0, stop_s=0.0, rc=100.0, rc_drop=0.0, non_actionable=True)


@pytest.mark.parametrize("dip,ok", [(1.9, True), (2.0, False), (2.5, False)])
def test_speed_reduction_threshold(dip, ok):
    """A dip of ``dip`` m/s below the no-warning speed for 1 s: dv_max = dip; passes < 2 m/s."""
    v_ref, live = cruise()
    v = v_ref.copy()
    v[60:80] -= dip
    m = dg.response_metrics(v_ref, live, v, live, 100.0, 100.0)
    assert m["dv_max"] == pytest.approx(dip, abs=1e-6)
    assert m["non_actionable"] is ok


def test_speeding_up_is_not_a_reduction():
    v_ref, live = cruise()
    m = dg.response_metrics(v_ref, live, v_ref + 1.0, live, 100.0, 100.0)
    assert m["dv_max"] == 0.0 and m["non_actionable"]


@pytest.mark.parametrize("ticks,ok", [(19, True), (20, False)])
def test_stop_threshold(ticks, ok):
    """A standstill of ``ticks`` x 0.05 s (0.95 s passes, 1.0 s fails); the speed reduction is
    measured against a reference that also stopped, so only the stop decides."""
    v, live = cruise()
    v[100 : 100 + ticks] = 0.0
    m = dg.response_metrics(v, live, v, live, 100.0, 100.0)
    assert m["stop_s"] == pytest.approx(ticks * DT)
    assert m["non_actionable"] is ok


@pytest.mark.parametrize("rc,ok", [(95.0, True), (94.9, False)])
def test_route_completion_threshold(rc, ok):
    v, live = cruise()
    m = dg.response_metrics(v, live, v, live, 100.0, rc)
    assert m["rc_drop"] == pytest.approx(100.0 - rc)
    assert m["non_actionable"] is ok


def test_ticks_after_either_run_ended_do_not_count():
    """The reference finished at tick 150 (its frozen speed 0 afterwards must not compare); the
    warned run's ticks after its own end are not a stop."""
    v_ref, live_ref = cruise()
    v_ref[150:], live_ref[150:] = 0.0, False
    v, live = cruise()
    v[150:] = 9.0  # still driving
    v[180:], live[180:] = 0.0, False
    m = dg.response_metrics(v_ref, live_ref, v, live, 100.0, 100.0)
    assert m["dv_max"] == 0.0 and m["stop_s"] == 0.0


def test_longest_stop_and_live_mask():
    speed = np.array([5, 0, 0, 1, 0, 0, 0, 0.05, 2], np.float32)
    live = np.ones(9, bool)
    assert dg.longest_stop_s(speed, live) == pytest.approx(4 * DT)  # 0, 0, 0, 0.05 < 0.1 m/s
    rec = type("R", (), {"done": np.array([[0, 0, 1, 1]], bool)})
    np.testing.assert_array_equal(dg.live_mask(rec), [[1, 1, 1, 0]])


def test_plan_length():
    wps = np.stack([np.arange(1, 11) * 2.0, np.zeros(10)], -1)
    assert dg.plan_length(wps) == pytest.approx(20.0)
    assert dg.plan_length(np.zeros((10, 2))) == 0.0
    assert dg.plan_length([[3.0, 4.0]] + [[3.0, 4.0]] * 9) == pytest.approx(5.0)


# ---------------------------------------------------------------------------------------------
# the wording table from hand-made rows
# ---------------------------------------------------------------------------------------------
def test_tier_rows():
    ids = [f"p{i}" for i in range(6)]
    tiers = np.array([0, 0, 1, 1, 2, 2])
    canon = pd.DataFrame({"pair_id": ids, "CUS": [80.0, 60, 90, 70, 50, 100],
                          "no_collision": [1] * 6})  # fmt: skip
    para = pd.DataFrame({"pair_id": ids, "CUS": [88.0, 66, 45, 0, np.nan, 40],
                         "no_collision": [1, 1, 1, 0, 1, 0]})  # fmt: skip
    t = dg.tier_rows(canon, para, tiers, ids).set_index("Wording")
    low = t.loc["Low ambiguity"]
    # low: paraphrase (88 + 66) / 2 = 77, canonical (80 + 60) / 2 = 70, retention 110 %
    assert (low["n"], low["Paraphrase CUS"], low["Matched canonical"]) == (2, 77.0, 70.0)
    assert low["Retention (%)"] == pytest.approx(110.0) and low["Coll. (%)"] == 0.0
    med = t.loc["Medium ambiguity"]  # (45 + 0) / 2 = 22.5 vs 80: 28.125 %, one collision of two
    assert med["Retention (%)"] == pytest.approx(28.125) and med["Coll. (%)"] == 50.0
    high = t.loc["High ambiguity, no position"]  # p4 has no paraphrase CUS: left out both sides
    assert (high["n"], high["Paraphrase CUS"], high["Matched canonical"]) == (1, 40.0, 100.0)
    assert high["Coll. (%)"] == 100.0
    assert t.loc["All tiers", "n"] == 5


# ---------------------------------------------------------------------------------------------
# closed-loop tables (shared runner instead of the command's own compile)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", [MODE_COOP, MODE_EGO])
def test_nonactionable_table_of_a_template_matcher(shared_runner, mode):
    """coop understands only the canonical wording and ego ignores warnings: none of the five
    texts changes the drive at all (dv_max exactly 0) and every one passes the criterion."""
    shared_runner["mode"] = mode
    t = dg.nonactionable_table("coop")
    assert len(t) == 1 + len(non_actionable_text_ids())
    assert t.loc[0, "Warning input"] == "(no warning)" and t.loc[0, "RC (%)"] == 100.0
    rest = t.iloc[1:]
    assert (rest["dv_max (m/s)"] == 0.0).all() and (rest["Stop (s)"] == 0.0).all()
    assert (rest["RC (%)"] == 100.0).all() and (rest["Non-actionable"] == "yes").all()


def test_distance_table(shared_runner):
    shared_runner["mode"] = MODE_COOP
    opened, closed = dg.distance_table("coop", routes=2)
    assert list(opened["pair"]) == ["pe_0001", "pe_0002"]
    # the frame is the first tick of the window, which opens at the ego's warning point: the
    # runs agree before it, so the no-warning run's warning point falls in the tick before it
    _, scenarios = dg.distance_scenarios(load_suite(), "PE", 2)
    final, rec, _ = dg.run_recorded(None, None, scenarios)
    for r in range(2):
        k0 = int(np.flatnonzero(rec.warning_active[3 * r + 1])[0])
        t_wp = float(final.protocol.t_warn_point[3 * r])
        assert (k0 - 1) * DT - 1e-4 <= t_wp <= k0 * DT + 1e-4
        np.testing.assert_array_equal(rec.ego_xy[3 * r, :k0], rec.ego_xy[3 * r + 2, :k0])
    for _, r in opened.iterrows():
        # cruising ~8 m/s: the 2.5 s plan covers ~20 m; a pedestrian 12 m ahead shortens it
        assert 15.0 < r["no-warning"] < 30.0
        assert r["near"] < 0.5 * r["no-warning"]
        assert r["Retention (%)"] == pytest.approx(100.0 * r["far"] / r["no-warning"])
    c = closed.set_index(["pair", "condition"])
    for pid in opened["pair"]:
        assert (
            c.loc[(pid, "near"), "min speed in window (m/s)"]
            < c.loc[(pid, "no-warning"), "min speed in window (m/s)"]
        )
        assert c.loc[(pid, "no-warning"), "RC (%)"] == 100.0


def test_distance_needs_a_known_family():
    with pytest.raises(ValueError, match="family"):
        dg.distance_scenarios(load_suite(), family="XX")


def test_write_tables(tmp_path):
    df = pd.DataFrame({"a": [1.0, 2.5], "b": ["x", "y"]})
    (tmp_path / "keep.txt").write_text("other")
    paths = dg.write_tables({"t": ("Title", df)}, tmp_path)
    assert sorted(p.split("/")[-1] for p in paths) == ["t.csv", "t.md"]
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "t.csv"), df)
    assert (tmp_path / "t.md").read_text().startswith("# Title\n")
    assert (tmp_path / "keep.txt").read_text() == "other"


def test_a_recorded_rollout_of_nothing_is_refused():
    """No scenarios: named before anything is traced (there is no batch to pad)."""
    from lantern_jax.policies.registry import get_policy

    with pytest.raises(ValueError, match="no scenarios"):
        dg.run_recorded(get_policy("coop"), None, [])
