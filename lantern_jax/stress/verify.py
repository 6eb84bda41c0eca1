"""Exact verification of stress-test candidates: hard pair CUS, gates, and plausibility.

A candidate counts as a **failure** only if the policy's hard (exact) evaluation of the pair
fails a gate or scores a CUS below the threshold, and it counts only when it is **plausible**:
the privileged expert, which sees every actor, still drives Route A without failing a gate (a
hazard no policy could avoid is not a failure of the policy).  Every search method uses this one
verifier, so their failure counts are comparable.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import ROUTE_A_GATE_NAMES
from lantern_jax.policies.base import Policy
from lantern_jax.scoring.cus import pair_components
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.engine import Program, remember
from lantern_jax.sim.rollout import rollout_batch
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.switch import policy_switch, switch_params
from lantern_jax.stress.objective import Problem

FAIL_BELOW_CUS = 50.0  # CUS points: a pair below this counts as a failure (besides any gate)


@dataclasses.dataclass
class Verdict:
    """Hard verification of N candidates (NumPy arrays, one entry per candidate)."""

    cus: np.ndarray  # (N,) float64, the policy's hard pair CUS, points
    gates_passed: np.ndarray  # (N,) bool, every gate of the pair passed
    clearance_m: np.ndarray  # (N,) float64, hard minimum clearance (NaN unavailable)
    expert_ok: np.ndarray  # (N,) bool, the privileged expert passes every Route A gate
    failed: np.ndarray  # (N,) bool, verified, plausible failure

    @property
    def fitness(self) -> np.ndarray:
        """(N,) what black-box searches minimise: hard CUS, ties broken by clearance."""
        clear = np.where(np.isnan(self.clearance_m), 10.0, np.minimum(self.clearance_m, 10.0))
        return self.cus + 0.01 * clear


MAX_VERIFY_TICKS = 1800  # ticks (90 s) >= the longest route timeout (20 s + 164 m / 3 m/s);
#                          each execution still ends at its own timeout, and the batch exits early


@functools.partial(jax.jit, static_argnames=("program",))
def _metrics(scs, params, settings, *, program: Program) -> Any:
    """Hard metrics of a batch rolled to its end; one compilation per policy program."""
    final = rollout_batch(scs, program.driver, params, MAX_VERIFY_TICKS, settings=settings)
    return finalize(final.telemetry, settings.scoring)


def _hard_metrics(policy: Any, settings: Settings = DEFAULT_SETTINGS) -> Any:
    """``(scenarios, policy_params) -> ExecutionMetrics`` for a policy or a policy switch."""
    program = Program(policy)
    return lambda scs, params: _metrics(scs, params, settings, program=program)


def _pair_builder(problem: Problem) -> Any:
    """``jit((scenario_a, scenario_b, values (N, K)) -> batched pairs)`` per knob set."""
    space = problem.space
    return remember(
        ("pairs", space.names),
        lambda: jax.jit(
            jax.vmap(lambda sa, sb, v: space.apply(sa, sb, v), in_axes=(None, None, 0))
        ),
    )


class Verifier:
    """Batched hard evaluation of candidate knob values for one :class:`Problem`.

    Compiled functions are shared by every problem with the same policy ``act`` and knob names
    (the scenarios and parameters are arguments), so one compilation serves a whole table of
    stress tests with the reference policies; the policy and the expert run as the two members
    of one program (:mod:`lantern_jax.sim.switch`), so the simulator compiles once for both.
    """

    def __init__(self, problem: Problem, expert: Policy, threshold: float = FAIL_BELOW_CUS):
        self.problem = problem
        self.threshold = threshold
        self.expert = expert
        self.expert_params = expert.init(jax.random.PRNGKey(0))
        self._pairs = _pair_builder(problem)
        if problem.policy.program == expert.program:
            self._metrics = _hard_metrics(expert, problem.settings)
            self._policy_params, self._expert_params = problem.policy_params, self.expert_params
        else:
            # The policy and the expert as members of one program: the simulator compiles
            # once for both (lantern_jax.sim.switch).
            switch = policy_switch((problem.policy, expert))
            members = (problem.policy_params, self.expert_params)
            self._metrics = _hard_metrics(switch, problem.settings)
            self._policy_params = switch_params(switch, 0, members)
            self._expert_params = switch_params(switch, 1, members)
        self._nominal_b = None

    def _route_b(self, scs_b: Any, n: int):
        if self.problem.space.shared:
            return self._metrics(scs_b, self._policy_params)
        if self._nominal_b is None:  # Route B does not depend on the knobs: run it once (in the
            # batch shape Route A uses, so the compiled rollout is shared)
            metrics = self._metrics(scs_b, self._policy_params)
            self._nominal_b = jax.tree.map(lambda x: x[:1], metrics)
        return jax.tree.map(lambda x: jnp.repeat(x, n, axis=0), self._nominal_b)

    def __call__(self, values: np.ndarray) -> Verdict:
        """Verify candidates given as knob values (N, K)."""
        values = jnp.asarray(values, jnp.float32)
        n = values.shape[0]
        p = self.problem
        scs_a, scs_b = self._pairs(p.scenario_a, p.scenario_b, values)
        m_a = self._metrics(scs_a, self._policy_params)
        m_b = self._route_b(scs_b, n)
        comps = pair_components(m_a, m_b, p.scenario_a.config.d_safe, p.settings.scoring)
        comps = jax.tree.map(np.asarray, comps)
        expert = jax.tree.map(np.asarray, self._metrics(scs_a, self._expert_params))
        expert_ok = np.all([getattr(expert, g) for g in ROUTE_A_GATE_NAMES], axis=0)
        passed = np.asarray(comps["gate_product"]) > 0.5
        cus = np.asarray(comps["CUS"], np.float64)
        failed = (~passed | (cus < self.threshold)) & expert_ok
        clear = np.asarray(jax.device_get(m_a.clearance_min_m), np.float64)
        return Verdict(cus, passed, clear, expert_ok, failed)
