"""Batched scenario search at equal wall-clock budget: gradient, random search and CMA-ES.

All three methods run ``R`` independent restarts at once, spend the same wall-clock budget
(compilation excluded: every jitted function is compiled before the clock starts) and verify
candidates with the same :class:`~lantern_jax.stress.verify.Verifier`.  Per restart and
iteration:

* **gradient** — estimate the smoothed surrogate's gradient from ``M`` perturbations of the
  current candidate (:func:`~lantern_jax.stress.objective.estimate`, one batched call for all
  restarts), verify those ``M`` perturbed candidates (hard), and take an Adam step on the
  unconstrained vector; ``2 M`` evaluations (``M`` soft rollouts with their backward pass, ``M``
  hard ones);
* **random** — ``M`` candidates drawn uniformly inside the ranges, verified; ``M`` evaluations;
* **cmaes** — one CMA-ES generation of population ``M`` (the ``cma`` package, in the
  unconstrained space, started from the same point as the gradient restart), fitness = hard
  CUS (ties broken by clearance); ``M`` evaluations.

An evaluation is one closed-loop rollout of Route A with the policy under test (soft for the
gradient's perturbations, hard for verification).  A restart *finds* a failure the first time a
verified, plausible failure appears among its candidates; the :class:`Trace` keeps when (seconds,
evaluations), what (knob values, hard CUS) and the best hard CUS over time.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from lantern_jax.stress.objective import Problem, batched_estimator
from lantern_jax.stress.verify import Verdict, Verifier

METHODS = ("gradient", "random", "cmaes")
VERIFY_SPREAD = 0.3  # unconstrained units: spread of the verified candidates around an iterate


@dataclasses.dataclass
class Trace:
    """What one method did within its budget."""

    method: str
    restarts: int
    seconds: list[float] = dataclasses.field(default_factory=list)  # elapsed, per iteration
    evaluations: list[int] = dataclasses.field(default_factory=list)  # cumulative, all restarts
    best_cus: list[float] = dataclasses.field(default_factory=list)  # lowest hard CUS so far
    first_seconds: np.ndarray | None = None  # (R,) s to the restart's first failure (NaN none)
    first_evaluations: np.ndarray | None = None  # (R,) evaluations of that restart until then
    found: list[dict] = dataclasses.field(default_factory=list)  # the first failure per restart
    lowest: dict | None = None  # the candidate with the lowest hard CUS (any restart)

    def __post_init__(self) -> None:
        self.first_seconds = np.full(self.restarts, np.nan)
        self.first_evaluations = np.full(self.restarts, np.nan)

    def record(self, owner: np.ndarray, values: np.ndarray, verdict: Verdict, elapsed: float,
               evals_per_restart: int, evals_total: int) -> None:  # fmt: skip
        """Fold one iteration's verified candidates (``owner[i]`` = restart of candidate i)."""
        done_before = evals_total - evals_per_restart * self.restarts
        for i in np.argsort(verdict.cus, kind="stable"):
            r = int(owner[i])
            if verdict.failed[i] and np.isnan(self.first_seconds[r]):
                self.first_seconds[r] = elapsed
                self.first_evaluations[r] = done_before // self.restarts + evals_per_restart
                self.found.append(dict(restart=r, values=values[i].tolist(),
                                       cus=float(verdict.cus[i]), seconds=elapsed,
                                       evaluations=int(self.first_evaluations[r])))  # fmt: skip
        k = int(np.argmin(verdict.cus))
        if self.lowest is None or verdict.cus[k] < self.lowest["cus"]:
            self.lowest = dict(
                values=values[k].tolist(),
                cus=float(verdict.cus[k]),
                failed=bool(verdict.failed[k]),
                expert_ok=bool(verdict.expert_ok[k]),
            )
        self.seconds.append(elapsed)
        self.evaluations.append(evals_total)
        self.best_cus.append(self.lowest["cus"])


def initial_points(problem: Problem, restarts: int, seed: int) -> np.ndarray:
    """(R, K) unconstrained starting points shared by the gradient and CMA-ES restarts."""
    return np.random.default_rng(seed).normal(0.0, 1.0, (restarts, problem.space.dim))


def gradient_search(problem: Problem, verifier: Verifier, budget_s: float, restarts: int,
                    samples: int, sigma: float, lr: float, seed: int) -> Trace:  # fmt: skip
    """Adam on the smoothed surrogate from every restart (see the module docstring)."""
    import optax

    space = problem.space
    est = batched_estimator(problem, sigma)
    rng = np.random.default_rng(seed + 1)
    z = initial_points(problem, restarts, seed).astype(np.float32)
    opt = optax.adam(lr)
    opt_state = opt.init(z)
    spread = max(sigma, VERIFY_SPREAD)  # where the verified candidates lie around z

    def perturb() -> np.ndarray:
        return rng.normal(0.0, 1.0, (restarts, samples, space.dim)).astype(np.float32)

    eps = perturb()
    est(z, eps)  # compile
    verifier(np.asarray(space.values((z[:, None, :] + spread * eps).reshape(-1, space.dim))))
    trace = Trace("gradient", restarts)
    owner = np.repeat(np.arange(restarts), samples)
    evals, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < budget_s:
        eps = perturb()
        g = np.asarray(est(z, eps).blend)
        candidates = (z[:, None, :] + spread * eps).reshape(-1, space.dim)
        values = np.asarray(space.values(candidates))
        verdict = verifier(values)
        updates, opt_state = opt.update(g, opt_state, z)
        z = np.asarray(optax.apply_updates(z, updates))
        evals += restarts * 2 * samples
        trace.record(owner, values, verdict, time.perf_counter() - t0, 2 * samples, evals)
    return trace


def random_search(problem: Problem, verifier: Verifier, budget_s: float, restarts: int,
                  samples: int, seed: int) -> Trace:  # fmt: skip
    """Uniform samples inside the ranges, ``samples`` per restart and iteration."""
    space = problem.space
    rng = np.random.default_rng(seed + 2)
    owner = np.repeat(np.arange(restarts), samples)

    def draw() -> np.ndarray:
        u = rng.uniform(0.0, 1.0, (restarts * samples, space.dim))
        return (space.lo + (space.hi - space.lo) * u).astype(np.float32)

    verifier(draw())  # compile
    trace = Trace("random", restarts)
    evals, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < budget_s:
        values = draw()
        verdict = verifier(values)
        evals += restarts * samples
        trace.record(owner, values, verdict, time.perf_counter() - t0, samples, evals)
    return trace


def cmaes_search(problem: Problem, verifier: Verifier, budget_s: float, restarts: int,
                 samples: int, seed: int) -> Trace:  # fmt: skip
    """One CMA-ES per restart (population ``samples``) on the unconstrained vector."""
    import cma

    space = problem.space
    starts = initial_points(problem, restarts, seed)
    opts = dict(popsize=samples, verbose=-9, CMA_diagonal=False)
    strategies = [
        cma.CMAEvolutionStrategy(starts[r].tolist(), 1.0, dict(opts, seed=seed + 100 + r))
        for r in range(restarts)
    ]
    owner = np.repeat(np.arange(restarts), samples)
    verifier(np.asarray(space.values(np.asarray(starts, np.float32))).repeat(samples, 0))  # compile
    trace = Trace("cmaes", restarts)
    evals, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < budget_s:
        # tell() must get the very arrays ask() returned: CMA-ES recognises its own injected
        # samples (selective mirrors, mean-shift samples) by their exact float64 values, and a
        # rounded copy would be updated as an ordinary sample ("orphanated injected solution")
        asked = [es.ask() for es in strategies]  # R x M arrays (K,) float64
        z = np.concatenate([np.asarray(a, np.float32) for a in asked])  # (R*M, K)
        values = np.asarray(space.values(z))
        verdict = verifier(values)
        fitness = verdict.fitness.reshape(restarts, samples)
        for r, es in enumerate(strategies):
            es.tell(asked[r], fitness[r].tolist())
        evals += restarts * samples
        trace.record(owner, values, verdict, time.perf_counter() - t0, samples, evals)
    return trace
