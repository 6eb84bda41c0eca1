"""plot_pair: one pair's executions recorded and drawn, collisions and failed gates marked."""

from __future__ import annotations

import os
import types

import jax
import matplotlib
import numpy as np
import pandas as pd
import pytest

matplotlib.use("Agg")

from lantern_jax.apps.evaluation import EvalResult, settings_record  # noqa: E402
from lantern_jax.core.constants import DT  # noqa: E402
from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim.settings import default_settings  # noqa: E402
from lantern_jax.viz import PairRecording, plot_pair, record_pair  # noqa: E402
from lantern_jax.viz.pair import _from_result, first_failed_gate, telling_tick  # noqa: E402


def _gids(fig) -> set[str]:
    return {a.get_gid() for a in fig.findobj() if a.get_gid()}


@pytest.fixture(scope="module")
def first_pe() -> str:
    return next(p.pair_id for p in load_suite().pairs if p.family == "PE")


@pytest.fixture(scope="module")
def coop_pe(first_pe) -> PairRecording:
    return record_pair("coop", first_pe)


def test_no_warning_collision_is_marked(coop_pe, tmp_path):
    nw = coop_pe.no_warning
    assert not bool(nw.metrics.gate_collision)  # the metrics say it collided
    assert nw.collided and nw.collision_time is not None
    assert first_failed_gate(nw, coop_pe.settings)[0] == "gate_collision"

    old = os.umask(0o022)
    try:
        fig, paths = plot_pair(coop_pe, condition="no-warning", out=tmp_path)
    finally:
        os.umask(old)
    gids = _gids(fig)
    assert "collision" in gids  # the X on the bird's-eye view
    assert "collision:nowarning" in gids  # the timeline's line and marker
    gate = next(a for a in fig.findobj() if a.get_gid() == "gate")
    assert "collision" in gate.get_text()
    (png,) = paths
    assert png.exists() and png.suffix == ".png" and png.stat().st_size > 0
    assert png.stat().st_mode & 0o777 == 0o644
    # the bird's-eye view is drawn at the collision: its title's time is the collision's
    bev = fig.axes[0]
    assert f"t = {nw.collision_time:.2f} s" in bev.get_title()


def test_execution_without_collision_has_no_marker(coop_pe):
    w = coop_pe.warning
    assert bool(w.metrics.gate_collision) and w.collision_time is None
    gids = _gids(plot_pair(coop_pe, condition="warning"))
    assert "collision" not in gids and "collision:warning" not in gids


def test_expert_pair_without_collisions(first_pe):
    rec = record_pair("expert", first_pe)
    assert not any(rec.execution(c).collided for c in ("warning", "no-warning", "route-b"))
    gids = _gids(plot_pair(rec, condition="route-b"))
    assert not any(g.startswith("collision") for g in gids)


def test_bad_pair_id_is_refused():
    with pytest.raises(ValueError, match="no_such_pair"):
        record_pair("coop", "no_such_pair")
    with pytest.raises(ValueError, match="no_such_pair"):
        plot_pair("coop", pair_id="no_such_pair")


def test_bad_condition_and_policy_twice(coop_pe):
    with pytest.raises(ValueError, match="condition"):
        plot_pair(coop_pe, condition="sideways")
    with pytest.raises(ValueError, match="policy given twice"):
        plot_pair("coop", "pe_0001")


def test_telling_tick_is_first_collision_else_min_clearance():
    t = DT * np.arange(1, 11)
    done = np.zeros(10, bool)
    done[7:] = True  # the execution ended at entry 7
    rec = types.SimpleNamespace(t=t, done=done)
    clearance = np.array([5, 4, 3, 2, 0.5, 1, np.nan, 3, 0.0, 0.0])
    assert telling_tick(rec, collision_time=t[3], clearance=clearance) == 3
    assert telling_tick(rec, collision_time=t[3] - 0.2 * DT, clearance=clearance) == 3
    assert telling_tick(rec, clearance=clearance) == 4  # entries past the end are ignored
    assert telling_tick(rec, collision_time=np.nan, clearance=clearance) == 4
    assert telling_tick(rec, clearance=np.full(10, np.nan)) == 7
    assert telling_tick(rec) == 7


def test_result_gives_suite_settings_and_policy():
    settings = default_settings()
    manifest = dict(
        suite_id="lantern-v3-sub",
        ablation="late_onset",
        settings=settings_record(settings),
        policies=[dict(name="coop")],
    )
    empty = pd.DataFrame()
    result = EvalResult(empty, empty, empty, manifest, [], empty)
    pol, suite, got, ablation = _from_result(result, None, None)
    assert pol == "coop" and ablation == "late_onset"
    assert suite.suite_id == load_suite().suite_id
    assert got == settings
    with pytest.raises(ValueError, match="expert"):
        _from_result(result, "expert", None)


def test_the_plot_command_writes_the_figure_and_names_a_bad_pair(tmp_path, capsys):
    """``lantern-jax plot`` writes the chosen execution's figure, readable by others; an unknown
    pair id ends with exit code 2 and a message naming it."""
    from lantern_jax.cli import main

    out = tmp_path / "plots"
    assert main(["plot", "--pair", "pe_0001", "--condition", "no-warning", "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    png = out / "pe_0001_coop_no-warning.png"
    assert png.is_file() and png.stat().st_size > 10_000
    assert str(png) in capsys.readouterr().out
    assert main(["plot", "--pair", "zz_9999", "--out", str(out), "--quiet"]) == 2
    assert "zz_9999" in capsys.readouterr().err


def test_pairs_and_batches_of_the_suite_share_one_recorded_program(coop_pe):
    """Recorded rollouts run to the longest timeout rounded up to RECORD_HORIZON_STEP_S and at
    least RECORD_MIN_HORIZON_S, the batch padded to RECORD_BATCH_STEP executions: another pair
    (pe_0001 47.4 s, rty_0002 longer) and a dozen executions of several families compile nothing
    new, every result is its own execution's (the padding's copies are dropped), and records end
    with frozen, ``done`` ticks past an execution's end."""
    from lantern_jax.apps import diagnostics
    from lantern_jax.core.constants import DT, RECORD_BATCH_STEP, RECORD_MIN_HORIZON_S
    from lantern_jax.scenarios.families import build_pair
    from lantern_jax.scenarios.suite import load_suite

    assert coop_pe.pair_id == "pe_0001"
    before = diagnostics._recorded._cache_size()
    other = record_pair("coop", "rty_0002")
    ticks = len(other.warning.record.t)
    assert ticks == len(coop_pe.warning.record.t) == round(RECORD_MIN_HORIZON_S / DT)
    done = np.asarray(other.route_b.record.done, bool)
    assert done[-1] and not done[0]
    pairs = [p for p in load_suite().pairs if p.pair_id.endswith(("_0001", "_0002"))]
    scenes = [build_pair(p.params)[0] for p in pairs]
    assert 3 < len(scenes) <= RECORD_BATCH_STEP and len(scenes) % RECORD_BATCH_STEP
    coop = get_policy("coop")
    params = coop.init(jax.random.PRNGKey(0))
    _, rec, metrics = diagnostics.run_recorded(coop, params, scenes)
    assert diagnostics._recorded._cache_size() == before
    assert np.asarray(rec.t).shape == (len(scenes), ticks)
    assert np.asarray(metrics.progress_m).shape == (len(scenes),)
    # every row is its own scenario's: the batch's second execution run alone (padded with its
    # own copies, the same program) gives its row, bit for bit
    _, rec_1, metrics_1 = diagnostics.run_recorded(coop, params, scenes[1:2])
    assert diagnostics._recorded._cache_size() == before
    np.testing.assert_array_equal(np.asarray(rec.ego_xy)[1], np.asarray(rec_1.ego_xy)[0])
    np.testing.assert_array_equal(
        np.asarray(metrics.progress_m)[1], np.asarray(metrics_1.progress_m)[0]
    )
    assert not np.array_equal(np.asarray(rec.ego_xy)[0], np.asarray(rec.ego_xy)[1])
