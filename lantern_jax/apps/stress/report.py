"""Running a stress test end to end and writing what it found.

:func:`stress_test` builds the :class:`~lantern_jax.apps.stress.objective.Problem` of one suite pair
and policy (its search space from the config: the family's knobs, adversarial tracks, or both),
compiles every program first (the ``compiling`` stage, timed apart), runs the methods
interleaved at equal budget and returns their traces; :func:`comparison_table` turns the traces
into the comparison (one row per method, KING's measures: share of restarts that found a
verified failure within the budget, with its bootstrap interval over the restarts, rollouts and
seconds to the first failure — the median over every restart, a restart without one counting as
beyond the budget, and the mean of the fastest half as KING's t@50 —, distinct failures, the
share of verified candidates the policy passed, the lowest hard CUS found, and the rollouts each
restart ran by kind); :func:`write_results` writes ``comparison.csv``, ``found.csv``,
``found_suite.json`` (each restart's first failure as an ordinary suite pair), the failure
catalogue (``catalogue.csv``, ``catalogue_suite.json``, ``catalogue.png``:
:mod:`lantern_jax.apps.stress.catalogue`) and the convergence plot
(:func:`lantern_jax.viz.stress.convergence_plot`). :func:`gradient_quality` measures how well
each gradient estimate agrees with central finite differences of the same surrogate.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import io
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from lantern_jax.apps.stress import catalogue, search
from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.apps.stress.objective import (
    WATCHES,
    Problem,
    batched_estimator,
    pad_rows,
    part_samples,
    parts_of,
    watched_slots,
)
from lantern_jax.apps.stress.space import Space, adversary_space, product_space, search_space
from lantern_jax.apps.stress.verify import Verifier
from lantern_jax.core.constants import CONDITIONS, WARNING_CONDITION
from lantern_jax.core.times import ticks_covering
from lantern_jax.io.files import StagedFolder, atomic_write
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.knobs import get_knobs
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, Suite, suite_hash
from lantern_jax.scoring.uncertainty import SEED, sample_interval

INTERACTION_TAIL_S = 10.0  # s of soft rollout after the ego would reach the conflict point
HORIZON_QUANTUM_S = 5.0  # s, soft horizons are rounded up to this (fewer distinct programs)
SPACES = ("knobs", "adversary", "both")

#: Per-space defaults of the settings left None in :class:`StressConfig`: a few knobs are
#: searched with smoothing (the closed loop is discontinuous in them) and many perturbations;
#: tracks with the plain pathwise gradient (agreeing with finite differences, cosines in the
#: README) and one uniform draw per restart and iteration.
SPACE_DEFAULTS = {
    "knobs": dict(samples=8, sigma=0.3, lr=0.3, init_z=1.0),
    "adversary": dict(samples=1, sigma=0.0, lr=0.2, init_z=search.INIT_Z),
    "both": dict(samples=1, sigma=0.0, lr=0.2, init_z=search.INIT_Z),
}


@dataclasses.dataclass(frozen=True)
class StressConfig:
    """Settings of a stress test (defaults are the command line's; None = the space's)."""

    budget_s: float = 60.0  # wall-clock seconds per method, compilation excluded
    budget_rollouts: float = math.inf  # rollouts per restart and method, all kinds
    restarts: int = 8  # R
    samples: int | None = None  # M: draws per random iteration, perturbations per gradient
    #                             step (with sigma > 0), per restart
    popsize: int = 0  # CMA-ES population per restart (0: cma's default, 4 + 3 ln K)
    sigma: float | None = None  # smoothing in the unconstrained space (0 = pathwise)
    lr: float | None = None  # Adam step size in the unconstrained space
    temperature: float = 0.1  # soft-score temperature of the surrogate
    objective: str = "plausible"
    condition: str = WARNING_CONDITION  # one of CONDITIONS
    seed: int = 0
    methods: tuple[str, ...] = search.METHODS  # of search.ALL_METHODS
    hybrid_draws: int = search.HYBRID_DRAWS  # hybrid: uniform draws per restart per descent
    hybrid_steps: int = search.HYBRID_STEPS  # hybrid: Adam steps per descent
    space: str = "knobs"  # knobs | adversary | both
    actors: tuple[str, ...] = ("hazard",)  # adversary: groups of actors with tracks
    knots: int = 16  # adversary: knots per track
    knot_s: float = 0.5  # adversary: s per knot
    background: int = 1  # adversary: background vehicles that "background" names
    horizon_s: float | None = None  # s of soft rollout (None: from the pair, rounded up)
    expert_weight: float = rules.EXPERT_WEIGHT  # 0: no expert part in the surrogate
    init_z: float | None = None  # spread of the gradient and CMA-ES starting points
    watch: str = "hazard"  # the actors the surrogate's margin and the verification watch:
    #                        "hazard" (and the tracked ones) or "all" (objective.WATCHES)
    actor_temperature: float | None = None  # m, the soft minimum over the watched actors
    #                        (None: ``temperature``; objective.soft_margin)

    def resolved(self) -> StressConfig:
        """The config with every None replaced by its space's default."""
        if self.space not in SPACES:
            raise ValueError(f"space: {self.space!r} not one of {', '.join(SPACES)}")
        d = SPACE_DEFAULTS[self.space]
        return dataclasses.replace(
            self,
            **{k: d[k] for k in ("samples", "sigma", "lr", "init_z") if getattr(self, k) is None},
        )


def make_space(
    pair: PairSpec,
    cfg: StressConfig,
    scenario_a: Any,
    suite: Suite | None = None,
    knobs: tuple[str, ...] | None = None,
    ranges: dict | None = None,
) -> Space:
    """The search space the config names, on the pair's built Route A."""
    if cfg.space == "knobs":
        return search_space(pair.family, knobs, ranges, suite)
    adv = adversary_space(
        scenario_a, pair.family, cfg.actors, cfg.knots, cfg.knot_s, cfg.background
    )
    if cfg.space == "adversary":
        return adv
    return product_space(search_space(pair.family, knobs, ranges, suite), adv)


def soft_horizon(scenario_a: Any, horizon_s: float | None) -> int:
    """Ticks of the soft rollouts: until the ego, at its reference speed, is
    :data:`INTERACTION_TAIL_S` past the conflict point (rounded up to
    :data:`HORIZON_QUANTUM_S`, so families share programs), never beyond the timeout."""
    cfg = scenario_a.config
    if horizon_s is None:
        reach = float(cfg.s_conflict) / float(cfg.v_ref) + INTERACTION_TAIL_S
        horizon_s = math.ceil(reach / HORIZON_QUANTUM_S) * HORIZON_QUANTUM_S
    return ticks_covering(min(horizon_s, float(cfg.timeout_s)))


def make_problem(
    pair: PairSpec,
    policy: Policy,
    space: Space | None,
    cfg: StressConfig,
    suite: Suite | None = None,
    knobs: tuple[str, ...] | None = None,
    ranges: dict | None = None,
) -> Problem:
    """The problem of one pair: Route A under the condition, the space (built from the config
    when None), the soft horizon, the surrogate and the expert that guards plausibility."""
    if cfg.condition not in CONDITIONS:
        raise ValueError(f"condition: {cfg.condition!r} not one of {', '.join(CONDITIONS)}")
    a, b, _ = build_pair(pair.params)
    warned = jnp.asarray(cfg.condition == WARNING_CONDITION)
    a = a.replace(config=a.config.replace(warning_enabled=warned))
    space = make_space(pair, cfg, a, suite, knobs, ranges) if space is None else space
    expert = get_policy("expert")
    key = jax.random.PRNGKey(0)  # reference policies ignore it; checkpoints carry their weights
    return Problem(
        space,
        a,
        b,
        policy,
        policy.init(key),
        soft_horizon(a, cfg.horizon_s),
        cfg.temperature,
        cfg.objective,
        expert,
        expert.init(key),
        watched=watched_slots(a, space, cfg.watch),
        expert_weight=cfg.expert_weight,
        actor_temperature=cfg.actor_temperature,
    )


def _check(cfg: StressConfig) -> None:
    if not cfg.budget_s > 0 or not cfg.budget_rollouts > 0:
        raise ValueError(
            f"budget_s: must be > 0, got {cfg.budget_s}"
            if not cfg.budget_s > 0
            else f"budget_rollouts: must be > 0, got {cfg.budget_rollouts}"
        )
    if cfg.watch not in WATCHES:
        raise ValueError(f"watch: {cfg.watch!r} not one of {', '.join(WATCHES)}")
    bad = [m for m in cfg.methods if m not in search.ALL_METHODS]
    if bad:
        raise ValueError(f"methods: {bad} not among {', '.join(search.ALL_METHODS)}")


def make_methods(problem: Problem, verifier: Verifier, cfg: StressConfig) -> list[search.Method]:
    """The configured methods, with one seed (same restarts' starting points)."""
    out: list[search.Method] = []
    for m in cfg.methods:
        if m == "gradient":
            out.append(
                search.GradientSearch(
                    problem,
                    verifier,
                    cfg.restarts,
                    cfg.seed,
                    cfg.lr,
                    cfg.sigma,
                    cfg.samples,
                    cfg.init_z,
                )
            )
        elif m == "random":
            out.append(search.RandomSearch(problem, verifier, cfg.restarts, cfg.seed, cfg.samples))
        elif m == "hybrid":
            out.append(
                search.HybridSearch(
                    problem,
                    verifier,
                    cfg.restarts,
                    cfg.seed,
                    cfg.lr,
                    cfg.hybrid_draws,
                    cfg.hybrid_steps,
                )
            )
        elif m == "king":
            out.append(search.KingSearch(problem, verifier, cfg.restarts, cfg.seed,
                                         init_z=cfg.init_z))  # fmt: skip
        else:
            popsize = cfg.popsize or (cfg.samples if cfg.space == "knobs" else 0)
            out.append(
                search.CMAESSearch(problem, verifier, cfg.restarts, cfg.seed, popsize, cfg.init_z)
            )
    return out


def _compile_beside(verify_nominal: Callable[[], Any], compile_methods: Callable[[], Any]) -> Any:
    """Run the nominal scene's verification (which compiles the hard program) on a second
    thread while this one compiles the methods' soft program; returns the verification's
    verdict.  The two programs share nothing, and tracing the soft program is Python on one
    core while XLA compiles the hard one beside it (a cell's compile 40 -> 33 s on a 2-core
    CPU, docs/performance.md).  The second thread is not waited for when this one is
    interrupted: the command line ends the process at once, and the API's caller gets the
    interrupt without waiting for the compile."""
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="stress-verify")
    try:
        pending = pool.submit(verify_nominal)
        compile_methods()
        return pending.result()
    finally:
        pool.shutdown(wait=False)


def stress_test(
    pair: PairSpec,
    policy: Policy | str,
    cfg: StressConfig,
    suite: Suite | None = None,
    knobs: tuple[str, ...] | None = None,
    ranges: dict | None = None,
    progress: bool = True,
    extra: Callable[[Problem, Verifier], list[search.Method]] | None = None,
) -> tuple[Problem, list[search.Trace]]:
    """Run the configured methods on one pair at equal budget, interleaved.

    Prints (unless ``progress`` is False) a ``compiling`` line with the compilation time and
    the nominal scene's verdict, then a line per method as it ends.  ``extra`` gives further
    methods built on the same problem and verifier (a benchmark's variants of a method); they
    run after the configured ones, interleaved with them.

    Raises:
        ValueError: for a non-positive budget, an unknown method or space, or a bad search
            space (see :mod:`lantern_jax.apps.stress.space`).
    """
    _check(cfg)
    cfg = cfg.resolved()
    pol = get_policy(policy) if isinstance(policy, str) else policy
    problem = make_problem(pair, pol, None, cfg, suite, knobs, ranges)
    verifier = Verifier(problem, batch=cfg.restarts)
    methods = make_methods(problem, verifier, cfg) + (extra(problem, verifier) if extra else [])
    say = (
        (lambda msg: print(f"[stress] {pair.pair_id} {pol.name}: {msg}", flush=True))
        if (progress)
        else None
    )
    if say:
        say(
            f"compiling ({problem.space.dim}-dimensional {cfg.space} space, "
            f"{len(problem.watched)} watched actors, soft horizon {problem.horizon} ticks)"
        )
    t0 = time.perf_counter()
    nominal = _compile_beside(
        lambda: verifier(np.repeat(nominal_values(problem)[None], cfg.restarts, axis=0)),
        lambda: [m.compile() for m in methods],
    )
    compile_s = time.perf_counter() - t0
    if say:
        say(
            f"compiled in {compile_s:.1f} s; nominal scene: CUS {nominal.cus[0]:.1f}, "
            f"policy {'fails' if nominal.policy_failed[0] else 'passes'}, expert "
            f"{'passes with margin' if nominal.expert_ok[0] else 'WITHOUT margin'}; searching "
            f"({cfg.budget_s:g} s, {cfg.budget_rollouts:g} rollouts per restart)"
        )
    traces = search.run_interleaved(methods, cfg.budget_s, cfg.budget_rollouts, say)
    for t in traces:
        t.compile_s = compile_s
    problem.info.update(
        nominal_cus=float(nominal.cus[0]),
        nominal_policy_failed=bool(nominal.policy_failed[0]),
        nominal_expert_ok=bool(nominal.expert_ok[0]),
        compile_s=compile_s,
    )
    return problem, traces


def nominal_values(problem: Problem) -> np.ndarray:
    """(K,) the values of the pair's own scene: its knobs (clipped into the box) and zero
    actions."""
    parts = getattr(problem.space, "parts", None) or (problem.space,)
    out = []
    for p in parts:
        if p.tracked:
            out.append(np.zeros(p.dim, np.float32))
        else:
            now = get_knobs(problem.scenario_a, list(p.names))
            out.append(np.clip([float(now[n]) for n in p.names], p.lo, p.hi))
    return np.concatenate(out).astype(np.float32)


def _censored(x: np.ndarray) -> np.ndarray:
    """NaN (not found) as +inf, for medians over every restart."""
    return np.where(np.isnan(x), np.inf, x)


def _median(x: np.ndarray) -> float:
    """Median over every restart, a restart without a failure counting as beyond the budget
    (NaN when fewer than half found one)."""
    m = float(np.median(_censored(x)))
    return m if np.isfinite(m) else float("nan")


def _fastest_half_mean(x: np.ndarray, restarts: int) -> float:
    """KING's t@50: mean of the fastest half of the restarts (NaN when fewer than half found)."""
    done = np.sort(x[~np.isnan(x)])
    half = int(np.ceil(restarts / 2))
    return float(np.mean(done[:half])) if len(done) >= half else float("nan")


def found_within(t: search.Trace, seconds: float = math.inf, rollouts: float = math.inf) -> float:
    """Share of the restarts that found a failure within ``seconds`` and ``rollouts``."""
    ok = (_censored(t.first_seconds) <= seconds) & (_censored(t.first_rollouts) <= rollouts)
    return float(np.mean(ok))


def comparison_table(
    traces: list[search.Trace], problem: Problem | None = None, seed: int = SEED
) -> pd.DataFrame:
    """One row per method (see the module docstring); the share of restarts that found a
    failure has its bootstrap interval over the restarts (``failure_rate_lo``, ``_hi``; the
    restarts are the sample, ``restarts`` their number); ``distinct_failures`` needs the problem
    (the near-duplicate rule compares the adversaries' trajectories), NaN without it."""
    rows = []
    for t in traces:
        found = ~np.isnan(t.first_seconds)
        lo, hi, _ = sample_interval(found.astype(np.float64), seed=seed)
        distinct = len(catalogue.distinct(t.failures, problem)) if problem is not None else np.nan
        rows.append(
            dict(
                method=t.method,
                restarts=t.restarts,
                failure_rate=float(np.mean(found)),
                failure_rate_lo=float(lo),
                failure_rate_hi=float(hi),
                median_rollouts_to_first=_median(t.first_rollouts),
                t50_rollouts=_fastest_half_mean(t.first_rollouts, t.restarts),
                median_s_to_first=_median(t.first_seconds),
                t50_s=_fastest_half_mean(t.first_seconds, t.restarts),
                median_evals_to_first=_median(t.first_evaluations),
                distinct_failures=distinct,
                failures=len(t.failures),
                verified=t.verified,
                policy_pass_share=1.0 - t.policy_failed / t.verified if t.verified else np.nan,
                plausible_failure_share=t.plausible_failed / t.verified if t.verified else np.nan,
                rejected_expert=t.rejected_expert,
                rejected_adversary=t.rejected_adversary,
                lowest_cus=t.lowest["cus"] if t.lowest else np.nan,
                rollouts=t.rollouts_per_restart,
                **{f"rollouts_{k}": v for k, v in t.counts.items()},
                iterations=len(t.seconds),
                search_s=t.seconds[-1] if t.seconds else 0.0,
                compile_s=t.compile_s,
                evaluations=t.evaluations[-1] if t.evaluations else 0,
            )
        )
    return pd.DataFrame(rows)


def found_suite(pair: PairSpec, space: Space | None, traces: list[search.Trace]) -> dict:
    """Each restart's first failure as a suite manifest: the pair's parameters plus the
    candidate's ``knobs`` or ``adversary`` field."""
    pairs, specs = [], []
    for t in traces:
        for f in t.found:
            params = dict(pair.params, **space.params(np.asarray(f["values"])))
            pid = f"{pair.pair_id}_{t.method}_r{f['restart']:02d}"
            h = content_hash(params)
            pairs.append(
                dict(pair_id=pid, family=pair.family, weather=pair.weather, sha256=h, params=params)
            )
            specs.append(PairSpec(pid, pair.family, pair.weather, params, h))
    suite_id = f"stress-{pair.pair_id}"
    return dict(
        suite_id=suite_id,
        format_version=1,
        seed=0,
        pairs=pairs,
        suite_sha256=suite_hash(specs),
        generation_report={},
    )


#: The comparison's columns a summary shows (the command line, the notebook).
SUMMARY_COLUMNS = ("method", "failure_rate", "failure_rate_lo", "failure_rate_hi",
                   "median_rollouts_to_first", "median_s_to_first",
                   "distinct_failures", "policy_pass_share", "lowest_cus", "rollouts",
                   "rollouts_soft_policy", "rollouts_soft_expert", "rollouts_hard_policy",
                   "rollouts_hard_expert", "search_s")  # fmt: skip

MAX_VALUE_COLUMNS = 8  # a space with more parameters keeps them out of found.csv (see the suite)


def found_table(space: Space | None, traces: list[search.Trace]) -> pd.DataFrame:
    """Every restart's first failure with its hard CUS, cost and (for small spaces) values."""
    named = space is not None and space.dim <= MAX_VALUE_COLUMNS
    rows = [
        dict(method=t.method, restart=f["restart"], hard_cus=f["cus"], seconds=f["seconds"],
             rollouts=f["rollouts"], gates=" + ".join(f["gates"]), t_fail_s=f["t_fail_s"],
             **(space.as_dict(np.asarray(f["values"])) if named else {}))
        for t in traces for f in t.found
    ]  # fmt: skip
    cols = ["method", "restart", "hard_cus", "seconds", "rollouts", "gates", "t_fail_s",
            *(space.names if named else ())]  # fmt: skip
    return pd.DataFrame(rows, columns=cols)


#: Every file :func:`write_results` writes (the figures only when given).
RESULT_FILES = (
    "comparison.csv",
    "found.csv",
    "catalogue.csv",
    "catalogue_suite.json",
    "convergence.png",
    "catalogue.png",
    "found_suite.json",
)
CATALOGUE_COLUMNS = (
    "pair_id",
    "method",
    "restart",
    "hard_cus",
    "gates",
    "t_fail_s",
    "rollouts",
    "seconds",
    "sha256",
    "description",
)


def write_results(out: str | Path, pair: PairSpec, space: Space | None,
                  traces: list[search.Trace], figure: Any = None,
                  problem: Problem | None = None, policy_name: str | None = None,
                  catalogue_figure: Callable[[list[dict]], Any] | None = None,
                  ) -> dict[str, Path]:  # fmt: skip
    """Write the result files into ``out`` as one whole set (:class:`lantern_jax.io.files.
    StagedFolder`: a kill leaves the old set or the new one): ``comparison.csv``,
    ``found.csv``, ``found_suite.json``, the catalogue (``catalogue.csv``,
    ``catalogue_suite.json``, ``catalogue.png``; empty without the ``problem``, the figure drawn
    by ``catalogue_figure`` — entries -> figure — when given) and, given a matplotlib
    ``figure``, ``convergence.png``.

    Returns:
        File name -> path, for every file written.
    """
    # deferred: matplotlib only when a figure is drawn
    from matplotlib.figure import Figure

    written = []
    name = policy_name or (problem.policy.name if problem is not None else "policy")
    entries = ([] if problem is None
               else catalogue.catalogue_entries(problem, pair, traces, name))  # fmt: skip
    with StagedFolder(out, RESULT_FILES) as stage:
        def put(file: str, data: str | bytes) -> None:
            atomic_write(stage.path / file, data)
            written.append(file)

        def png(file: str, fig: Any) -> None:
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=110)
            put(file, buf.getvalue())

        put("comparison.csv", comparison_table(traces, problem).to_csv(index=False))
        put("found.csv", found_table(space, traces).to_csv(index=False))
        table = pd.DataFrame(entries, columns=[*CATALOGUE_COLUMNS, "params", "values"])
        put("catalogue.csv", table[list(CATALOGUE_COLUMNS)].to_csv(index=False))
        suite = catalogue.catalogue_suite(pair, entries, name)
        put("catalogue_suite.json", json.dumps(suite, indent=1) + "\n")
        if catalogue_figure is not None and entries:
            png("catalogue.png", catalogue_figure(entries))
        else:
            empty = Figure(figsize=(4, 1))
            empty.text(0.5, 0.5, "no failure in the catalogue", ha="center", va="center")
            png("catalogue.png", empty)
        if figure is not None:
            png("convergence.png", figure)
        manifest = found_suite(pair, space, traces) if space is not None else found_suite(
            pair, None, [])  # fmt: skip
        put("found_suite.json", json.dumps(manifest, indent=1) + "\n")
        stage.commit()
    return {n: Path(out) / n for n in written}


def gradient_quality(
    problem: Problem,
    points: np.ndarray,
    sigma: float,
    samples: int,
    directions: int = 8,
    step: float = 0.05,
    seed: int = 0,
    batch: int = 8,
) -> pd.DataFrame:
    """Cosine similarity between each gradient estimate's directional derivatives along random
    unit directions and central finite differences of the same (smoothed) surrogate along them
    (common random numbers, so the finite difference is of one deterministic function).

    Everything runs through the search's own compiled programs (``batch`` points per call).

    Returns:
        One row per point: ``cos_first``, ``cos_zeroth``, ``cos_blend`` (NaN for zeroth with
        ``sigma == 0``), ``alpha`` (1 when the blend followed the first-order estimate) and
        ``value`` (the surrogate there).
    """
    rng = np.random.default_rng(seed)
    k = problem.space.dim
    m = samples if sigma > 0 else 1
    eps = rng.normal(0.0, 1.0, (m, k)).astype(np.float32)
    est = batched_estimator(problem, sigma)
    samples_fn = part_samples(problem)

    def chunks(z: np.ndarray):
        return pad_rows(z, batch), len(z)

    def smoothed(zs: np.ndarray) -> np.ndarray:
        z, n = chunks(np.asarray(zs, np.float32))
        out = []
        for i in range(0, len(z), batch):
            pts = z[i : i + batch, None, :] + sigma * eps[None, :, :]
            out.append(sum(np.asarray(samples_fn(p, pts)[0]) for p in parts_of(problem)))
        return np.concatenate(out)[:n].mean(axis=1)

    z_all, n = chunks(np.asarray(points, np.float32))
    e_all = [
        est(z_all[i : i + batch], np.broadcast_to(eps, (batch, m, k)))
        for i in range(0, len(z_all), batch)
    ]
    rows = []
    for j, z in enumerate(np.asarray(points, np.float32)):
        e = e_all[j // batch]
        d = rng.normal(0.0, 1.0, (directions, k))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        vals = smoothed(np.concatenate([z + step * d, z - step * d]))
        fd = (vals[:directions] - vals[directions:]) / (2 * step)

        def cos(g, fd=fd, d=d):
            ad = d @ np.asarray(g, np.float64)
            den = np.linalg.norm(ad) * np.linalg.norm(fd)
            return float(ad @ fd / den) if den > 0 else float("nan")

        i = j % batch
        rows.append(
            dict(
                cos_first=cos(e.first[i]),
                cos_zeroth=cos(e.zeroth[i]) if sigma > 0 else np.nan,
                cos_blend=cos(e.blend[i]),
                alpha=float(e.alpha[i]),
                value=float(e.value[i]),
            )
        )
    return pd.DataFrame(rows)
