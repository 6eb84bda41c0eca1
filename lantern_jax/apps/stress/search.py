"""Gradient search, random search and CMA-ES with honest accounting, interleaved in one process.

Every method runs ``R`` independent restarts at once and verifies candidates with the same
:class:`~lantern_jax.apps.stress.verify.Verifier` (two hard rollouts each: the policy's and the
expert's).  Per restart and iteration:

* **gradient** — the surrogate's gradient at the restart's current iterate ``z``
  (:func:`~lantern_jax.apps.stress.objective.batched_estimator`: one soft rollout with its backward
  pass per part — the policy's and the expert's — or ``M`` of each with randomized smoothing),
  the **iterate itself** verified (not samples around it), then an Adam step;
* **random** — ``M`` candidates drawn uniformly in the space, verified;
* **cmaes** — one CMA-ES generation (the ``cma`` package, in the unconstrained space, from the
  gradient restart's starting point), fitness = the surrogate's expression of the hard
  verification (:func:`lantern_jax.apps.stress.plausibility.hard_objective`);
* **hybrid** (not in the default comparison; name it in ``methods``) — gradient descent started
  from global samples: a cycle of ``draws`` uniform candidates per restart (verified), then
  ``steps`` Adam steps on the surrogate from the restart's best draw by the hard fitness (each
  new iterate verified), then the next cycle from new draws.  It asks whether
  local descent pays once a global sample has found the right region;
* **king** (not in the default comparison) — KING's recipe (:mod:`lantern_jax.apps.stress.king`):
  Adam with KING's step on KING's cost, the policy's plans held, no expert part (one soft
  rollout per step), every iterate verified.

**Accounting.**  Rollouts are counted per restart and by kind (:data:`ROLLOUT_KINDS`: soft with
a backward pass, per part; hard verification, per driver); a restart *finds* a failure the first
time one of its candidates is a verified plausible failure, and its cost to then is every
rollout it had run, all kinds together (a batch is counted whole: it ran whole).  Methods
compile everything before the search (:meth:`Method.compile`, timed apart), then run
**interleaved**: one iteration of each method in turn, each method's clock counting only its own
iterations, so machine load falls on all methods alike.  A method stops when its clock reaches
``budget_s`` or its restarts have run ``budget_rollouts`` rollouts each.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
import optax

from lantern_jax.apps.stress.king import KING_BETAS, KING_LR, king_problem
from lantern_jax.apps.stress.objective import EXPERT, Problem, batched_estimator, parts_of
from lantern_jax.apps.stress.verify import Verdict, Verifier

METHODS = ("gradient", "random", "cmaes")  # the default comparison
ALL_METHODS = (*METHODS, "hybrid", "king")  # every method the stress report can build
ROLLOUT_KINDS = ("soft_policy", "soft_expert", "hard_policy", "hard_expert")
INIT_Z = 0.5  # unconstrained units: spread of the restarts' starting points around 0 (nominal)
CMA_SIGMA0 = 1.0  # unconstrained units: CMA-ES's initial step size
HYBRID_DRAWS = 8  # hybrid: uniform draws per restart that start each descent
HYBRID_STEPS = 8  # hybrid: Adam steps per descent before the next draws
ADAM_B1, ADAM_B2, ADAM_EPS = 0.9, 0.999, 1e-8  # hybrid's per-restart Adam (optax's defaults)


@dataclasses.dataclass
class Trace:
    """What one method did within its budget (per restart where it says so)."""

    method: str
    restarts: int
    seconds: list[float] = dataclasses.field(default_factory=list)  # own clock, per iteration
    rollouts: list[int] = dataclasses.field(default_factory=list)  # per restart, cumulative
    evaluations: list[int] = dataclasses.field(default_factory=list)  # candidates, all restarts
    best_cus: list[float] = dataclasses.field(default_factory=list)  # lowest hard CUS so far
    counts: dict = dataclasses.field(default_factory=lambda: dict.fromkeys(ROLLOUT_KINDS, 0))
    first_seconds: np.ndarray | None = None  # (R,) s to the restart's first failure (NaN none)
    first_rollouts: np.ndarray | None = None  # (R,) its rollouts until then, all kinds
    first_evaluations: np.ndarray | None = None  # (R,) its verified candidates until then
    found: list[dict] = dataclasses.field(default_factory=list)  # the first failure per restart
    failures: list[dict] = dataclasses.field(default_factory=list)  # every verified failure
    lowest: dict | None = None  # the candidate with the lowest hard CUS (any restart)
    verified: int = 0  # candidates verified, all restarts
    policy_failed: int = 0  # of which the policy failed (plausible or not)
    plausible_failed: int = 0  # of which were verified plausible failures
    rejected_expert: int = 0  # policy failures the expert did not drive with margin
    rejected_adversary: int = 0  # ... that it did, whose tracked actors broke rules 2-4
    compile_s: float = 0.0  # s spent compiling before the search (not on the clock)
    nan_gradients: int = 0  # gradient estimates with a non-finite entry (taken as 0 there)

    def __post_init__(self) -> None:
        self.first_seconds = np.full(self.restarts, np.nan)
        self.first_rollouts = np.full(self.restarts, np.nan)
        self.first_evaluations = np.full(self.restarts, np.nan)

    @property
    def rollouts_per_restart(self) -> int:
        """Rollouts each restart has run so far, all kinds."""
        return sum(self.counts.values())

    def record(
        self,
        owner: np.ndarray,
        values: np.ndarray,
        verdict: Verdict,
        elapsed: float,
        iteration_cost: dict[str, int],
        candidates_per_restart: int,
    ) -> None:
        """Fold one iteration's verified candidates (``owner[i]`` = restart of candidate i).

        Args:
            owner: (N,) int, the restart of each candidate.
            values: (N, K) the candidates' values.
            verdict: their verification.
            elapsed: s on this method's clock at the end of the iteration.
            iteration_cost: rollouts per restart of this iteration, by kind.
            candidates_per_restart: candidates each restart verified this iteration.
        """
        for k, n in iteration_cost.items():
            self.counts[k] += n
        spent = self.rollouts_per_restart
        self.verified += len(values)
        policy_failed = verdict.failed if verdict.policy_failed is None else verdict.policy_failed
        self.policy_failed += int(np.sum(policy_failed))
        self.rejected_expert += int(np.sum(policy_failed & ~verdict.expert_ok))
        if verdict.plausible is not None:
            shared = policy_failed & verdict.expert_ok & ~verdict.plausible
            self.rejected_adversary += int(np.sum(shared))
        self.plausible_failed += int(np.sum(verdict.failed))
        evals = len(self.evaluations) and self.evaluations[-1]
        for i in np.argsort(verdict.cus, kind="stable"):
            r = int(owner[i])
            if not verdict.failed[i]:
                continue
            entry = dict(
                restart=r,
                values=values[i].tolist(),
                cus=float(verdict.cus[i]),
                seconds=elapsed,
                rollouts=spent,
                iteration=len(self.seconds),
                gates=list(verdict.failed_gates[i]) if verdict.failed_gates else [],
                t_fail_s=float(verdict.t_fail_s[i]) if verdict.t_fail_s is not None else np.nan,
                margin_m=float(verdict.margin_m[i]) if verdict.margin_m is not None else np.nan,
                expert_dist_m=(
                    float(verdict.expert_dist_m[i]) if verdict.expert_dist_m is not None else np.nan
                ),
                traj=None if verdict.traj is None else np.asarray(verdict.traj[i]),
            )
            self.failures.append(entry)
            if np.isnan(self.first_seconds[r]):
                self.first_seconds[r] = elapsed
                self.first_rollouts[r] = spent
                self.first_evaluations[r] = evals // self.restarts + candidates_per_restart
                self.found.append(entry)
        k = int(np.argmin(verdict.cus))
        if self.lowest is None or verdict.cus[k] < self.lowest["cus"]:
            self.lowest = dict(
                values=values[k].tolist(),
                cus=float(verdict.cus[k]),
                failed=bool(verdict.failed[k]),
                expert_ok=bool(verdict.expert_ok[k]),
            )
        self.seconds.append(elapsed)
        self.rollouts.append(spent)
        self.evaluations.append(evals + len(values))
        self.best_cus.append(self.lowest["cus"])


def initial_points(problem: Problem, restarts: int, seed: int, scale: float = INIT_Z) -> np.ndarray:
    """(R, K) unconstrained starting points shared by the gradient and CMA-ES restarts:
    Gaussian around ``z = 0`` (the box's centre: in an adversary space, the benchmark's own
    scene) with standard deviation ``scale``."""
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, scale, (restarts, problem.space.dim)).astype(np.float32)


class Method:
    """One search method's state; :meth:`step` runs one iteration of every restart."""

    name = ""

    def __init__(self, problem: Problem, verifier: Verifier, restarts: int, seed: int):
        self.problem = problem
        self.verifier = verifier
        self.restarts = restarts
        self.seed = seed
        self.trace = Trace(self.name, restarts)
        self.clock = 0.0

    def compile(self) -> None:
        """Compile (and warm) everything :meth:`step` runs; not on the clock."""

    def iterate(self) -> None:
        """One iteration (subclasses)."""
        raise NotImplementedError

    def step(self) -> None:
        """One timed iteration on this method's own clock."""
        self._t0 = time.perf_counter()
        self.iterate()
        self.clock = self.elapsed()

    def elapsed(self) -> float:
        """Seconds on the clock including the iteration running now."""
        return self.clock + (time.perf_counter() - self._t0)

    def done(self, budget_s: float, budget_rollouts: float) -> bool:
        """Whether the budget is spent."""
        return self.clock >= budget_s or self.trace.rollouts_per_restart >= budget_rollouts

    def _gradient(self, est: Callable, z: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """(R, K) the estimate ``est(z, eps).blend``, a non-finite entry counted in the trace
        and taken as 0."""
        g = np.asarray(est(z, eps).blend)
        bad = ~np.isfinite(g)
        self.trace.nan_gradients += int(np.any(bad, axis=1).sum())
        return np.where(bad, 0.0, g)

    def _verify(
        self, values: np.ndarray, owner: np.ndarray, cost: dict[str, int], per_restart: int
    ) -> Verdict:
        verdict = self.verifier(values)
        self.trace.record(owner, values, verdict, self.elapsed(), cost, per_restart)
        return verdict


class GradientSearch(Method):
    """Adam on the smoothed surrogate from every restart, verifying each iterate."""

    name = "gradient"

    def __init__(
        self,
        problem,
        verifier,
        restarts,
        seed,
        lr: float,
        sigma: float,
        samples: int,
        init_z: float = INIT_Z,
    ):
        super().__init__(problem, verifier, restarts, seed)

        self.sigma = float(sigma)
        self.samples = int(samples) if sigma > 0 else 1
        self.est = batched_estimator(problem, self.sigma)
        self.rng = np.random.default_rng(seed + 1)
        self.z = initial_points(problem, restarts, seed, init_z)
        self.opt = self._optimizer(lr)
        self.opt_state = self.opt.init(self.z)
        self.owner = np.arange(restarts)
        parts = parts_of(problem)
        self.cost = dict(
            soft_policy=self.samples,
            soft_expert=self.samples if EXPERT in parts else 0,
            hard_policy=1,
            hard_expert=1,
        )

    @staticmethod
    def _optimizer(lr: float) -> optax.GradientTransformation:
        return optax.adam(lr)

    def _eps(self) -> np.ndarray:
        shape = (self.restarts, self.samples, self.problem.space.dim)
        return self.rng.normal(0.0, 1.0, shape).astype(np.float32)

    def compile(self) -> None:
        """Compile the estimator (both parts)."""
        np.asarray(self.est(self.z, self._eps()).blend)

    def iterate(self) -> None:
        """Gradient at the iterates, their verification, an Adam step."""

        g = self._gradient(self.est, self.z, self._eps())
        values = np.asarray(self.problem.space.values(self.z))
        self._verify(values, self.owner, self.cost, 1)
        updates, self.opt_state = self.opt.update(g, self.opt_state, self.z)
        self.z = np.asarray(optax.apply_updates(self.z, updates), np.float32)


class KingSearch(GradientSearch):
    """KING's recipe (:mod:`lantern_jax.apps.stress.king`): Adam with KING's step and betas on
    KING's cost (:func:`~lantern_jax.apps.stress.king.king_problem`: the policy's plans held,
    no expert part) from every restart, each iterate verified like every other method's.

    KING stops a route's descent at its first collision; here a restart keeps descending after
    its first verified failure, as every gradient restart does (the restarts run as one batch
    whatever each has found), so the measures compared -- the restarts that find a failure and
    the rollouts to the first -- are KING's, and the counts after it (distinct failures, the
    share of iterates the policy passes) are comparable with the gradient method's."""

    name = "king"

    def __init__(self, problem, verifier, restarts, seed, lr: float = KING_LR,
                 init_z: float = INIT_Z):  # fmt: skip
        super().__init__(king_problem(problem), verifier, restarts, seed, lr, 0.0, 1, init_z)

    @staticmethod
    def _optimizer(lr: float) -> optax.GradientTransformation:
        return optax.adam(lr, b1=KING_BETAS[0], b2=KING_BETAS[1])


class RandomSearch(Method):
    """Uniform draws in the space, ``samples`` per restart and iteration."""

    name = "random"

    def __init__(self, problem, verifier, restarts, seed, samples: int):
        super().__init__(problem, verifier, restarts, seed)
        self.samples = int(samples)
        self.rng = np.random.default_rng(seed + 2)
        self.owner = np.repeat(np.arange(restarts), self.samples)
        self.cost = dict(
            soft_policy=0, soft_expert=0, hard_policy=self.samples, hard_expert=self.samples
        )

    def iterate(self) -> None:
        """Draw and verify."""
        values = self.problem.space.uniform(self.rng, self.restarts * self.samples)
        self._verify(values, self.owner, self.cost, self.samples)


class CMAESSearch(Method):
    """One CMA-ES per restart on the unconstrained vector."""

    name = "cmaes"

    def __init__(self, problem, verifier, restarts, seed, popsize: int, init_z: float = INIT_Z):
        super().__init__(problem, verifier, restarts, seed)
        # deferred: cma only for the CMA-ES method
        import cma

        starts = initial_points(problem, restarts, seed, init_z)
        opts = dict(verbose=-9, CMA_diagonal=False)
        if popsize:
            opts["popsize"] = int(popsize)
        self.strategies = [
            cma.CMAEvolutionStrategy(
                starts[r].tolist(), CMA_SIGMA0, dict(opts, seed=seed + 100 + r)
            )
            for r in range(restarts)
        ]
        self.popsize = int(self.strategies[0].popsize)
        self.owner = np.repeat(np.arange(restarts), self.popsize)
        self.cost = dict(
            soft_policy=0, soft_expert=0, hard_policy=self.popsize, hard_expert=self.popsize
        )

    def iterate(self) -> None:
        """Ask, verify, tell."""
        # tell() must get the very arrays ask() returned: CMA-ES recognises its own injected
        # samples (selective mirrors, mean-shift samples) by their exact float64 values, and a
        # rounded copy would be updated as an ordinary sample ("orphanated injected solution")
        asked = [es.ask() for es in self.strategies]  # R x P arrays (K,) float64
        z = np.concatenate([np.asarray(a, np.float32) for a in asked])  # (R*P, K)
        values = np.asarray(self.problem.space.values(z))
        verdict = self._verify(values, self.owner, self.cost, self.popsize)
        fitness = verdict.fitness.reshape(self.restarts, self.popsize)
        for r, es in enumerate(self.strategies):
            es.tell(asked[r], fitness[r].tolist())


class HybridSearch(Method):
    """Cycles of global draws and local descent, every restart in step (see the module
    docstring): ``draws`` uniform candidates per restart, then ``steps`` Adam steps from each
    restart's best draw (lowest :attr:`~lantern_jax.apps.stress.verify.Verdict.fitness`), every
    iterate verified.  Adam's moments and step count restart with each descent, so each
    descent is an ordinary Adam run from its draw (kept per restart in NumPy: optax's state
    shares one step count across the batch)."""

    name = "hybrid"

    def __init__(
        self,
        problem,
        verifier,
        restarts,
        seed,
        lr: float,
        draws: int = HYBRID_DRAWS,
        steps: int = HYBRID_STEPS,
    ):
        super().__init__(problem, verifier, restarts, seed)
        if draws < 1 or steps < 1:
            raise ValueError(f"hybrid: draws and steps must be >= 1, got {draws} and {steps}")
        self.lr, self.draws, self.steps = float(lr), int(draws), int(steps)
        self.est = batched_estimator(problem, 0.0)
        self.rng = np.random.default_rng(seed + 3)
        dim = problem.space.dim
        self.z = np.zeros((restarts, dim), np.float32)
        self.m = np.zeros_like(self.z)
        self.v = np.zeros_like(self.z)
        self.phase = 0  # 0: draw; 1..steps: the descent's step number
        self.owner = np.arange(restarts)
        two = EXPERT in parts_of(problem)
        self.draw_cost = dict(
            soft_policy=0, soft_expert=0, hard_policy=self.draws, hard_expert=self.draws
        )
        self.step_cost = dict(soft_policy=1, soft_expert=int(two), hard_policy=1, hard_expert=1)

    def compile(self) -> None:
        """Compile the estimator (both parts)."""
        np.asarray(self.est(self.z, self._no_eps()).blend)

    def _no_eps(self) -> np.ndarray:
        """(R, 1, K) zeros: the pathwise estimate at the iterates (no smoothing)."""
        return np.zeros((self.restarts, 1, self.z.shape[1]), np.float32)

    def iterate(self) -> None:
        """The cycle's next iteration: the draws, or one verified Adam step."""
        if self.phase == 0:
            values = self.problem.space.uniform(self.rng, self.restarts * self.draws)
            owner = np.repeat(self.owner, self.draws)
            verdict = self._verify(values, owner, self.draw_cost, self.draws)
            best = np.argmin(verdict.fitness.reshape(self.restarts, self.draws), axis=1)
            picked = values.reshape(self.restarts, self.draws, -1)[self.owner, best]
            self.z = np.asarray(self.problem.space.unconstrained(picked), np.float32)
            self.m[:] = 0.0
            self.v[:] = 0.0
            self.phase = 1
            return
        g = self._gradient(self.est, self.z, self._no_eps())
        t = self.phase
        self.m = ADAM_B1 * self.m + (1 - ADAM_B1) * g
        self.v = ADAM_B2 * self.v + (1 - ADAM_B2) * g * g
        m_hat, v_hat = self.m / (1 - ADAM_B1**t), self.v / (1 - ADAM_B2**t)
        self.z = (self.z - self.lr * m_hat / (np.sqrt(v_hat) + ADAM_EPS)).astype(np.float32)
        # the step's new iterate is verified (the draw it started from already was)
        values = np.asarray(self.problem.space.values(self.z))
        self._verify(values, self.owner, self.step_cost, 1)
        self.phase = 0 if t >= self.steps else t + 1


def run_interleaved(
    methods: list[Method],
    budget_s: float,
    budget_rollouts: float,
    progress: Callable[[str], None] | None = None,
) -> list[Trace]:
    """Run ``methods`` one iteration each in turn until every one has spent its budget.

    Returns:
        Their traces, in the order given.
    """
    active = list(methods)
    while active:
        for m in list(active):
            if m.done(budget_s, budget_rollouts):
                active.remove(m)
                if progress:
                    t = m.trace
                    progress(
                        f"{m.name}: {len(t.seconds)} iterations, {t.rollouts_per_restart} "
                        f"rollouts per restart, {m.clock:.1f} s, "
                        f"{int(np.sum(~np.isnan(t.first_seconds)))}/{t.restarts} restarts "
                        "found a failure"
                    )
                continue
            m.step()
    return [m.trace for m in methods]


# -- the knob-space interface of earlier versions (one method at a time, its own budget) -----
def gradient_search(
    problem: Problem,
    verifier: Verifier,
    budget_s: float,
    restarts: int,
    samples: int,
    sigma: float,
    lr: float,
    seed: int,
) -> Trace:
    """Adam on the smoothed surrogate from every restart (see the module docstring)."""
    m = GradientSearch(problem, verifier, restarts, seed, lr, sigma, samples)
    m.compile()
    return run_interleaved([m], budget_s, np.inf)[0]


def random_search(
    problem: Problem, verifier: Verifier, budget_s: float, restarts: int, samples: int, seed: int
) -> Trace:
    """Uniform samples inside the ranges, ``samples`` per restart and iteration."""
    return run_interleaved(
        [RandomSearch(problem, verifier, restarts, seed, samples)], budget_s, np.inf
    )[0]


def cmaes_search(
    problem: Problem, verifier: Verifier, budget_s: float, restarts: int, samples: int, seed: int
) -> Trace:
    """One CMA-ES per restart (population ``samples``) on the unconstrained vector."""
    return run_interleaved(
        [CMAESSearch(problem, verifier, restarts, seed, samples)], budget_s, np.inf
    )[0]
