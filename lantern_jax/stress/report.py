"""Running a stress test end to end and writing what it found.

:func:`stress_test` builds the :class:`~lantern_jax.stress.objective.Problem` of one suite pair
and policy, runs the methods at equal budget and returns their traces; :func:`comparison_table`
turns the traces into the comparison (one row per method, KING's measures: share of restarts
that found a verified failure within the budget, with its bootstrap interval over the
restarts, time and evaluations to the first failure —
median, and the mean of the fastest half as KING's t@50 — and the lowest hard CUS found);
:func:`write_results` writes ``comparison.csv``, ``found.csv`` and ``found_suite.json`` (the
found failures as ordinary suite pairs with knob overrides, so ``lantern-jax evaluate --suite``
runs them with the validation and hashes of any suite); the convergence plot is
:func:`lantern_jax.viz.stress.convergence_plot`.  :func:`gradient_quality`
measures how well each gradient estimate agrees with finite differences of the smoothed
surrogate.
"""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from lantern_jax.constants import CONDITIONS, DT, WARNING_CONDITION
from lantern_jax.files import StagedFolder, atomic_write
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, Suite, suite_hash
from lantern_jax.scoring.uncertainty import SEED, sample_interval
from lantern_jax.stress import search
from lantern_jax.stress.objective import Problem, batched_objective, estimate
from lantern_jax.stress.space import SearchSpace, search_space
from lantern_jax.stress.verify import Verifier

INTERACTION_TAIL_S = 10.0  # s of soft rollout after the ego would reach the conflict point


@dataclasses.dataclass(frozen=True)
class StressConfig:
    """Settings of a stress test (defaults are the command line's)."""

    budget_s: float = 60.0  # wall-clock seconds per method, compilation excluded
    restarts: int = 8  # R
    samples: int = 8  # M: perturbations per gradient step, population per CMA-ES generation
    sigma: float = 0.3  # smoothing in the unconstrained space
    lr: float = 0.3  # Adam step size in the unconstrained space
    temperature: float = 0.1  # soft-score temperature of the surrogate
    objective: str = "clearance"
    condition: str = WARNING_CONDITION  # one of CONDITIONS
    seed: int = 0
    methods: tuple[str, ...] = search.METHODS


def make_problem(pair: PairSpec, policy: Policy, space: SearchSpace, cfg: StressConfig) -> Problem:
    """The problem of one pair: Route A under the condition, the soft horizon, the surrogate."""
    if cfg.condition not in CONDITIONS:
        raise ValueError(f"condition: {cfg.condition!r} not one of {', '.join(CONDITIONS)}")
    a, b, _ = build_pair(pair.params)
    warned = jnp.asarray(cfg.condition == WARNING_CONDITION)
    a = a.replace(config=a.config.replace(warning_enabled=warned))
    reach = float(a.config.s_conflict) / float(a.config.v_ref) + INTERACTION_TAIL_S
    horizon = int(min(np.ceil(reach / DT), np.ceil(float(a.config.timeout_s) / DT)))
    params = policy.init(jax.random.PRNGKey(0))
    return Problem(space, a, b, policy, params, horizon, cfg.temperature, cfg.objective)


def stress_test(
    pair: PairSpec, policy: Policy | str, cfg: StressConfig, suite: Suite | None = None,
    knobs: tuple[str, ...] | None = None, ranges: dict | None = None, progress: bool = True,
) -> tuple[Problem, list[search.Trace]]:  # fmt: skip
    """Run the configured methods on one pair at equal budget.

    Raises:
        ValueError: for a non-positive budget, an unknown method, or a bad search space (see
            :func:`~lantern_jax.stress.space.search_space`).
    """
    if not cfg.budget_s > 0:
        raise ValueError(f"budget_s: must be > 0, got {cfg.budget_s}")
    bad = [m for m in cfg.methods if m not in search.METHODS]
    if bad:
        raise ValueError(f"methods: {bad} not among {', '.join(search.METHODS)}")
    pol = get_policy(policy) if isinstance(policy, str) else policy
    space = search_space(pair.family, knobs, ranges, suite)
    problem = make_problem(pair, pol, space, cfg)
    verifier = Verifier(problem, get_policy("expert"))
    traces = []
    for method in cfg.methods:
        if progress:
            print(f"[stress] {pair.pair_id} {pol.name}: {method}, {cfg.budget_s:g} s budget",
                  flush=True)  # fmt: skip
        if method == "gradient":
            traces.append(
                search.gradient_search(
                    problem,
                    verifier,
                    cfg.budget_s,
                    cfg.restarts,
                    cfg.samples,
                    cfg.sigma,
                    cfg.lr,
                    cfg.seed,
                )
            )
        elif method == "random":
            traces.append(
                search.random_search(
                    problem, verifier, cfg.budget_s, cfg.restarts, cfg.samples, cfg.seed
                )
            )
        else:
            traces.append(search.cmaes_search(problem, verifier, cfg.budget_s, cfg.restarts,
                                              cfg.samples, cfg.seed))  # fmt: skip
    return problem, traces


def _fastest_half_mean(x: np.ndarray, restarts: int) -> float:
    """KING's t@50: mean of the fastest half of the restarts (NaN when fewer than half found)."""
    done = np.sort(x[~np.isnan(x)])
    half = int(np.ceil(restarts / 2))
    return float(np.mean(done[:half])) if len(done) >= half else float("nan")


def comparison_table(traces: list[search.Trace], seed: int = SEED) -> pd.DataFrame:
    """One row per method (see the module docstring); the share of restarts that found a
    failure has its bootstrap interval over the restarts (``failure_rate_lo``, ``_hi``; the
    restarts are the sample, ``restarts`` their number)."""
    rows = []
    for t in traces:
        found = ~np.isnan(t.first_seconds)
        lo, hi, _ = sample_interval(found.astype(np.float64), seed=seed)
        rows.append(dict(
            method=t.method,
            restarts=t.restarts,
            failure_rate=float(np.mean(found)),
            failure_rate_lo=float(lo),
            failure_rate_hi=float(hi),
            median_s_to_first=float(np.nanmedian(t.first_seconds)) if found.any() else np.nan,
            t50_s=_fastest_half_mean(t.first_seconds, t.restarts),
            median_evals_to_first=(float(np.nanmedian(t.first_evaluations)) if found.any()
                                   else np.nan),
            t50_evals=_fastest_half_mean(t.first_evaluations, t.restarts),
            lowest_cus=t.lowest["cus"] if t.lowest else np.nan,
            evaluations=t.evaluations[-1] if t.evaluations else 0,
            iterations=len(t.seconds),
        ))  # fmt: skip
    return pd.DataFrame(rows)


def found_suite(pair: PairSpec, space: SearchSpace, traces: list[search.Trace]) -> dict:
    """The found failures as a suite manifest: the pair's parameters plus knob overrides."""
    pairs, specs = [], []
    for t in traces:
        for f in t.found:
            params = dict(pair.params, knobs=space.as_dict(np.asarray(f["values"])))
            pid = f"{pair.pair_id}_{t.method}_r{f['restart']:02d}"
            h = content_hash(params)
            pairs.append(dict(pair_id=pid, family=pair.family, weather=pair.weather,
                              sha256=h, params=params))  # fmt: skip
            specs.append(PairSpec(pid, pair.family, pair.weather, params, h))
    suite_id = f"stress-{pair.pair_id}"
    return dict(suite_id=suite_id, format_version=1, seed=0, pairs=pairs,
                suite_sha256=suite_hash(specs), generation_report={})  # fmt: skip


def found_table(space: SearchSpace, traces: list[search.Trace]) -> pd.DataFrame:
    """Every found failure (first per restart and method) with its knob values and hard CUS."""
    rows = [
        dict(method=t.method, restart=f["restart"], hard_cus=f["cus"], seconds=f["seconds"],
             evaluations=f["evaluations"], **space.as_dict(np.asarray(f["values"])))
        for t in traces for f in t.found
    ]  # fmt: skip
    cols = ["method", "restart", "hard_cus", "seconds", "evaluations", *space.names]
    return pd.DataFrame(rows, columns=cols)


#: Every file :func:`write_results` writes (the plot only when one is given).
RESULT_FILES = ("comparison.csv", "found.csv", "convergence.png", "found_suite.json")


def write_results(out: str | Path, pair: PairSpec, space: SearchSpace,
                  traces: list[search.Trace], figure: Any = None) -> dict[str, Path]:  # fmt: skip
    """Write ``comparison.csv``, ``found.csv``, ``found_suite.json`` and, given a matplotlib
    ``figure``, ``convergence.png`` into ``out`` as one whole set
    (:class:`lantern_jax.files.StagedFolder`: a kill leaves the old set or the new one).

    Returns:
        File name -> path, for every file written.
    """
    names = [n for n in RESULT_FILES if figure is not None or not n.endswith(".png")]
    with StagedFolder(out, RESULT_FILES) as stage:
        atomic_write(stage.path / "comparison.csv", comparison_table(traces).to_csv(index=False))
        atomic_write(stage.path / "found.csv", found_table(space, traces).to_csv(index=False))
        if figure is not None:
            buf = io.BytesIO()
            figure.savefig(buf, format="png", dpi=110)
            atomic_write(stage.path / "convergence.png", buf.getvalue())
        manifest = found_suite(pair, space, traces)
        atomic_write(stage.path / "found_suite.json", json.dumps(manifest, indent=1) + "\n")
        stage.commit()
    return {n: Path(out) / n for n in names}


def gradient_quality(
    problem: Problem,
    points: np.ndarray,
    sigma: float,
    samples: int,
    directions: int = 4,
    step: float = 0.05,
    seed: int = 0,
) -> pd.DataFrame:
    """Cosine similarity, over random unit directions, between each gradient estimate's
    directional derivative and central finite differences of the same smoothed surrogate
    (common random numbers, so the finite difference is of one deterministic function).

    Returns:
        One row per point: ``cos_first``, ``cos_zeroth``, ``cos_blend`` (NaN for zeroth with
        ``sigma == 0``) and ``alpha`` (1 when the blend followed the first-order estimate).
    """
    rng = np.random.default_rng(seed)
    k = problem.space.dim
    eps = rng.normal(0.0, 1.0, (samples, k)).astype(np.float32)
    f = batched_objective(problem)
    grad = jax.jit(lambda z: estimate(problem, z, jnp.asarray(eps), sigma))

    def smoothed(zs: np.ndarray) -> np.ndarray:
        if sigma == 0.0:
            return np.asarray(f(jnp.asarray(zs, jnp.float32)))
        pts = zs[:, None, :] + sigma * eps[None, :, :]
        vals = np.asarray(f(jnp.asarray(pts.reshape(-1, k), jnp.float32)))
        return vals.reshape(len(zs), samples).mean(axis=1)

    rows = []
    for z in np.asarray(points, np.float32):
        e = grad(jnp.asarray(z))
        d = rng.normal(0.0, 1.0, (directions, k))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        fd = (smoothed(z + step * d) - smoothed(z - step * d)) / (2 * step)

        def cos(g, fd=fd, d=d):
            ad = d @ np.asarray(g, np.float64)
            den = np.linalg.norm(ad) * np.linalg.norm(fd)
            return float(ad @ fd / den) if den > 0 else float("nan")

        rows.append(dict(cos_first=cos(e.first),
                         cos_zeroth=cos(e.zeroth) if sigma > 0 else np.nan,
                         cos_blend=cos(e.blend), alpha=float(e.alpha)))  # fmt: skip
    return pd.DataFrame(rows)
