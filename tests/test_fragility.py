"""Fragility radius: the first-order distance on toy margins with known boundaries, the box
projection and the probe lines, the command's refusals, and (slow) a whole run whose verified
failures re-evaluate through ``evaluate`` to the reported CUS."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.apps.stress import fragility as frag
from lantern_jax.apps.stress.fragility_probes import probe_pair
from lantern_jax.apps.stress.knob_box import knob_union
from lantern_jax.cli import main
from lantern_jax.scenarios.families import KNOB_RANGES, KNOBS_FIELD
from lantern_jax.scenarios.suite import build_suite_batches, load_suite


def _radius_at(f, u0: np.ndarray, active: np.ndarray | None = None) -> tuple:
    """The module's radius of a JAX margin function ``f`` at ``u0`` (one row)."""
    m, g = jax.value_and_grad(f)(jnp.asarray(u0, jnp.float32))
    act = np.ones((1, len(u0)), bool) if active is None else active[None]
    r, d = frag.radius_of(np.asarray([m]), np.asarray(g)[None], act, np.asarray(u0)[None])
    return float(r[0]), d[0]


# ---------------------------------------------------------------------------------------------
# toy margins with known boundaries
# ---------------------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(
    w=st.lists(st.floats(-3, 3, allow_nan=False), min_size=3, max_size=3),
    u0=st.lists(st.floats(0.05, 0.95), min_size=3, max_size=3),
    a=st.floats(0.5, 5.0),
)
def test_a_linear_margin_has_its_exact_distance_to_the_boundary(w, u0, a):
    w, u0 = np.asarray(w), np.asarray(u0)
    if np.linalg.norm(w) < 1e-2:
        return
    b = a + float(w @ u0)  # m(u) = b - w.u, so m(u0) = a > 0
    r, d = _radius_at(lambda u: b - jnp.dot(jnp.asarray(w, jnp.float32), u), u0)
    assert r == pytest.approx(a / np.linalg.norm(w), rel=1e-4)
    np.testing.assert_allclose(d, w / np.linalg.norm(w), atol=1e-5)
    # the predicted point lies on the boundary m = 0
    assert b - w @ (u0 + r * d) == pytest.approx(0.0, abs=1e-3)


def test_a_sphere_boundary_is_found_from_inside_it():
    c, radius = np.array([0.8, 0.2]), 0.5
    u0 = np.array([0.5, 0.4])
    r, d = _radius_at(lambda u: radius - jnp.linalg.norm(u - jnp.asarray(c, jnp.float32)), u0)
    expect = radius - np.linalg.norm(u0 - c)  # the distance from u0 to the sphere
    assert r == pytest.approx(expect, rel=1e-5)
    np.testing.assert_allclose(d, (u0 - c) / np.linalg.norm(u0 - c), atol=1e-5)


def test_a_knob_at_its_bound_does_not_leave_the_box():
    # m = 3 + 3 u0 - 4 u1 at (0, 0.5) is 1; descent wants u0 below 0, where it sits: only u1
    # moves, and m reaches 0 at u1 = 0.75, a distance 0.25
    r, d = _radius_at(lambda u: 3.0 + 3.0 * u[0] - 4.0 * u[1], np.array([0.0, 0.5]))
    np.testing.assert_allclose(d, [0.0, 1.0], atol=1e-6)
    assert r == pytest.approx(0.25, rel=1e-5)


def test_inactive_knobs_and_flat_margins():
    active = np.array([True, False])
    # m = 4 - u0 - 5 u1 is 1 at (0.5, 0.5); only u0 moves: m = 0 at u0 = 1.5
    r, d = _radius_at(lambda u: 4.0 - u[0] - 5.0 * u[1], np.array([0.5, 0.5]), active)
    assert r == pytest.approx(1.0) and d[1] == 0.0  # the inactive knob's slope is ignored
    r, d = _radius_at(lambda u: 2.0 + 0.0 * u[0], np.array([0.5, 0.5]))
    assert r == np.inf and not d.any()
    r, _ = _radius_at(lambda u: -1.0 + u[0], np.array([0.5, 0.5]))
    assert r == 0.0  # already colliding


def test_line_end_and_probe_distances():
    u0 = np.array([[0.25, 0.5], [0.5, 0.5], [0.5, 0.5]])
    d = np.array([[1.0, 0.0], [-0.6, 0.8], [0.0, 0.0]])
    t = frag.line_end(u0, d)
    np.testing.assert_allclose(t, [0.75, 0.625, 0.0])
    dist = frag.probe_distances(np.array([0.3, 0.5, np.inf]), t)
    assert dist.shape == (3, len(frag.MULTIPLES) + frag.LINE_POINTS)
    zero = frag.probe_distances(np.array([0.0]), np.array([0.8]))  # a collision already
    assert np.isnan(zero[0, :4]).all() and np.isfinite(zero[0, 4:]).all()
    twice = frag.probe_distances(np.array([0.2]), np.array([0.8]))  # 1 r = the first line point
    assert np.isfinite(twice[0, 1]) and np.isnan(twice[0, 4])
    np.testing.assert_allclose(dist[0, :4], [0.15, 0.3, 0.45, 0.6])
    np.testing.assert_allclose(dist[1, :4], [0.25, 0.5, np.nan, np.nan])  # past the edge
    assert np.isnan(dist[2]).all()  # no direction: nothing to probe
    np.testing.assert_allclose(dist[0, 4:], 0.75 * np.arange(1, 5) / 4)


def test_knob_boxes_normalise_each_family_and_mask_the_others():
    suite = load_suite().subset(1)
    scen_a, _ = build_suite_batches(suite)
    boxes = frag.knob_boxes(suite, scen_a)
    assert set(boxes.names) == {k for f in KNOB_RANGES for k in KNOB_RANGES[f]}
    for i, p in enumerate(suite.pairs):
        assert {n for n, a in zip(boxes.names, boxes.active[i], strict=True) if a} == set(
            KNOB_RANGES[p.family])
        assert np.all(boxes.lo[i][~boxes.active[i]] == boxes.hi[i][~boxes.active[i]])
    assert boxes.in_box.all()
    # the normalised point maps back onto the scene's own values
    back = boxes.values(boxes.u0)
    for k, n in enumerate(boxes.names):
        now = np.asarray(jax.vmap(frag.knob(n).get)(scen_a), np.float64)
        np.testing.assert_allclose(back[:, k], now, rtol=1e-5, atol=1e-5)


def test_probe_pairs_stay_inside_the_family_ranges():
    pair = load_suite().pairs[0]
    names = knob_union([pair.family])
    hi = np.array([KNOB_RANGES[pair.family][n][1] for n in names]) + 1e-6  # float rounding
    spec = probe_pair(pair, names, hi, "_p3")
    assert spec.pair_id == pair.pair_id + "_p3"
    assert all(v <= KNOB_RANGES[pair.family][n][1] for n, v in spec.params[KNOBS_FIELD].items())


def test_family_summary_counts_and_intervals():
    table = pd.DataFrame(dict(
        family=["PE"] * 4 + ["VC"] * 2, radius=[0.1, 0.2, np.inf, 2.0, 0.5, 0.05],
        fails_on_line=[True, True, False, False, True, False],
        fails_within=[True, False, False, False, True, False],
    ))  # fmt: skip
    s = frag.family_summary(table).set_index("family")
    assert s.loc["PE", "pairs"] == 4 and s.loc["all", "pairs"] == 6
    assert s.loc["PE", "bounded_radius"] == pytest.approx((0.1 + 0.2 + 1 + 1) / 4)
    assert s.loc["PE", "within_2r"] == pytest.approx(0.5) and s.loc["PE", "within_2r_n"] == 2
    assert s.loc["all", "fails_on_line"] == pytest.approx(0.5)
    assert s.loc["all", "bounded_radius_lo"] <= s.loc["all", "bounded_radius"]
    assert s.loc["all", "bounded_radius"] <= s.loc["all", "bounded_radius_hi"]


# ---------------------------------------------------------------------------------------------
# the command's refusals (before anything compiles)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, message",
    [
        (["stress"], "--family is required"),
        (["stress", "--fragility", "--family", "XX"], "--family 'XX': not one of"),
        (["stress", "--fragility", "--space", "adversary"], "--space: --fragility does not"),
        (["stress", "--fragility", "--budget-s", "5", "--restarts", "3"],
         "--budget-s, --restarts: --fragility does not read them"),
        (["stress", "--fragility", "--watch", "all"], "--watch: --fragility does not read it"),
        (["stress", "--family", "PE", "--sampling", "4"], "--sampling: only --fragility"),
        (["stress", "--fragility", "--family", "PE", "--pair", "vc_0001"], "no pair of"),
    ],
)
def test_fragility_refusals_name_the_option(argv, message, capsys, tmp_path):
    code = main([*argv, "--out", str(tmp_path / "out")])
    assert code == 2
    assert message in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# a whole run (slow: compiles the margin program and the evaluation)
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_fragility_run_writes_its_files_and_failures_re_evaluate(tmp_path):
    from lantern_jax.apps.evaluation import evaluate

    out = tmp_path / "frag"
    # coop at the right turns: the family where its scenes lie closest to a collision
    assert main(["stress", "--fragility", "--policy", "coop", "--family", "RTY", "--quiet",
                 "--out", str(out)]) == 0  # fmt: skip
    for f in frag.FRAGILITY_FILES:
        if f != "fragility_sampling.csv":  # written only with --sampling
            assert (out / f).is_file(), f
    table = pd.read_csv(out / "fragility.csv")
    assert (table["family"] == "RTY").all() and len(table) == 20
    # every margin is finite and moves with the knobs: a gradient, not zero
    assert np.isfinite(table["margin_m"]).all() and (table["grad_norm"] > 0).all()
    assert (table["radius"] >= 0).all()
    assert ((table["radius"] == 0) == (table["margin_m"] <= 0)).all()  # a collision: radius 0
    probes = pd.read_csv(out / "fragility_probes.csv")
    found = probes[probes["failed"]]
    assert len(found) > 0
    assert (found["expert_ok"] & found["policy_failed"]).all()
    # the verified failures are an ordinary suite; evaluate gives the CUS the probes reported
    manifest = json.loads((out / "fragility_suite.json").read_text())
    assert len(manifest["pairs"]) == len(found)
    suite = load_suite(out / "fragility_suite.json")
    rows = evaluate(["coop"], suite=suite, progress=False).route_table
    cus = rows[rows["condition"] == "warning"].set_index("pair_id")["CUS"]
    for _, r in found.iterrows():
        assert cus[f"{r['pair_id']}_p{r['probe']}"] == pytest.approx(r["CUS"], abs=1e-3)
