"""Smooth failure surrogates through the differentiable simulator, and their gradients.

A stress :class:`Problem` fixes one pair (its Route A under one condition), the policy under test
and a search space; :func:`soft_objective` rolls Route A out in soft mode and returns a number
that is lower the closer the execution comes to failing (never the binary collision):

* ``"clearance"`` — the soft minimum box-surface distance (m) between the ego and the controlled
  hazard from the event to clearance, capped at :data:`CLEARANCE_CAP_M` (KING-style distance
  cost);
* ``"margin"`` — the collision margin of the collision gate (m; the minimum over hazard ticks of
  ``max(box distance, 0.1 m/s - ego speed)``, non-positive on a counted collision);
* ``"soft_cus"`` — the Route A part of the soft CUS (gates × quality, with Route B progress 1).

The closed loop is piecewise (visibility flips, event triggers, planner choices), so pathwise
gradients can be biased (Suh et al., ICML 2022).  :func:`estimate` therefore returns, from one
batch of ``M`` Gaussian perturbations ``z + sigma eps`` (randomized smoothing):

* the **first-order** (pathwise) estimate ``mean_m grad f(z + sigma eps_m)``;
* the **zeroth-order** estimate ``mean_m (f(z + sigma eps_m) - mean f) eps_m / sigma``;
* their **blend**: the first-order estimate where it agrees with the zeroth-order one within
  ``BIAS_Z`` standard errors in every coordinate (low variance, unbiased enough), else the
  zeroth-order one (a simple form of the paper's alpha-order gradient).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.policies.base import Policy
from lantern_jax.scoring.cus import cus_of, quality_a, soft_execution_terms
from lantern_jax.scoring.smooth import softmin_decode
from lantern_jax.sim.engine import remember
from lantern_jax.sim.rollout import rollout
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.stress.space import SearchSpace
from lantern_jax.world import Scenario

Array = jax.Array

OBJECTIVES = ("clearance", "margin", "soft_cus")
CLEARANCE_CAP_M = 5.0  # m, soft clearance is capped here (a far-away hazard is just "safe")
BIAS_Z = 2.0  # standard errors within which the first-order estimate is trusted


@dataclasses.dataclass(frozen=True)
class Problem:
    """What is searched: one pair's Route A, the policy under test, the space and the surrogate.

    The jitted functions built from a problem take its arrays (scenarios, policy parameters,
    ranges) as arguments, so problems that differ only in those — another pair, another
    reference policy's parameters, narrower ranges — reuse one compilation.
    """

    space: SearchSpace
    scenario_a: Scenario  # Route A with the condition (warning on/off) already set
    scenario_b: Scenario
    policy: Policy
    policy_params: Any
    horizon: int  # ticks of the soft rollouts
    temperature: float  # soft-score temperature (m, s, m/s in the relaxed quantities)
    objective: str  # one of OBJECTIVES
    settings: Settings = DEFAULT_SETTINGS  # scoring and protocol (its temperature replaced)

    def data(self) -> tuple:
        """The problem's arrays: ``(scenario_a, scenario_b, policy_params, lo, hi, settings)``
        (the settings with the surrogate's temperature)."""
        return (self.scenario_a, self.scenario_b, self.policy_params,
                jnp.asarray(self.space.lo), jnp.asarray(self.space.hi),
                self.settings.with_temperature(self.temperature))  # fmt: skip

    def static(self) -> tuple:
        """What a compilation depends on besides the arrays."""
        return (
            self.space.names, self.policy.program, self.horizon, float(self.temperature),
            self.objective,
        )  # fmt: skip


def candidate_values(data: tuple, z: Array) -> Array:
    """(..., K) knob values of unconstrained ``z`` for the problem arrays ``data``."""
    lo, hi = data[3], data[4]
    return lo + (hi - lo) * jax.nn.sigmoid(z)


def soft_objective(problem: Problem, z: Array, data: tuple | None = None) -> Array:
    """() float32 surrogate of one candidate ``z`` (K,); lower = closer to failure.

    Args:
        problem: the problem (its static parts; its arrays unless ``data`` is given).
        z: (K,) float32, unconstrained candidate.
        data: the problem's arrays as traced arguments (see :meth:`Problem.data`).
    """
    if problem.objective not in OBJECTIVES:
        raise ValueError(f"objective {problem.objective!r} not one of {', '.join(OBJECTIVES)}")
    data = problem.data() if data is None else data
    sc_a, sc_b, policy_params, _, _, settings = data
    sc_a, _ = problem.space.apply(sc_a, sc_b, candidate_values(data, z))
    final, _ = rollout(
        sc_a, problem.policy, policy_params, problem.horizon, settings=settings, remat=True
    )
    tel, temp, s = final.telemetry, problem.temperature, settings.scoring
    if problem.objective == "clearance":
        return softmin_decode(tel.clearance.lse, temp, cap=CLEARANCE_CAP_M)
    if problem.objective == "margin":
        return jnp.minimum(tel.collision.margin, CLEARANCE_CAP_M)
    t = soft_execution_terms(tel, sc_a.config.d_safe, temp, s)
    gates = (t["gate_collision"] * t["gate_route_deviation"] * t["gate_lane"] * t["gate_rule"]
             * t["gate_block"])  # fmt: skip
    safety = 0.5 * (t["S_ttc"] + t["S_clear"])
    temporal = 0.5 * (t["S_ant"] + t["S_rec"])
    # Route B is taken as fully completed: the knobs move Route A's hazard only
    return cus_of(quality_a(t["P"], safety, temporal, s), 1.0, gates, s)


@struct.dataclass
class Estimate:
    """Value and gradient estimates of the smoothed surrogate at one candidate."""

    value: Array  # () float32, mean surrogate over the perturbations
    first: Array  # (K,) float32, first-order (pathwise) estimate
    zeroth: Array  # (K,) float32, zeroth-order estimate (zeros when sigma = 0)
    blend: Array  # (K,) float32, the estimate a search follows
    alpha: Array  # () float32, 1 where the first-order estimate was trusted, else 0


def smoothed_estimate(f: Callable[[Array], Array], z: Array, eps: Array, sigma: float) -> Estimate:
    """Value and gradient estimates of ``E[f(z + sigma eps)]`` from perturbations ``eps`` (M, K).

    With ``sigma == 0`` (no smoothing) the perturbations are ignored and the estimate is the
    plain pathwise gradient at ``z``.

    Args:
        f: scalar function of one candidate (K,), differentiable almost everywhere.
        z: (K,) float32, the candidate.
        eps: (M, K) float32, standard-normal perturbations.
        sigma: smoothing scale (units of ``z``).
    """
    if sigma == 0.0:
        value, grad = jax.value_and_grad(f)(z)
        return Estimate(value, grad, jnp.zeros_like(grad), grad, jnp.ones((), jnp.float32))
    values, grads = jax.vmap(jax.value_and_grad(f))(z[None, :] + sigma * eps)
    mean = jnp.mean(values)
    first = jnp.mean(grads, axis=0)
    terms = (values - mean)[:, None] * eps / sigma  # (M, K)
    zeroth = jnp.mean(terms, axis=0)
    se = jnp.std(terms, axis=0) / jnp.sqrt(eps.shape[0]) + 1e-6
    trusted = jnp.all(jnp.abs(first - zeroth) <= BIAS_Z * se)
    blend = jnp.where(trusted, first, zeroth)
    return Estimate(mean, first, zeroth, blend, trusted.astype(jnp.float32))


def estimate(
    problem: Problem, z: Array, eps: Array, sigma: float, data: tuple | None = None
) -> Estimate:
    """:func:`smoothed_estimate` of the problem's surrogate at ``z`` (K,)."""
    return smoothed_estimate(lambda x: soft_objective(problem, x, data), z, eps, sigma)


def batched_estimator(problem: Problem, sigma: float) -> Callable:
    """``(z (R, K), eps (R, M, K)) -> Estimate`` over restarts, compiled once per static part."""
    fn = remember(
        ("estimate", problem.static(), float(sigma)),
        lambda: jax.jit(
            jax.vmap(lambda data, z, e: estimate(problem, z, e, sigma, data), in_axes=(None, 0, 0))
        ),  # fmt: skip
    )
    data = problem.data()
    return lambda z, eps: fn(data, z, eps)


def batched_objective(problem: Problem) -> Callable:
    """``z (N, K) -> (N,)`` surrogate values, compiled once per static part."""
    fn = remember(
        ("objective", problem.static()),
        lambda: jax.jit(
            jax.vmap(lambda data, z: soft_objective(problem, z, data), in_axes=(None, 0))
        ),  # fmt: skip
    )
    data = problem.data()
    return lambda z: fn(data, z)
