"""Scenario stress testing: search spaces, gradient estimators, verification, bad inputs, and a
whole (small) stress test whose found scenarios re-evaluate to the same hard CUS."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import constant_speed_waypoints
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.constants import KIND_PEDESTRIAN, ROLE_HAZARD, TRIGGER_EVENT
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios.families import KNOB_RANGES
from lantern_jax.scenarios.handmade import ActorSpec, straight_scene
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.stress import objective, report
from lantern_jax.stress.space import search_space


@pytest.fixture(scope="module")
def suite():
    return load_suite()


# ---------------------------------------------------------------------------------------------
# search spaces
# ---------------------------------------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(
    family=st.sampled_from(sorted(KNOB_RANGES)),
    z=st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=3, max_size=3),
)
def test_unconstrained_map_never_leaves_the_ranges(family, z):
    space = search_space(family)
    v = np.asarray(space.values(jnp.asarray(z[: space.dim], jnp.float32)))
    assert np.all(v >= space.lo) and np.all(v <= space.hi)


def test_unconstrained_round_trip():
    space = search_space("VC")
    values = (space.lo + space.hi) / 2 + np.array([0.3, -0.1, 0.2], np.float32)
    back = np.asarray(space.values(space.unconstrained(values)))
    np.testing.assert_allclose(back, values, rtol=1e-5)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(family_code="XX"), r"family: 'XX' not one of"),
        (dict(family_code="PE", knobs=("hazard_start",)), r"PE: knob\(s\) hazard_start not in"),
        (dict(family_code="PE", ranges={"hazard_speed": (4.0, 3.0)}),
         r"PE.hazard_speed: range \[4.0, 3.0\] is empty"),
        (dict(family_code="PE", ranges={"hazard_speed": (1.0, 3.0)}),
         r"leaves the documented \[1.5, 4.5\]"),
        (dict(family_code="PE", knobs=("hazard_speed",), ranges={"hazard_delay": (0.0, 1.0)}),
         r"range given for knob\(s\) not searched: hazard_delay"),
    ],
)  # fmt: skip
def test_bad_search_spaces_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        search_space(**kwargs)


def test_a_range_that_excludes_the_suite_is_refused(suite):
    with pytest.raises(ValueError, match=r"excludes the suite's own value 3 \(pair pe_0001\)"):
        search_space("PE", ranges={"hazard_speed": (3.5, 4.5)}, suite=suite)
    search_space("PE", ranges={"hazard_speed": (2.0, 4.0)}, suite=suite)  # contains 3 m/s


def test_non_positive_budget_and_unknown_method(suite):
    pair = suite.pairs[0]
    with pytest.raises(ValueError, match=r"budget_s: must be > 0, got 0"):
        report.stress_test(pair, "coop", report.StressConfig(budget_s=0.0), progress=False)
    with pytest.raises(ValueError, match=r"methods: \['annealing'\] not among"):
        cfg = report.StressConfig(budget_s=1.0, methods=("annealing",))
        report.stress_test(pair, "coop", cfg, progress=False)


# ---------------------------------------------------------------------------------------------
# gradient estimators on functions with known answers
# ---------------------------------------------------------------------------------------------
EPS = np.random.default_rng(0).normal(0.0, 1.0, (512, 2)).astype(np.float32)


def test_estimators_on_a_smooth_quadratic():
    """f(z) = |z - c|^2: the smoothed objective has the same gradient 2 (z - c); the first-order
    estimate equals it exactly (the mean perturbation cancels in a linear gradient), the
    zeroth-order one approximates it, and the blend trusts the first-order estimate."""
    c = jnp.asarray([1.0, -2.0])
    z = jnp.asarray([0.5, 0.5])
    e = objective.smoothed_estimate(lambda x: jnp.sum((x - c) ** 2), z, jnp.asarray(EPS), 0.1)
    exact = 2 * (z - c) + 2 * 0.1 * jnp.mean(EPS, axis=0)
    np.testing.assert_allclose(e.first, exact, rtol=1e-5)
    # zeroth-order standard error ~ |grad| / sqrt(M) = 5.1 / sqrt(512) = 0.23 per coordinate
    np.testing.assert_allclose(e.zeroth, 2 * (z - c), atol=3 * 0.23)
    assert float(e.alpha) == 1.0
    np.testing.assert_allclose(e.blend, e.first)


def test_blend_falls_back_to_zeroth_order_on_a_step():
    """f(z) = 1[z_0 > 0]: the pathwise gradient is 0 everywhere, the smoothed function's slope
    at 0 is the normal density / sigma; the zeroth-order estimate sees it and the blend uses it."""
    sigma = 0.5
    e = objective.smoothed_estimate(
        lambda x: jnp.where(x[0] > 0.0, 1.0, 0.0), jnp.zeros(2), jnp.asarray(EPS), sigma
    )
    np.testing.assert_allclose(e.first, 0.0)
    slope = 1.0 / (sigma * np.sqrt(2 * np.pi))  # d/dz P(z + sigma eps > 0) at z = 0
    assert abs(float(e.zeroth[0]) - slope) < 0.25 * slope
    assert float(e.alpha) == 0.0
    np.testing.assert_allclose(e.blend, e.zeroth)


def test_adam_on_the_estimates_finds_a_known_minimum():
    """The gradient search's update rule (blend + Adam) walks to the minimum of a smooth bowl."""
    import optax

    c = jnp.asarray([1.5, -0.5])
    z = jnp.zeros(2)
    opt = optax.adam(0.1)
    state = opt.init(z)
    rng = np.random.default_rng(1)
    for _ in range(300):
        eps = jnp.asarray(rng.normal(0.0, 1.0, (8, 2)), jnp.float32)
        g = objective.smoothed_estimate(lambda x: jnp.sum((x - c) ** 2), z, eps, 0.2).blend
        updates, state = opt.update(g, state, z)
        z = optax.apply_updates(z, updates)
    np.testing.assert_allclose(z, c, atol=0.05)


# ---------------------------------------------------------------------------------------------
# autodiff against finite differences on a smooth scene
# ---------------------------------------------------------------------------------------------
def _crossing_problem():
    """A pedestrian crossing the ego's path on the event; the ego drives straight at 8 m/s
    whatever happens (no planner decisions), so the clearance is a smooth function of the
    pedestrian's crossing speed and trigger delay."""
    ped = ActorSpec(
        path=np.array([[40.0, -6.0], [40.0, 16.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
        role=ROLE_HAZARD, v_post=3.0, trigger=TRIGGER_EVENT, despawn_at_end=True,
    )  # fmt: skip
    scene = straight_scene([ped], s_warn=20.0, s_event=30.0, s_conflict=40.0, clear_s=22.0,
                           despawn_on_clear=True)  # fmt: skip
    space = search_space("PE")
    cruise = Policy("cruise", lambda key: None, lambda p, obs: constant_speed_waypoints(8.0))
    return objective.Problem(space, scene, scene, cruise, None, 160, 0.1, "clearance")


def test_cmaes_tells_its_own_samples_and_converges_on_a_bowl():
    """CMA-ES gets back exactly the float64 samples it asked for, so it keeps track of the ones
    it injects itself (selective mirrors, mean-shift samples): no "orphanated injected solution"
    warning, and the search walks to the minimum of a bowl in the unconstrained space."""
    import types
    import warnings

    from lantern_jax.stress import search

    centre = np.array([0.7, -1.2, 0.4])
    space = types.SimpleNamespace(dim=3, values=lambda z: np.asarray(z, np.float64))
    problem = types.SimpleNamespace(space=space)

    def verifier(values):
        cus = np.sum((np.asarray(values, np.float64) - centre) ** 2, axis=1)
        n = len(cus)
        return search.Verdict(cus=cus, gates_passed=np.ones(n, bool),
                              clearance_m=np.full(n, np.nan), expert_ok=np.ones(n, bool),
                              failed=np.zeros(n, bool))  # fmt: skip

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trace = search.cmaes_search(problem, verifier, budget_s=0.5, restarts=2, samples=2,
                                    seed=0)  # fmt: skip
    assert len(trace.evaluations) > 20
    assert trace.lowest["cus"] < 1e-3


@pytest.mark.slow
def test_autodiff_agrees_with_finite_differences_on_a_smooth_scene():
    problem = _crossing_problem()
    z = problem.space.unconstrained(jnp.asarray([3.2, 0.4]))
    grad = jax.jit(jax.grad(lambda x: objective.soft_objective(problem, x)))(z)
    f = objective.batched_objective(problem)
    h = 1e-2
    plus = np.asarray(f(jnp.stack([z + h * jnp.eye(2)[i] for i in range(2)])))
    minus = np.asarray(f(jnp.stack([z - h * jnp.eye(2)[i] for i in range(2)])))
    fd = (plus - minus) / (2 * h)
    assert np.all(np.abs(np.asarray(grad)) > 1e-3), "the clearance should depend on both knobs"
    np.testing.assert_allclose(np.asarray(grad), fd, rtol=0.05, atol=1e-3)


# ---------------------------------------------------------------------------------------------
# verification
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_verification_rejects_a_soft_failure_whose_hard_rollout_passes(suite):
    """At a high temperature the soft Route A score of the nominal PE pair under coop lies far
    below the failure threshold, but coop drives it cleanly: verification says no failure."""
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.stress.verify import FAIL_BELOW_CUS, Verifier

    pair = next(p for p in suite.pairs if p.family == "PE")
    cfg = report.StressConfig(temperature=1.0, objective="soft_cus")
    problem = report.make_problem(pair, get_policy("coop"), search_space("PE"), cfg)
    nominal = jnp.asarray([[3.0, 0.0]], jnp.float32)
    soft = float(objective.soft_objective(problem, problem.space.unconstrained(nominal[0])))
    assert soft < FAIL_BELOW_CUS
    verdict = Verifier(problem, get_policy("expert"))(np.asarray(nominal))
    assert bool(verdict.gates_passed[0]) and verdict.cus[0] > FAIL_BELOW_CUS
    assert not bool(verdict.failed[0])


@pytest.mark.slow
def test_a_small_stress_test_end_to_end(suite, tmp_path):
    """Every method runs on a tiny budget; ego's failures on the hidden pedestrian are found; the
    found scenarios, written as a suite file, re-evaluate to the hard CUS the search reported."""
    from lantern_jax.evaluation import evaluate
    from lantern_jax.scoring.table import REPRODUCIBLE_ATOL

    pair = next(p for p in suite.pairs if p.family == "PE")
    # a wall-clock budget: generous, so that a loaded machine still completes a few iterations
    cfg = report.StressConfig(budget_s=10.0, restarts=2, samples=2, seed=0)
    problem, traces = report.stress_test(pair, "ego", cfg, suite=suite, progress=False)
    table = report.comparison_table(traces)
    assert list(table["method"]) == ["gradient", "random", "cmaes"]
    assert (table["failure_rate"] > 0).all()  # ego never sees the hidden pedestrian in time
    assert (table["failure_rate_lo"] <= table["failure_rate"]).all()
    assert (table["failure_rate"] <= table["failure_rate_hi"]).all()
    files = report.write_results(tmp_path, pair, problem.space, traces)
    manifest = json.loads(files["found_suite.json"].read_text())
    assert manifest["pairs"], "nothing was found"
    found = load_suite(files["found_suite.json"])
    result = evaluate(["ego"], suite=found, progress=False)
    got = result.route_table[result.route_table["condition"] == "warning"].set_index("pair_id")
    reported = {f"{pair.pair_id}_{t.method}_r{f['restart']:02d}": f["cus"]
                for t in traces for f in t.found}  # fmt: skip
    for pid, cus in reported.items():
        assert abs(got.loc[pid, "CUS"] - cus) <= REPRODUCIBLE_ATOL, pid
