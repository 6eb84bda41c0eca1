"""Scenario stress testing: search spaces, gradient estimators, plausibility, the failure
catalogue, and a whole (small) stress test whose found scenarios re-evaluate to the same hard
CUS."""

from __future__ import annotations

import dataclasses
import types

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from conftest import constant_speed_waypoints
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.apps.stress import objective, report
from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.apps.stress.plausibility import CAP_M
from lantern_jax.apps.stress.space import adversary_space, search_space
from lantern_jax.core.constants import KIND_PEDESTRIAN, ROLE_HAZARD, TRIGGER_CLOCK, TRIGGER_EVENT
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import KNOB_RANGES
from lantern_jax.scenarios.handmade import ActorSpec, straight_scene
from lantern_jax.scenarios.suite import load_suite


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
    with pytest.raises(
        ValueError, match=r"methods: \['annealing'\] not among gradient, random, cmaes, hybrid"
    ):
        cfg = report.StressConfig(budget_s=1.0, methods=("annealing",))
        report.stress_test(pair, "coop", cfg, progress=False)


def test_watched_slots_of_the_hazard_or_of_every_actor(suite):
    """``watch="hazard"``: the hazard and the tracked slots (1 + T entries); ``"all"``: the
    hazard first, then every other slot with a box, padded with the hazard to ``MAX_ACTORS``
    (one program for every family); a bad value is named, by the config check too."""
    from lantern_jax.core.constants import MAX_ACTORS
    from lantern_jax.scenarios.families import build_pair

    pair = next(p for p in suite.pairs if p.family == "RTY")
    a, _, _ = build_pair(pair.params)
    space = adversary_space(a, "RTY", ("hazard",), knots=4, knot_s=0.5)
    hazard = int(np.asarray(a.config.hazard_index))
    boxed = {int(s) for s in np.nonzero(np.asarray(a.actors.extent)[:, 0] > 0)[0]}
    assert space.tracked == (hazard,)  # the hazard's track: watched once, padded to 1 + T
    assert objective.watched_slots(a, space) == (hazard, hazard)
    every = objective.watched_slots(a, space, "all")
    assert len(every) == MAX_ACTORS and every[0] == hazard
    assert set(every) == boxed and len(boxed) > 1  # the hazard and the scene's other vehicles
    assert every[len(boxed):] == (hazard,) * (MAX_ACTORS - len(boxed))
    with pytest.raises(ValueError, match=r"watch: 'near' not one of hazard, all"):
        objective.watched_slots(a, space, "near")
    with pytest.raises(ValueError, match=r"watch: 'near' not one of hazard, all"):
        report.stress_test(pair, "coop", report.StressConfig(watch="near"), progress=False)
    problem = report.make_problem(pair, get_policy("coop"), space, report.StressConfig(watch="all"))
    assert problem.watched == every and problem.tracked_mask.sum() == len(space.tracked)


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
CRUISE = Policy("cruise", lambda key: None, lambda p, obs: constant_speed_waypoints(8.0))


def _crossing(x=40.0, y0=-6.0, trigger=TRIGGER_EVENT, delay=0.0, speed=3.0, s_event=30.0,
              **config):  # fmt: skip
    """A straight road; a pedestrian crossing it at ``x`` (from ``y0`` to the far side) after
    its trigger."""
    ped = ActorSpec(
        path=np.array([[x, y0], [x, 16.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
        role=ROLE_HAZARD, v_post=speed, trigger=trigger, trigger_delay=delay,
        despawn_at_end=True,
    )  # fmt: skip
    config = {"clear_s": 22.0, "despawn_on_clear": True, **config}
    return straight_scene([ped], s_warn=s_event - 1.0, s_event=s_event, s_conflict=x, **config)


def _crossing_problem(expert=None, objective_name="margin", horizon=160):
    """The crossing under the cruise policy (8 m/s whatever happens: no planner decisions, so
    the margin is a smooth function of the pedestrian's track: it is across, metres away, when
    the ego passes)."""
    scene = _crossing(s_event=10.0)
    space = adversary_space(scene, "PE", ("hazard",), knots=8, knot_s=0.5)
    expert_params = None if expert is None else expert.init(jax.random.PRNGKey(0))
    return objective.Problem(space, scene, scene, CRUISE, None, horizon, 0.1, objective_name,
                             expert, expert_params)  # fmt: skip


def test_cmaes_tells_its_own_samples_and_converges_on_a_bowl():
    """CMA-ES gets back exactly the float64 samples it asked for, so it keeps track of the ones
    it injects itself (selective mirrors, mean-shift samples): no "orphanated injected solution"
    warning, and the search walks to the minimum of a bowl in the unconstrained space."""
    import types
    import warnings

    from lantern_jax.apps.stress import search

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


def test_the_nominal_verification_runs_beside_the_methods_compile():
    """``stress_test`` verifies the nominal scene (compiling the hard program) on a second
    thread while the calling thread compiles the methods' programs: the verdict comes back,
    the verification's error reaches the caller, and an error of the compile is raised at once,
    without waiting for the verification still running."""
    import threading

    here = threading.current_thread().name
    seen = {}

    def verify():
        seen["verify"] = threading.current_thread().name
        return "verdict"

    def compile_methods():
        seen["compile"] = threading.current_thread().name

    assert report._compile_beside(verify, compile_methods) == "verdict"
    assert seen["compile"] == here != seen["verify"]

    def broken():
        raise ValueError("no hard program")

    with pytest.raises(ValueError, match="no hard program"):
        report._compile_beside(broken, compile_methods)

    release = threading.Event()

    def interrupted():
        raise KeyboardInterrupt

    try:
        with pytest.raises(KeyboardInterrupt):
            report._compile_beside(lambda: release.wait(60.0), interrupted)
        assert not release.is_set()  # raised while the verification still waited
    finally:
        release.set()


def test_hybrid_descends_from_its_best_draw_and_counts_every_rollout(monkeypatch):
    """The hybrid method on a bowl in a box: each cycle verifies its draws, starts Adam at each
    restart's best draw (lowest fitness), verifies every new iterate, and counts the draws as
    hard rollouts and each step as one soft rollout per part plus two hard ones; the descent
    goes below the draws it started from."""
    from lantern_jax.apps.stress import search

    lo, hi, centre = -3.0, 3.0, np.array([0.7, -1.2, 0.4])
    sigmoid = lambda z: 1.0 / (1.0 + np.exp(-np.asarray(z, np.float64)))  # noqa: E731

    def values(z):
        return (lo + (hi - lo) * sigmoid(z)).astype(np.float32)

    def unconstrained(v):
        u = (np.asarray(v, np.float64) - lo) / (hi - lo)
        return np.log(u) - np.log1p(-u)

    def uniform(rng, n):
        return rng.uniform(lo, hi, (n, 3)).astype(np.float32)

    space = types.SimpleNamespace(dim=3, values=values, unconstrained=unconstrained,
                                  uniform=uniform)  # fmt: skip
    problem = types.SimpleNamespace(space=space, expert=object(), expert_weight=1.0)

    def estimator(problem, sigma):  # the bowl's exact gradient in z, as an Estimate would carry
        def run(z, eps):
            x = values(z).astype(np.float64)
            u = sigmoid(z)
            return types.SimpleNamespace(blend=2.0 * (x - centre) * (hi - lo) * u * (1.0 - u))

        return run

    monkeypatch.setattr(search, "batched_estimator", estimator)
    seen = []

    def verifier(v):
        v = np.asarray(v, np.float64)
        seen.append(v)
        cus = np.sum((v - centre) ** 2, axis=1)
        n = len(cus)
        return search.Verdict(cus=cus, gates_passed=np.ones(n, bool),
                              clearance_m=np.full(n, np.nan), expert_ok=np.ones(n, bool),
                              failed=np.zeros(n, bool))  # fmt: skip

    draws, steps, restarts = 5, 6, 3
    m = search.HybridSearch(problem, verifier, restarts, 0, lr=0.3, draws=draws, steps=steps)
    m.compile()
    m.step()  # the draws
    assert m.trace.counts == dict(soft_policy=0, soft_expert=0, hard_policy=draws,
                                  hard_expert=draws)  # fmt: skip
    first = seen[-1].reshape(restarts, draws, 3)
    best = first[np.arange(restarts), np.argmin(np.sum((first - centre) ** 2, axis=2), axis=1)]
    np.testing.assert_allclose(values(m.z), best, atol=1e-4)  # the descent starts at the best
    for _ in range(steps):
        m.step()
    assert m.trace.counts == dict(soft_policy=steps, soft_expert=steps,
                                  hard_policy=draws + steps, hard_expert=draws + steps)  # fmt: skip
    assert [len(v) for v in seen] == [restarts * draws] + [restarts] * steps
    start = np.sum((best - centre) ** 2, axis=1)
    end = np.sum((seen[-1] - centre) ** 2, axis=1)
    assert np.all(end < start)  # every descent went downhill from its draw
    m.step()  # the next cycle starts with new draws
    assert len(seen[-1]) == restarts * draws and m.phase == 1


@pytest.mark.slow
def test_autodiff_agrees_with_finite_differences_on_a_smooth_scene():
    """On the adversary space of a crossing walker met by a cruising ego, the pathwise gradient
    of the soft collision margin equals central finite differences of it (the closed form of
    the track and the watch are smooth there)."""
    problem = _crossing_problem()
    rng = np.random.default_rng(0)
    z = jnp.asarray(rng.normal(0.0, 0.3, problem.space.dim), jnp.float32)
    # batches of two candidates: the program the batch-independence test below runs too
    quality = report.gradient_quality(problem, np.asarray(z)[None], 0.0, 1, directions=8,
                                      step=1e-2, batch=2)  # fmt: skip
    assert np.isfinite(quality["value"][0]) and 0.0 < quality["value"][0] < CAP_M
    assert quality["cos_first"][0] > 0.99
    pair = jnp.stack([z, 0.5 * z])
    grad = objective.batched_estimator(problem, 0.0)(pair, np.zeros((2, 1, z.shape[0])))
    assert np.all(np.isfinite(np.asarray(grad.first)))
    assert np.all(np.linalg.norm(np.asarray(grad.first), axis=1) > 0)


@given(rows=st.integers(1, 9), multiple=st.integers(1, 5))
@settings(max_examples=40, deadline=None)
def test_padded_candidates_are_the_last_one_repeated_to_a_whole_batch(rows, multiple):
    """:func:`objective.pad_rows`: the candidates first, unchanged, then copies of the last one
    until the count is a multiple of the compiled batch, and no more than that."""
    x = np.arange(rows * 3, dtype=np.float32).reshape(rows, 3)
    out = objective.pad_rows(x, multiple)
    assert len(out) % multiple == 0 and len(out) - rows < multiple
    np.testing.assert_array_equal(out[:rows], x)
    np.testing.assert_array_equal(out[rows:], np.broadcast_to(x[-1], (len(out) - rows, 3)))


@pytest.mark.slow  # the soft program of the test above (two candidates per batch)
def test_a_candidate_s_value_and_gradient_do_not_see_the_rest_of_its_batch():
    """The candidates of a batch are one soft rollout and one backward pass of their sum
    (:func:`objective.part_samples`): candidate 0's value and gradient are the same bits
    whatever candidate 1 is, and candidate 1's gradient is its own (it moves with it).  That
    the gradients are right is the finite-difference test's above."""
    problem = _crossing_problem()
    rng = np.random.default_rng(1)
    z0, z1, z2 = rng.normal(0.0, 0.3, (3, problem.space.dim)).astype(np.float32)
    samples = objective.part_samples(problem)
    v, g = samples(objective.POLICY, np.stack([[z0, z1]]))
    v2, g2 = samples(objective.POLICY, np.stack([[z0, z2]]))
    np.testing.assert_array_equal(v[0, 0], v2[0, 0])
    np.testing.assert_array_equal(g[0, 0], g2[0, 0])
    assert np.abs(g[0, 1] - g2[0, 1]).max() > 0 and np.isfinite(g).all()
    assert np.linalg.norm(g[0, 0]) > 0


# ---------------------------------------------------------------------------------------------
# KING's recipe
# ---------------------------------------------------------------------------------------------
def test_the_margin_over_actors_is_the_nearest_s_unless_its_temperature_shares_it():
    """Two watched actors 1 m and 3 m from a collision.  At the surrogate's 0.1 m the margin is
    the nearest's, 1 m, and the farther actor's share of the gradient is exp(-20) (nothing for
    a descent to follow); at an actor temperature of 2 m the margin is
    -2 log(exp(-1/2) + exp(-3/2)) = 0.3735 m and the gradient's shares are
    softmax(-(1, 3) / 2) = (0.7311, 0.2689)."""
    t = 0.1
    margins = jnp.asarray([1.0, 3.0], jnp.float32)

    def margin(m, actor_temperature=None):  # the watch's accumulator of each actor's margin
        return objective.soft_margin(-m / t, t, actor_temperature)

    np.testing.assert_allclose(float(margin(margins)), 1.0, atol=1e-6)
    assert float(margin(margins)) == float(margin(margins, t))  # None is the surrogate's
    g = np.asarray(jax.grad(margin)(margins))
    np.testing.assert_allclose(g[0], 1.0, atol=1e-6)
    assert 0.0 <= g[1] < 1e-8
    np.testing.assert_allclose(float(margin(margins, 2.0)), 0.37346, atol=1e-4)
    shared = np.asarray(jax.grad(margin)(margins, 2.0))
    np.testing.assert_allclose(shared, [0.73106, 0.26894], atol=1e-5)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_a_bad_actor_temperature_is_refused_naming_it(suite, bad):
    pair = next(p for p in suite.pairs if p.family == "PE")
    cfg = report.StressConfig(actor_temperature=bad)
    with pytest.raises(ValueError, match="actor_temperature: expected metres > 0"):
        report.make_problem(pair, get_policy("coop"), search_space("PE"), cfg)


def test_king_cost_on_its_numbers():
    """KING's cost from a watch: the nearest watched actor's distance averaged over the time any
    was present, plus each tracked actor's soft off-road time as a share of the horizon; with
    no actor ever present the distance is CAP_M; a padded duplicate of the hazard (not
    tracked) adds no off-road time."""
    from lantern_jax.apps.stress.king import king_cost

    near_sum, near_seen = jnp.float32(12.0), jnp.float32(4.0)  # m s, s: 3 m on average
    off = jnp.asarray([0.0, 2.0, 5.0, 7.0])  # s off the road (soft)
    tracked = jnp.asarray([False, True, True, False])
    got = king_cost(near_sum, near_seen, off, tracked, horizon_s=20.0)
    assert float(got) == pytest.approx(3.0 + (2.0 + 5.0) / 20.0)
    far = king_cost(jnp.float32(0.0), jnp.float32(0.0), off, tracked & False, 20.0)
    assert float(far) == pytest.approx(CAP_M)
    g = jax.grad(lambda n, o: king_cost(n, near_seen, o, tracked, 20.0), argnums=(0, 1))(
        near_sum, off
    )
    assert float(g[0]) == pytest.approx(1 / 4.0)
    np.testing.assert_allclose(g[1], [0.0, 1 / 20.0, 1 / 20.0, 0.0])


def test_king_problem_holds_the_policy_and_drops_the_expert_part():
    """KING's problem descends its own cost with the ego's plans held (its detached ego) and no
    expert part; the problem it came from is unchanged, and the two compile apart."""
    from lantern_jax.apps.stress.king import king_problem

    expert = get_policy("expert")
    problem = _crossing_problem(expert=expert, objective_name="plausible")
    king = king_problem(problem)
    assert king.objective == "king" and king.expert_weight == 0.0 and king.hold_policy
    assert objective.parts_of(king) == (objective.POLICY,)
    assert objective.parts_of(problem) == (objective.POLICY, objective.EXPERT)
    assert king.soft_driver.program == objective.held_plans(CRUISE).program  # no switch
    assert problem.soft_driver.members[0].program == CRUISE.program
    # the expert under test: its held program once (a switch would need two distinct ones)
    own = king_problem(dataclasses.replace(problem, policy=expert))
    assert own.soft_driver.program == objective.held_plans(expert).program
    assert king.static() != problem.static()
    verifying = [[m.program for m in p.driver.members] for p in (king, problem)]
    assert verifying[0] == verifying[1]  # the hard rollouts that verify are the same


def test_king_search_steps_with_its_adam_and_counts_one_soft_rollout(monkeypatch):
    """The king method: one soft rollout (the policy's part only) and two hard ones per restart
    and iteration, on KING's problem without smoothing; Adam with KING's step moves each
    iterate by KING_LR per coordinate on its first step (Adam's first step is the step size
    times the gradient's sign)."""
    from lantern_jax.apps.stress import king as king_module
    from lantern_jax.apps.stress import search

    problem = _crossing_problem(expert=get_policy("expert"), objective_name="plausible")
    seen_problems = []

    def estimator(p, sigma):
        seen_problems.append((p.objective, p.hold_policy, sigma))
        return lambda z, eps: types.SimpleNamespace(blend=np.where(np.arange(z.shape[1]) % 2,
                                                                   1.0, -3.0) * np.ones_like(z))

    monkeypatch.setattr(search, "batched_estimator", estimator)

    def verifier(values):
        n = len(values)
        return search.Verdict(cus=np.full(n, 90.0), gates_passed=np.ones(n, bool),
                              clearance_m=np.full(n, np.nan), expert_ok=np.ones(n, bool),
                              failed=np.zeros(n, bool))  # fmt: skip

    m = search.KingSearch(problem, verifier, restarts=3, seed=0)
    assert seen_problems == [("king", True, 0.0)] and m.name == "king"
    z0 = m.z.copy()
    m.step()
    assert m.trace.counts == dict(soft_policy=1, soft_expert=0, hard_policy=1, hard_expert=1)
    sign = np.where(np.arange(z0.shape[1]) % 2, 1.0, -1.0)
    np.testing.assert_allclose(m.z, z0 - king_module.KING_LR * sign, atol=1e-6)


@pytest.mark.slow
def test_king_gradient_agrees_with_finite_differences_on_a_smooth_scene():
    """KING's cost on the crossing walker met by a cruising ego: finite, between the walker's
    least and its farthest mean distance, and its pathwise gradient (the ego's plans held)
    equals central finite differences of it and is not zero."""
    from lantern_jax.apps.stress.king import king_problem

    problem = king_problem(_crossing_problem())
    rng = np.random.default_rng(0)
    z = rng.normal(0.0, 0.3, (1, problem.space.dim)).astype(np.float32)
    quality = report.gradient_quality(problem, z, 0.0, 1, directions=8, step=1e-2, batch=2)
    assert np.isfinite(quality["value"][0]) and 0.0 < quality["value"][0] < CAP_M
    assert quality["cos_first"][0] > 0.99
    # two candidates per call, as the finite differences ran: the same compiled program
    pair = np.concatenate([z, 0.5 * z])
    grad = objective.batched_estimator(problem, 0.0)(pair, np.zeros((2, 1, z.shape[1])))
    assert np.all(np.isfinite(np.asarray(grad.first)))
    assert np.all(np.linalg.norm(np.asarray(grad.first), axis=1) > 0)


# ---------------------------------------------------------------------------------------------
# plausibility
# ---------------------------------------------------------------------------------------------
def test_plausibility_rules_on_their_numbers():
    """The rules as stated: the expert needs every gate, 0.5 m of clearance (or none measured)
    and 0.5 m from every watched actor; a tracked actor may stop in the path for 2 s, never
    leave the road, never exceed its speed limit (within 0.05 m/s)."""
    ok = rules.expert_passes_with_margin(
        np.array([True, True, True, False, True]),
        np.array([0.6, np.nan, 0.4, 3.0, 2.0]),
        np.array([0.5, 3.0, 3.0, 3.0, 0.49]),
    )
    np.testing.assert_array_equal(ok, [True, True, False, False, False])
    plausible = rules.adversary_plausible(
        np.array([2.0, 2.05, 0.0, 0.0]), np.array([0.0, 0.0, 0.05, 0.0]),
        np.array([[4.5], [4.5], [4.5], [4.6]]), np.array([4.54]),
    )  # fmt: skip
    np.testing.assert_array_equal(plausible, [True, False, False, False])
    # the black-box expression: margin + 2 per m of expert margin missing below 1 m + 2 per s
    obj = rules.hard_objective(np.array([1.5, 1.5, 40.0]), np.array([0.25, 3.0, 3.0]),
                               np.array([0.0, 1.5, 0.0]), np.array([0.0, 0.0, 0.0]))  # fmt: skip
    np.testing.assert_allclose(obj, [1.5 + 2 * 0.75, 1.5 + 2 * 0.5, rules.CAP_M])
    # a walker's speed limit: hypot(run, sidestep); a car's: hypot(v, v tan(heading bound))
    assert rules.speed_limit(4.5, 1.0, True, 3.0) == pytest.approx(np.hypot(4.5, 1.0))
    assert rules.speed_limit(16.7, 0.2, False, 20.0) == pytest.approx(np.hypot(20.0, 4.0))


@pytest.mark.slow
def test_only_plausible_failures_are_reported():
    """Three crossings met by the cruising policy (8 m/s, never brakes), verified with the
    privileged expert as the guard:

    * a walker crossing at its scripted 3 m/s into the cruising ego: the policy collides, the
      expert (which sees it) stops with metres to spare: a plausible failure, reported;
    * the same walker braking to a stop in the middle of the lane and waiting there until the
      ego arrives (3.6 s in its path): the policy collides, but the walker froze: not reported;
    * a walker running into the side of the ego right beside it: the expert cannot avoid it
      either (its failure is shared): not reported.
    """
    from lantern_jax.apps.stress.verify import Verifier

    expert = get_policy("expert")

    def verdict(scene, actions):
        space = adversary_space(scene, "PE", ("hazard",), knots=16, knot_s=0.5)
        problem = objective.Problem(space, scene, scene, CRUISE, None, 200, 0.1, "plausible",
                                    expert, expert.init(jax.random.PRNGKey(0)))  # fmt: skip
        return Verifier(problem, batch=2)(np.asarray(actions, np.float32))

    zero, freeze = np.zeros(32), np.zeros(32)
    freeze[3:5] = -1.0  # brake at 3 m/s^2 from 1.5 s to 2.5 s after the trigger: stops mid-lane
    crossing = verdict(_crossing(x=40.0, s_event=20.0), [zero, zero])
    assert crossing.failed[0] and crossing.failed_gates[0] == ["gate_collision"]
    assert crossing.expert_ok[0] and crossing.expert_dist_m[0] > 1.0 and crossing.plausible[0]
    frozen = verdict(_crossing(x=50.0, s_event=5.0, despawn_on_clear=False,
                               clear_time_limit=60.0), [zero, freeze])  # fmt: skip
    assert not frozen.policy_failed[0]  # unperturbed, the walker is across before the ego comes
    assert frozen.policy_failed[1] and frozen.expert_ok[1]
    assert frozen.stop_s[1] > rules.STOP_IN_PATH_LIMIT_S and not frozen.plausible[1]
    assert not frozen.failed[1]
    beside = _crossing(x=4.0, y0=-2.5, trigger=TRIGGER_CLOCK, delay=0.1, speed=4.5, s_event=3.0)
    side = verdict(beside, [zero, zero])
    assert side.policy_failed[0] and not side.expert_ok[0] and not side.failed[0]


# ---------------------------------------------------------------------------------------------
# the failure catalogue
# ---------------------------------------------------------------------------------------------
def test_near_duplicates_of_a_manoeuvre_are_one_failure():
    """The paper's rule on the adversary's positions at equal times: within 3 m at 70 % of the
    samples both ways is the same manoeuvre; farther, or present in one only, is another."""
    from lantern_jax.apps.stress import catalogue

    t = np.arange(20, dtype=np.float64)
    base = np.stack([t, np.zeros_like(t)], -1)[:, None, :]  # (K, W=1, 2)
    near = base + np.array([0.0, 2.5])  # 2.5 m apart everywhere
    far = base.copy()
    far[:8] += np.array([0.0, 4.0])  # 4 m apart at 8 of 20 samples: 60 % near
    gone = base.copy()
    gone[7:] = np.nan  # absent from 7 s on: only 35 % of base's samples are matched
    assert catalogue.same_manoeuvre(base, near, [0])
    assert not catalogue.same_manoeuvre(base, far, [0])
    assert not catalogue.same_manoeuvre(base, gone, [0])
    problem = types.SimpleNamespace(tracked_mask=np.array([True]))
    failures = [dict(traj=x) for x in (base, near, far, gone, far + 0.1)]
    assert catalogue.distinct(failures, problem) == [0, 2, 3]


@pytest.mark.slow
def test_found_failures_round_trip_through_their_suite_file(suite, tmp_path):
    """A small adversary stress test of ``ego`` on the hidden pedestrian: every method (the
    hybrid's draws and descent included) finds verified failures; the catalogue, written as a
    suite file, re-evaluates to the hard CUS the search verified (within the evaluation's
    reproducibility promise) with the same gates."""
    from lantern_jax.apps.evaluation import evaluate
    from lantern_jax.scoring.table import REPRODUCIBLE_ATOL

    pair = next(p for p in suite.pairs if p.family == "PE")
    cfg = report.StressConfig(space="adversary", knots=8, budget_s=600.0, budget_rollouts=8,
                              restarts=2, popsize=2, methods=("random", "cmaes", "hybrid"),
                              hybrid_draws=2, hybrid_steps=1)  # fmt: skip
    problem, traces = report.stress_test(pair, "ego", cfg, suite=suite, progress=False)
    table = report.comparison_table(traces, problem)
    assert list(table["method"]) == ["random", "cmaes", "hybrid"]
    assert (table["failure_rate"] > 0).all()
    assert (table["failure_rate_lo"] <= table["failure_rate"]).all()
    assert (table["failure_rate"] <= table["failure_rate_hi"]).all()
    assert (table["rollouts"] >= 8).all()
    soft = table.set_index("method")["rollouts_soft_policy"]
    assert soft["random"] == soft["cmaes"] == 0 and soft["hybrid"] > 0  # the hybrid descended
    files = report.write_results(tmp_path, pair, problem.space, traces, None, problem, "ego")
    entries = pd.read_csv(files["catalogue.csv"])
    assert len(entries) >= 1 and entries["description"].str.contains("pedestrian").all()
    found = load_suite(files["catalogue_suite.json"])
    assert all("adversary" in p.params for p in found.pairs)
    result = evaluate(["ego"], suite=found, progress=False, path="split")  # the stored world
    got = result.route_table[result.route_table["condition"] == "warning"].set_index("pair_id")
    for _, e in entries.iterrows():
        assert abs(got.loc[e["pair_id"], "CUS"] - e["hard_cus"]) <= REPRODUCIBLE_ATOL, e["pair_id"]


@pytest.mark.slow
def test_verification_rejects_a_soft_failure_whose_hard_rollout_passes(suite):
    """At a high temperature the soft Route A score of the nominal PE pair under coop lies far
    below the failure threshold, but coop drives it cleanly: verification says no failure."""
    from lantern_jax.apps.stress.verify import FAIL_BELOW_CUS, Verifier

    pair = next(p for p in suite.pairs if p.family == "PE")
    cfg = report.StressConfig(temperature=1.0, objective="soft_cus", expert_weight=0.0)
    problem = report.make_problem(pair, get_policy("coop"), search_space("PE"), cfg)
    nominal = jnp.asarray([[3.0, 0.0]], jnp.float32)
    soft = float(objective.soft_objective(problem, problem.space.unconstrained(nominal[0])))
    assert soft < FAIL_BELOW_CUS
    verdict = Verifier(problem)(np.asarray(nominal))
    assert bool(verdict.gates_passed[0]) and verdict.cus[0] > FAIL_BELOW_CUS
    assert not bool(verdict.failed[0])


# ---------------------------------------------------------------------------------------------
# the program store
# ---------------------------------------------------------------------------------------------
def _user_speed_setter(scenario, value):
    """A knob's write function from outside the package (here: a test module)."""
    return scenario


def test_a_cells_programs_are_kept_only_when_the_store_can_vouch_for_them(suite, monkeypatch):
    """A stress cell's programs are keyed for the program store when everything they call is
    this package's: a reference policy on the adversary space, the knobs or both.  A policy or a
    knob from outside the package cannot be described with certainty, and the cell then
    compiles its programs in every process.  What compiles another program keys another
    entry."""
    from lantern_jax.io.program_store import describable
    from lantern_jax.scenarios import knobs

    pair = next(p for p in suite.pairs if p.family == "PE")
    ego = get_policy("ego")
    problems = {space: report.make_problem(pair, ego, None, report.StressConfig(space=space))
                for space in report.SPACES}  # fmt: skip
    for space, problem in problems.items():
        for name in ("values_and_grads", "values"):
            assert describable(problem.store_identity(name)), (space, name)
    ids = {problem.store_identity("values") for problem in problems.values()}
    assert len(ids) == len(problems)
    knob_problem = problems["knobs"]
    for field, value in (("temperature", 1.0), ("horizon", knob_problem.horizon + 1),
                         ("objective", "margin"), ("expert_weight", 0.0)):  # fmt: skip
        other = dataclasses.replace(knob_problem, **{field: value})
        assert other.store_identity("values") != knob_problem.store_identity("values"), field
    assert not describable(dataclasses.replace(knob_problem, policy=CRUISE)
                           .store_identity("values"))  # fmt: skip
    speed = knobs.knob("hazard_speed")
    monkeypatch.setitem(knobs.KNOBS, "hazard_speed",
                        dataclasses.replace(speed, set=_user_speed_setter))  # fmt: skip
    assert not describable(knob_problem.store_identity("values"))
    assert describable(problems["adversary"].store_identity("values"))  # reads no knob


def test_a_cells_programs_are_asked_of_the_program_store(suite, monkeypatch):
    """The soft program (with and without its backward pass), the hard program, the pair
    builder and the fragility map's program are each asked for under an identity the store
    keys; none is compiled here (the request stops there)."""
    from lantern_jax.apps.stress import fragility, verify
    from lantern_jax.io.program_store import describable
    from lantern_jax.sim import programs

    class Asked(Exception):
        pass

    asked = []

    def spy(fn, *args, identity=None, **kwargs):
        asked.append(identity)
        raise Asked

    for module in (programs, fragility):  # programs.stored calls programs.executable
        monkeypatch.setattr(module, "executable", spy)
    pair = next(p for p in suite.pairs if p.family == "PE")
    problem = report.make_problem(pair, get_policy("ego"), None,
                                  report.StressConfig(space="adversary"))  # fmt: skip
    points = np.zeros((1, 1, problem.space.dim), np.float32)
    for grad in (True, False):
        with pytest.raises(Asked):
            objective.part_samples(problem, grad=grad)(objective.POLICY, points)
    with pytest.raises(Asked):
        verify.Verifier(problem)(np.zeros((1, problem.space.dim), np.float32))
    with pytest.raises(Asked):
        verify._hard_program(problem)(None, None)
    with pytest.raises(Asked):
        fragility.radii(suite.select(["pe_0001"]), get_policy("ego"), None)
    assert asked[:2] == [problem.store_identity("values_and_grads"),
                         problem.store_identity("values")]  # fmt: skip
    assert [a[0] for a in asked[2:]] == ["stress-pairs", "stress-hard", "fragility"]
    assert all(describable(a) for a in asked)
