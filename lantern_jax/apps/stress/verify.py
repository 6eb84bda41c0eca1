"""Exact verification of stress-test candidates: hard pair CUS, gates, and plausibility.

A candidate counts as a **failure** only if the policy's hard (exact) evaluation of the pair
fails a gate or scores a CUS below the threshold, and only when it is **plausible** by the rules
of :mod:`lantern_jax.apps.stress.plausibility` (the privileged expert drives the same scene with
margin; no actor with a track freezes in the ego's path, leaves the road or exceeds its limits).
Every search method uses this one verifier, so their failure counts are comparable; it runs the
policy and the expert as the two members of one compiled program
(:mod:`lantern_jax.sim.switch`) and processes candidates in batches of one fixed size, so one
compilation serves every method.  A verified candidate costs two hard rollouts of Route A (the
policy's and the expert's); Route B does not depend on the candidate (unless the space changes
what both routes share) and is run once, nominally, before any search starts.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.apps.stress.objective import EXPERT, POLICY, Problem, pad_rows
from lantern_jax.apps.stress.watch import hard_batch
from lantern_jax.core.constants import MAX_VERIFY_S, ROUTE_A_GATE_NAMES
from lantern_jax.core.times import ticks
from lantern_jax.core.xla_options import fast_compile_options
from lantern_jax.dynamics.adversary import limits_of_kind
from lantern_jax.scoring.cus import compiled_pair_components
from lantern_jax.sim.engine import program_identity, remember
from lantern_jax.sim.programs import stored

FAIL_BELOW_CUS = rules.FAIL_BELOW_CUS
ROUTE_A_GATES = ROUTE_A_GATE_NAMES  # the five gates of a Route A execution
MAX_VERIFY_TICKS = ticks(MAX_VERIFY_S)  # ticks; the batch exits early


@dataclasses.dataclass
class Verdict:
    """Hard verification of N candidates (NumPy arrays, one entry per candidate)."""

    cus: np.ndarray  # (N,) float64, the policy's hard pair CUS, points
    gates_passed: np.ndarray  # (N,) bool, every gate of the pair passed
    clearance_m: np.ndarray  # (N,) float64, the policy's hard clearance to the hazard (NaN n/a)
    expert_ok: np.ndarray  # (N,) bool, the expert passes with margin (plausibility rule 1)
    failed: np.ndarray  # (N,) bool, verified, plausible failure
    plausible: np.ndarray | None = None  # (N,) bool, rules 2-4 (the tracked actors)
    policy_failed: np.ndarray | None = None  # (N,) bool, gate or CUS failure, plausible or not
    margin_m: np.ndarray | None = None  # (N,) m, the policy's least collision margin (watched)
    expert_dist_m: np.ndarray | None = None  # (N,) m, the expert's least distance (watched)
    stop_s: np.ndarray | None = None  # (N,) s, longest stop in the ego's path (tracked)
    off_road_s: np.ndarray | None = None  # (N,) s, longest time off the road (tracked)
    objective: np.ndarray | None = None  # (N,) the surrogate's hard expression
    failed_gates: list | None = None  # (N,) names of the policy's failed Route A gates
    t_fail_s: np.ndarray | None = None  # (N,) s, the policy's first gate failure (NaN none)
    expert_failed_gates: list | None = None  # (N,) names of the expert's failed Route A gates
    traj: np.ndarray | None = None  # (N, K, W, 2) m, watched actors every 0.25 s (NaN absent)

    @property
    def fitness(self) -> np.ndarray:
        """(N,) what black-box searches minimise: the surrogate's hard expression when known,
        else the hard CUS with ties broken by clearance."""
        if self.objective is not None:
            return self.objective
        clear = np.where(np.isnan(self.clearance_m), 10.0, np.minimum(self.clearance_m, 10.0))
        return self.cus + 0.01 * clear


def _hard_program(problem: Problem) -> Any:
    """``(scenarios, member_params) -> (metrics, watch)`` under the problem's settings,
    compiled once per driver and number of watched slots (which slots, and the settings' float
    fields, are arguments), with :func:`~lantern_jax.core.xla_options.fast_compile_options`,
    and kept in the program store (a driver from outside this package is compiled in every
    process: :func:`lantern_jax.io.program_store.program_key`)."""
    driver = problem.driver
    n_watched = len(problem.watched)
    identity = ("stress-hard", program_identity(driver), n_watched, MAX_VERIFY_TICKS,
                fast_compile_options())  # fmt: skip
    fn = remember(
        ("stress-hard", getattr(driver, "program", driver), n_watched),
        lambda: jax.jit(
            lambda scs, params, watched, tracked, settings: hard_batch(
                scs, driver, params, MAX_VERIFY_TICKS, watched, tracked, settings
            ),
            compiler_options=fast_compile_options(),
        ),
    )
    watched = jnp.asarray(problem.watched, jnp.int32)
    tracked = jnp.asarray(problem.tracked_mask)
    settings = problem.settings
    run = stored(fn, identity)
    return lambda scs, params: run(scs, params, watched, tracked, settings)


def _pair_builder(problem: Problem) -> Any:
    """``(scenario_a, scenario_b, values (N, K)) -> batched pairs``, compiled once per space
    layout and kept in the program store (:meth:`Problem.store_identity`)."""
    space = problem.space
    fn = remember(
        ("stress-pairs", space.key()),
        lambda: jax.jit(
            jax.vmap(lambda sa, sb, v: space.apply(sa, sb, v), in_axes=(None, None, 0))
        ),
    )
    return stored(fn, ("stress-pairs", space.key(), space.program_parts()))


def speed_limits(problem: Problem) -> np.ndarray:
    """(W,) m/s, the realised-speed limit of each watched slot (inf for untracked ones)."""
    script = problem.scenario_a.actors
    out = []
    for s, tracked in zip(problem.watched, problem.tracked_mask, strict=True):
        if not tracked:
            out.append(np.inf)
            continue
        lim = limits_of_kind(int(np.asarray(script.kind)[s]))
        v_start = max(float(np.asarray(script.v_post)[s]), float(np.asarray(script.v_pre)[s]))
        out.append(rules.speed_limit(lim.v_max, lim.lat_max, lim.holonomic, v_start))
    return np.asarray(out, np.float64)


class Verifier:
    """Batched hard evaluation of candidate values (N, K) for one :class:`Problem`.

    Args:
        problem: the problem (its ``expert`` is the plausibility guard and must be set).
        batch: candidates per compiled call (every call pads to it; one program).
        threshold: CUS below which a pair fails.
    """

    def __init__(self, problem: Problem, batch: int = 8, threshold: float = FAIL_BELOW_CUS):
        if problem.expert is None:
            raise ValueError("Verifier: the problem needs an expert (the plausibility guard)")
        self.problem = problem
        self.batch = int(batch)
        self.threshold = threshold
        self._pairs = _pair_builder(problem)
        self._run = _hard_program(problem)
        self._limits = speed_limits(problem)
        self._nominal_b = None

    def _route_b(self, scs_b: Any) -> Any:
        p = self.problem
        if p.space.shared:
            return self._run(scs_b, p.member(POLICY))[0]
        if self._nominal_b is None:  # Route B does not depend on the candidate: run it once
            metrics = self._run(scs_b, p.member(POLICY))[0]
            self._nominal_b = jax.tree.map(lambda x: x[:1], metrics)
        return jax.tree.map(lambda x: jnp.repeat(x, self.batch, axis=0), self._nominal_b)

    def _chunk(self, values: np.ndarray) -> dict[str, Any]:
        p = self.problem
        scs_a, scs_b = self._pairs(p.scenario_a, p.scenario_b, jnp.asarray(values, jnp.float32))
        m_a, w_a = self._run(scs_a, p.member(POLICY))
        comps = compiled_pair_components(
            m_a, self._route_b(scs_b), p.scenario_a.config.d_safe, p.settings.scoring
        )
        m_e, w_e = self._run(scs_a, p.member(EXPERT))
        return jax.device_get(dict(m_a=m_a, w_a=w_a, comps=comps, m_e=m_e, w_e=w_e))

    def __call__(self, values: np.ndarray) -> Verdict:
        """Verify candidates given as values (N, K) of the problem's space."""
        values = np.asarray(values, np.float32)
        n = values.shape[0]
        padded = pad_rows(values, self.batch)
        parts = [self._chunk(padded[i : i + self.batch]) for i in range(0, len(padded), self.batch)]
        cat = lambda *xs: np.concatenate([np.asarray(x) for x in xs])[:n]  # noqa: E731
        r = jax.tree.map(cat, *parts)
        return self._verdict(r)

    def _verdict(self, r: dict[str, Any]) -> Verdict:
        m_a, w_a, comps, m_e, w_e = r["m_a"], r["w_a"], r["comps"], r["m_e"], r["w_e"]
        tracked = self.problem.tracked_mask
        passed = np.asarray(comps["gate_product"]) > 0.5
        cus = np.asarray(comps["CUS"], np.float64)
        policy_failed = ~passed | (cus < self.threshold)
        expert_gates = np.all([np.asarray(getattr(m_e, g)) for g in ROUTE_A_GATES], axis=0)
        expert_dist = np.min(np.asarray(w_e.dist, np.float64), axis=1)
        expert_ok = rules.expert_passes_with_margin(
            expert_gates, np.asarray(m_e.clearance_min_m, np.float64), expert_dist
        )
        if tracked.any():
            stop = np.max(np.asarray(w_a.stop_max)[:, tracked], axis=1).astype(np.float64)
            off = np.max(np.asarray(w_a.off_road)[:, tracked], axis=1).astype(np.float64)
            speed = np.asarray(w_a.max_speed, np.float64)[:, tracked]
            plausible = rules.adversary_plausible(stop, off, speed, self._limits[tracked])
        else:
            stop = off = np.zeros(len(cus))
            plausible = np.ones(len(cus), bool)
        margin = np.min(np.asarray(w_a.margin, np.float64), axis=1)
        failed_gates, expert_failed_gates = (
            [[g for g in ROUTE_A_GATES if not bool(np.asarray(getattr(m, g))[i])]
             for i in range(len(cus))]
            for m in (m_a, m_e)
        )  # fmt: skip
        return Verdict(
            cus=cus,
            gates_passed=passed,
            clearance_m=np.asarray(m_a.clearance_min_m, np.float64),
            expert_ok=expert_ok,
            failed=policy_failed & expert_ok & plausible,
            plausible=plausible,
            policy_failed=policy_failed,
            margin_m=margin,
            expert_dist_m=expert_dist,
            stop_s=stop,
            off_road_s=off,
            objective=rules.hard_objective(margin, expert_dist, stop, off),
            failed_gates=failed_gates,
            expert_failed_gates=expert_failed_gates,
            t_fail_s=np.asarray(m_a.t_first_failure_s, np.float64),
            traj=np.asarray(w_a.traj),
        )
