"""Smooth failure surrogates through the differentiable simulator, and their gradients.

A stress :class:`Problem` fixes one pair (its Route A under one condition), the policy under
test, the privileged expert that guards plausibility, a search space and a surrogate.  The
surrogate is a sum of two **parts**, each from its own soft rollout of Route A (lower = closer
to a plausible failure):

* the **policy part** (the policy drives), by ``objective``:

  - ``"plausible"`` (default) — the soft collision margin to the watched actors (the minimum
    over ticks and actors of ``max(box distance, 0.1 m/s - ego speed)``, log-sum-exp smoothed,
    capped at :data:`~lantern_jax.apps.stress.plausibility.CAP_M`; it keeps decreasing where the
    plain clearance saturates at 0 m against a stopped ego) plus the soft penalties on actors
    with tracks that stop in the ego's path or leave the road
    (:func:`~lantern_jax.apps.stress.plausibility.plausibility_term`);
  - ``"margin"`` — the collision margin alone;
  - ``"clearance"`` — the benchmark's soft clearance to the hazard (KING-style distance cost);
  - ``"soft_cus"`` — the Route A part of the soft CUS (gates x quality, Route B progress 1);
  - ``"king"`` — KING's cost: the nearest watched actor's box distance to the ego averaged
    over time, plus the tracked actors' soft share of time off the road
    (:func:`~lantern_jax.apps.stress.king.king_cost`; the recipe's problem,
    :func:`~lantern_jax.apps.stress.king.king_problem`, also holds the policy's plans);

* the **expert part** (the expert drives the same scene): a softplus hinge on its soft distance
  to the watched actors below the margin the verification asks of it plus a buffer, weighted by
  ``expert_weight`` (0 = no expert rollout): the surrogate heads for scenes the policy fails and
  the expert still drives with margin, not for collisions nobody could avoid.  It is
  differentiated with the expert's plans held fixed (:func:`held_plans`): it moves the
  adversary away from where the expert drives.

The two parts are separable, so one compiled program (the policy and the expert as the members
of one :class:`~lantern_jax.sim.switch.PolicySwitch`) computes either, and a gradient step costs
one soft rollout with its backward pass per part.

The closed loop is piecewise (visibility flips, event triggers, planner choices), so pathwise
gradients can be biased (Suh et al., ICML 2022).  :func:`estimate` therefore returns, from one
batch of ``M`` Gaussian perturbations ``z + sigma eps`` (randomized smoothing):

* the **first-order** (pathwise) estimate ``mean_m grad f(z + sigma eps_m)``;
* the **zeroth-order** estimate ``mean_m (f(z + sigma eps_m) - mean f) eps_m / sigma``;
* their **blend**: the first-order estimate where it agrees with the zeroth-order one within
  ``BIAS_Z`` standard errors in every coordinate (low variance, unbiased enough), else the
  zeroth-order one (a simple form of the paper's alpha-order gradient).

With ``sigma = 0`` the estimate is the plain pathwise gradient at ``z`` (one rollout per part).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.apps.stress.king import king_cost
from lantern_jax.apps.stress.space import Space
from lantern_jax.apps.stress.watch import soft_rollout_batch
from lantern_jax.core.constants import DT, MAX_ACTORS
from lantern_jax.core.xla_options import fast_compile_options
from lantern_jax.policies.base import Policy
from lantern_jax.scoring.cus import cus_of, quality_a, soft_execution_terms
from lantern_jax.scoring.smooth import softmin_decode
from lantern_jax.sim.engine import program_identity, remember
from lantern_jax.sim.programs import stored
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.switch import policy_switch, switch_params
from lantern_jax.types.world import Scenario

Array = jax.Array

OBJECTIVES = ("plausible", "margin", "clearance", "soft_cus", "king")
CLEARANCE_CAP_M = rules.CAP_M  # m, soft clearance is capped here (a far-away hazard is "safe")
BIAS_Z = 2.0  # standard errors within which the first-order estimate is trusted
POLICY, EXPERT = 0, 1  # the parts (and the members of the problem's switch)


#: The actors a problem can watch (``StressConfig.watch``): ``"hazard"``, the hazard and every
#: actor with a track; ``"all"``, every actor of the scene (a policy may collide with another
#: vehicle than the hazard, and the expert must keep its margin from every one).
WATCHES = ("hazard", "all")


def watched_slots(scenario_a: Scenario, space: Space, watch: str = "hazard") -> tuple[int, ...]:
    """The slots a problem watches: the hazard first, then the tracked slots (``"hazard"``,
    padded with the hazard to 1 + T entries) or every other slot with a box (``"all"``, padded
    with the hazard to ``MAX_ACTORS`` entries); the padding gives every family's problem of one
    space layout one compiled program.

    Raises:
        ValueError: for a ``watch`` not in :data:`WATCHES`.
    """
    if watch not in WATCHES:
        raise ValueError(f"watch: {watch!r} not one of {', '.join(WATCHES)}")
    hazard = int(np.asarray(scenario_a.config.hazard_index))
    if watch == "hazard":
        slots, size = space.tracked, 1 + len(space.tracked)
    else:
        boxed = np.asarray(scenario_a.actors.extent)[:, 0] > 0
        slots, size = tuple(int(s) for s in np.nonzero(boxed)[0]), MAX_ACTORS
    watched = (hazard, *(s for s in slots if s != hazard))
    return watched + (hazard,) * (size - len(watched))


@dataclasses.dataclass(frozen=True)
class Problem:
    """What is searched: one pair's Route A, the policy under test, its guard, space, surrogate.

    The jitted functions built from a problem take its arrays (scenarios, parameters, ranges)
    as arguments, so problems that differ only in those — another pair or family with the same
    space layout, narrower ranges — reuse one compilation.
    """

    space: Space
    scenario_a: Scenario  # Route A with the condition (warning on/off) already set
    scenario_b: Scenario
    policy: Policy
    policy_params: Any
    horizon: int  # ticks of the soft rollouts
    temperature: float  # soft-score temperature (m, s, m/s in the relaxed quantities)
    objective: str  # one of OBJECTIVES
    expert: Policy | None = None  # the plausibility guard (None: no expert part)
    expert_params: Any = None
    watched: tuple[int, ...] = ()  # slots the watch measures (default: hazard + tracked,
    #                                padded with the hazard to 1 + T entries)
    expert_weight: float = rules.EXPERT_WEIGHT
    settings: Settings = DEFAULT_SETTINGS  # scoring and protocol (its temperature replaced)
    hold_policy: bool = False  # the soft rollouts hold the policy's plans fixed to
    #                            differentiation (KING's detached ego, :func:`held_plans`)
    actor_temperature: float | None = None  # m, of the margins' soft minimum over the
    #                watched actors (None: ``temperature``, in effect the nearest actor's
    #                margin; larger: the actors near the nearest share the gradient,
    #                :func:`soft_margin`)
    info: dict = dataclasses.field(default_factory=dict, compare=False, hash=False)  # notes
    #                  of a run (the nominal scene's verdict, compile time)

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective {self.objective!r} not one of {', '.join(OBJECTIVES)}")
        if self.actor_temperature is not None and not (
            np.isfinite(self.actor_temperature) and self.actor_temperature > 0
        ):
            raise ValueError(f"actor_temperature: expected metres > 0 (or None), got "
                             f"{self.actor_temperature!r}")  # fmt: skip
        if not self.watched:
            object.__setattr__(self, "watched", watched_slots(self.scenario_a, self.space))

    @property
    def tracked_mask(self) -> np.ndarray:
        """(W,) bool: which watched entries are tracked slots (first occurrence)."""
        first = [self.watched.index(s) == i for i, s in enumerate(self.watched)]
        return np.asarray([s in self.space.tracked and f for s, f in
                           zip(self.watched, first, strict=True)], bool)  # fmt: skip

    @functools.cached_property
    def driver(self) -> Any:
        """The program that drives the hard rollouts: the policy and the expert as one switch
        (or the policy alone, when it is the expert)."""
        if self.expert is None or self.expert.program == self.policy.program:
            return self.policy
        return policy_switch((self.policy, self.expert))

    @functools.cached_property
    def soft_driver(self) -> Any:
        """The program of the soft rollouts: the policy (its plans held too with
        ``hold_policy``) and the expert with its plans held fixed (:func:`held_plans`), as one
        switch; the policy alone without an expert, or with ``hold_policy`` and no expert part
        (KING's recipe: the expert never drives a soft rollout there, and a held expert under
        test would be the same program twice)."""
        policy = held_plans(self.policy) if self.hold_policy else self.policy
        if self.expert is None or (self.hold_policy and self.expert_weight == 0):
            return policy
        return policy_switch((policy, held_plans(self.expert)))

    def member(self, part: int, soft: bool = False) -> Any:
        """A driver's parameters with the policy (``POLICY``) or the expert driving."""
        driver = self.soft_driver if soft else self.driver
        if not hasattr(driver, "members"):  # one policy drives (no switch)
            return self.policy_params if part == POLICY else self.expert_params
        return switch_params(driver, part, (self.policy_params, self.expert_params))

    def data(self) -> tuple:
        """The problem's arrays: ``(scenario_a, scenario_b, lo, hi, watched, tracked,
        settings)`` (the settings with the surrogate's temperature)."""
        return (
            self.scenario_a,
            self.scenario_b,
            jnp.asarray(self.space.lo),
            jnp.asarray(self.space.hi),
            jnp.asarray(self.watched, jnp.int32),
            jnp.asarray(self.tracked_mask),
            self.settings.with_temperature(self.temperature),
        )

    def static(self) -> tuple:
        """What a compilation depends on besides the arrays."""
        driver, soft = (getattr(d, "program", d) for d in (self.driver, self.soft_driver))
        return self._static(driver, soft)

    def _static(self, driver: Any, soft_driver: Any) -> tuple:
        """:meth:`static` with the drivers as given."""
        return (
            self.space.key(),
            driver,
            soft_driver,
            self.horizon,
            float(self.temperature),
            self.objective,
            len(self.watched),
            float(self.expert_weight),
            self.hold_policy,
            self.actor_temperature,
        )

    def store_identity(self, name: str) -> tuple:
        """The program store's identity of this problem's program ``name``
        (:func:`lantern_jax.sim.programs.executable`): what a compilation depends on besides
        the arrays (:meth:`static`), the functions the space calls (a knob's) and the compiler
        options, so that a cell run again in a new process loads its programs instead of
        tracing and compiling them.  A policy, expert or knob from outside this package cannot
        be described with certainty, and its programs are then compiled in every process
        (:func:`lantern_jax.io.program_store.program_key`)."""
        static = self._static(program_identity(self.driver), program_identity(self.soft_driver))
        return ("stress", name, *static, self.space.program_parts(), fast_compile_options())


@functools.cache
def held_plans(expert: Policy) -> Policy:
    """``expert`` whose plans are constants to differentiation (``stop_gradient``): the expert
    part of the surrogate then moves with the adversary's motion only, the expert's reaction
    held as it is.  Its rule-based planner is a chain of decisions whose derivative is neither
    informative nor finite everywhere (a NaN at touching boxes, measured on Vehicle Cut-In)."""
    if expert.stateful:
        raise ValueError(f"policy {expert.name!r}: its plans cannot be held fixed (a policy "
                         "with memory); the expert guard and KING's detached ego need one "
                         "without")  # fmt: skip

    expert_act = expert.act  # the program's identity names the act function, not the policy

    def act(params, obs):
        return jax.lax.stop_gradient(expert_act(params, obs))

    return Policy(
        f"{expert.name} (plans held)", expert.init, act, expert.description, sensors=expert.sensors
    )


def candidate_values(data: tuple, z: Array) -> Array:
    """(..., K) parameter values of unconstrained ``z`` for the problem arrays ``data``."""
    lo, hi = data[2], data[3]
    return lo + (hi - lo) * jax.nn.sigmoid(z)


def _softmin(x: Array, temperature: float) -> Array:
    """Soft minimum of ``x`` (W,) at ``temperature``."""
    return -temperature * jax.nn.logsumexp(-x / temperature)


def soft_margin(margin_lse: Array, temperature: float,
                actor_temperature: float | None = None) -> Array:  # fmt: skip
    """() m, the soft collision margin of a watch's accumulators ``margin_lse`` (W,): each
    watched actor's soft minimum over ticks at ``temperature``, capped at
    :data:`~lantern_jax.apps.stress.plausibility.CAP_M`, then the soft minimum over the actors
    at ``actor_temperature`` (m; None: ``temperature``).

    At the surrogate's 0.1 m the minimum over the actors is in effect the nearest one's, and so
    is its gradient: an actor a metre farther gets ``exp(-10)`` of it.  A larger
    ``actor_temperature`` shares the gradient among the actors within a few of it of the
    nearest (weights ``softmax(-margin / actor_temperature)``), so a descent moves each of
    them toward the ego, not only the nearest (``docs/stress.md``: why plain descent falls
    when a background vehicle nearer the ego joins the space)."""
    per_actor = softmin_decode(margin_lse, temperature, cap=rules.CAP_M)
    return _softmin(per_actor, temperature if actor_temperature is None else actor_temperature)


def part_value(
    problem: Problem, z: Array, part: Array, member_params: Any, data: tuple | None = None
) -> Array:
    """() float32, one part of the surrogate at candidate ``z`` (K,) (see the module docstring):
    :func:`part_values` of a batch of one.

    Args:
        problem: the problem (its static parts; its arrays unless ``data`` is given).
        z: (K,) float32, unconstrained candidate.
        part: () int32, ``POLICY`` or ``EXPERT`` (which formula; traced, so both parts share
            one program).
        member_params: the driver's parameters with that part's policy driving.
        data: the problem's arrays as traced arguments (see :meth:`Problem.data`).
    """
    return part_values(problem, z[None], part, member_params, data)[0]


def part_values(
    problem: Problem, z: Array, part: Array, member_params: Any, data: tuple | None = None
) -> Array:
    """(N,) float32, one part of the surrogate at every candidate of ``z`` (N, K), from one
    batched soft rollout (:func:`~lantern_jax.apps.stress.watch.soft_rollout_batch`).  Candidate
    ``i``'s value depends on ``z[i]`` only, so the gradient of the sum is each candidate's own
    (:func:`part_samples`).  Arguments as :func:`part_value`'s."""
    data = problem.data() if data is None else data
    sc_a, sc_b = data[0], data[1]
    scenarios = jax.vmap(lambda x: problem.space.apply(sc_a, sc_b, candidate_values(data, x))[0])(z)
    temp, actor_temp = problem.temperature, problem.actor_temperature
    watched, tracked, settings = data[4], data[5], data[6]
    n = z.shape[0]
    final, watch = soft_rollout_batch(
        scenarios, problem.soft_driver, member_params, problem.horizon, settings,
        jnp.broadcast_to(watched, (n, *watched.shape)),
        jnp.broadcast_to(tracked, (n, *tracked.shape)),
    )  # fmt: skip

    def value(tel, w, d_safe):
        # a branch, not a select: the other part's derivative is never formed (a select would
        # multiply its infinite partials by zero)
        return jax.lax.cond(part == POLICY, policy_part, expert_part, (tel, w, d_safe))

    def policy_part(ops):
        tel, w, d_safe = ops
        if problem.objective == "plausible":
            stop = jnp.max(jnp.where(tracked, w.stop_soft, 0.0))
            off = jnp.max(jnp.where(tracked, w.off_road_soft, 0.0))
            return soft_margin(w.margin_lse, temp, actor_temp) + rules.plausibility_term(stop, off)
        if problem.objective == "margin":
            return soft_margin(w.margin_lse, temp, actor_temp)
        if problem.objective == "clearance":
            return softmin_decode(tel.clearance.lse, temp, cap=CLEARANCE_CAP_M)
        if problem.objective == "king":
            return king_cost(w.near_sum, w.near_seen, w.off_road_soft, tracked,
                             problem.horizon * DT)  # fmt: skip
        s = settings.scoring
        t = soft_execution_terms(tel, d_safe, temp, s)
        gates = (
            t["gate_collision"]
            * t["gate_route_deviation"]
            * t["gate_lane"]
            * t["gate_rule"]
            * t["gate_block"]
        )
        safety = 0.5 * (t["S_ttc"] + t["S_clear"])
        temporal = 0.5 * (t["S_ant"] + t["S_rec"])
        # Route B is taken as fully completed: the search moves Route A only
        return cus_of(quality_a(t["P"], safety, temporal, s), 1.0, gates, s)

    def expert_part(ops):
        return rules.expert_term(soft_margin(ops[1].dist_lse, temp, actor_temp),
                                 problem.expert_weight)

    return jax.vmap(value)(final.telemetry, watch, scenarios.config.d_safe)


def soft_objective(problem: Problem, z: Array, data: tuple | None = None) -> Array:
    """() float32 surrogate of one candidate ``z`` (K,): both parts (eager convenience)."""
    value = part_value(problem, z, jnp.int32(POLICY), problem.member(POLICY, True), data)
    if problem.expert is not None and problem.expert_weight > 0:
        value = value + part_value(
            problem, z, jnp.int32(EXPERT), problem.member(EXPERT, True), data
        )
    return value


@struct.dataclass
class Estimate:
    """Value and gradient estimates of the smoothed surrogate at one candidate."""

    value: Array  # () float32, mean surrogate over the perturbations
    first: Array  # (K,) float32, first-order (pathwise) estimate
    zeroth: Array  # (K,) float32, zeroth-order estimate (zeros when sigma = 0)
    blend: Array  # (K,) float32, the estimate a search follows
    alpha: Array  # () float32, 1 where the first-order estimate was trusted, else 0


def estimate_from_samples(values: Array, grads: Array, eps: Array, sigma: float) -> Estimate:
    """:class:`Estimate` from the surrogate's values (M,) and gradients (M, K) at
    ``z + sigma eps`` (M, K) (the module docstring's three estimates)."""
    mean = jnp.mean(values)
    first = jnp.mean(grads, axis=0)
    if sigma == 0.0:
        return Estimate(mean, first, jnp.zeros_like(first), first, jnp.ones((), jnp.float32))
    terms = (values - mean)[:, None] * eps / sigma  # (M, K)
    zeroth = jnp.mean(terms, axis=0)
    se = jnp.std(terms, axis=0) / jnp.sqrt(eps.shape[0]) + 1e-6
    trusted = jnp.all(jnp.abs(first - zeroth) <= BIAS_Z * se)
    blend = jnp.where(trusted, first, zeroth)
    return Estimate(mean, first, zeroth, blend, trusted.astype(jnp.float32))


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
        return estimate_from_samples(value[None], grad[None], eps[:1], 0.0)
    values, grads = jax.vmap(jax.value_and_grad(f))(z[None, :] + sigma * eps)
    return estimate_from_samples(values, grads, eps, sigma)


def estimate(
    problem: Problem, z: Array, eps: Array, sigma: float, data: tuple | None = None
) -> Estimate:
    """:func:`smoothed_estimate` of the problem's whole surrogate at ``z`` (K,) (eager)."""
    return smoothed_estimate(lambda x: soft_objective(problem, x, data), z, eps, sigma)


def pad_rows(x: np.ndarray, multiple: int) -> np.ndarray:
    """``x`` (N, ...) with its last row repeated until N is a multiple of ``multiple``: the
    candidates of one call of a program compiled for batches of ``multiple`` (the rows added
    are evaluated and dropped, so they never change a result)."""
    pad = (-len(x)) % multiple
    return np.concatenate([x, np.repeat(x[-1:], pad, axis=0)]) if pad else x


def part_samples(problem: Problem, grad: bool = True) -> Callable:
    """``(part, points (R, M, K)) -> (values (R, M), grads (R, M, K))``: one part's surrogate and
    pathwise gradient at every point (``grads`` None when ``grad`` is False: no backward pass),
    compiled once per static part of the problem (both parts and every restart share the
    program) with :func:`~lantern_jax.core.xla_options.fast_compile_options` (a cell's compile
    is what its user waits for) and kept in the program store (:meth:`Problem.store_identity`).
    The R x M points are one batch of :func:`part_values`; their gradients are one backward
    pass of the batch's sum (each value depends on its own point only)."""

    def values(z, data, part, mp):
        return part_values(problem, z, part, mp, data)

    def values_and_grads(z, data, part, mp):
        v, pull = jax.vjp(lambda x: values(x, data, part, mp), z)
        return v, pull(jnp.ones_like(v))[0]

    fn = remember(
        ("part_samples", grad, problem.static()),
        lambda: jax.jit(
            values_and_grads if grad else values, compiler_options=fast_compile_options()
        ),
    )
    data = problem.data()
    program = stored(fn, problem.store_identity("values_and_grads" if grad else "values"))

    def run(part: int, pts: Array):
        pts = jnp.asarray(pts, jnp.float32)
        r, m, k = pts.shape
        out = program(pts.reshape(r * m, k), data, jnp.int32(part), problem.member(part, True))
        if not grad:
            return out.reshape(r, m), None
        v, g = out
        return v.reshape(r, m), g.reshape(r, m, k)

    return run


def parts_of(problem: Problem) -> tuple[int, ...]:
    """The parts a gradient step evaluates: the policy's, and the expert's when it counts."""
    has_expert = problem.expert is not None and problem.expert_weight > 0
    return (POLICY, EXPERT) if has_expert else (POLICY,)


def batched_estimator(problem: Problem, sigma: float) -> Callable:
    """``(z (R, K), eps (R, M, K)) -> Estimate`` over restarts (the parts summed; with
    ``sigma == 0`` only ``eps[:, :1]`` is used: one rollout per part and restart)."""
    samples = part_samples(problem)

    def run(z, eps):
        eps = jnp.asarray(eps, jnp.float32)
        if sigma == 0.0:
            eps = jnp.zeros_like(eps[:, :1])
        pts = jnp.asarray(z, jnp.float32)[:, None, :] + sigma * eps
        values, grads = 0.0, 0.0
        for part in parts_of(problem):
            v, g = samples(part, pts)
            values, grads = values + v, grads + g
        return jax.vmap(lambda v, g, e: estimate_from_samples(v, g, e, sigma))(values, grads, eps)

    return run


def batched_objective(problem: Problem) -> Callable:
    """``z (N, K) -> (N,)`` surrogate values (both parts; no backward pass)."""
    samples = part_samples(problem, grad=False)

    def run(z):
        pts = jnp.asarray(z, jnp.float32)[:, None, :]
        return sum(samples(part, pts)[0][:, 0] for part in parts_of(problem))

    return run
