"""Several trained models of one architecture driving as one policy: the mean of their plans.

The members' weights are stacked along a leading axis (``LearnedParams.model``, one entry per
member) and :func:`ensemble_act` runs the one learned act function over that axis with
``vmap``, then averages the ``(10, 2)`` waypoints.  Every ensemble of one architecture and
member count is one compiled program (its weights are arguments, as for a single model), and
the ensemble declares exactly its members' sensors, so it sees what each member sees and
nothing more.

Averaging plans is the plain ensemble of regression models: where the members agree it changes
little, where one member would pull away or brake alone the others damp it.  It is not a vote
between modes (two members that pass a car on either side average to a plan between them), so
it suits members of one recipe trained from several seeds, as measured in the learned models'
page of the documentation.  ``combine="median"`` takes the element-wise median of the plans
instead: with three members, where two agree and one would pull away or brake alone, the plan
follows the two.  Both can give a plan no member proposed (the mean of a member that stops short
of a junction and one that crosses it creeps into the junction); ``combine="medoid"`` drives the
plan of one member, the one whose plan lies nearest the others'.  ``combine="slowest"`` drives
the plan of the member that would travel least along its ten waypoints: where any member would
wait, the ensemble waits (a safety-first arbitration, which also crawls for as long as the most
hesitant member does).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.policies.base import Policy
from lantern_jax.policies.learned.checkpoint import LearnedParams, checkpoint_policy, learned_act
from lantern_jax.types.observation import Observation

Array = jax.Array


def member_plans(params: LearnedParams, obs: Observation) -> Array:
    """``(K, 10, 2)`` float32 waypoints (m, ego frame): the plan of each of the ``K`` members
    whose weights ``params.model`` stacks along its leading axis, for one observation."""
    return jax.vmap(lambda weights: learned_act(params.replace(model=weights), obs))(
        params.model
    )


def ensemble_act(params: LearnedParams, obs: Observation) -> Array:
    """``(10, 2)`` float32 waypoints (m, ego frame): the mean of the members' plans
    (:func:`member_plans`), for one observation."""
    return jnp.mean(member_plans(params, obs), axis=0)


def ensemble_median_act(params: LearnedParams, obs: Observation) -> Array:
    """``(10, 2)`` float32 waypoints (m, ego frame): the element-wise median of the members'
    plans (:func:`member_plans`), for one observation.  With three members each coordinate of
    each waypoint is the middle one of the three: where two members agree and one would pull
    away or brake alone, the plan follows the two (the mean moves a third of the way)."""
    return jnp.median(member_plans(params, obs), axis=0)


def medoid_plan(plans: Array) -> Array:
    """``(10, 2)`` float32: the one of ``plans`` (``(K, 10, 2)`` float32, m) whose summed
    Euclidean distance to the others (each plan's waypoints as one vector) is least, the first
    such on a tie.  It is always a plan some member proposed."""
    flat = plans.reshape(plans.shape[0], -1)  # (K, 20)
    gaps = jnp.sqrt(jnp.sum((flat[:, None, :] - flat[None, :, :]) ** 2, axis=-1) + 1e-12)
    return plans[jnp.argmin(jnp.sum(gaps, axis=1))]


def ensemble_medoid_act(params: LearnedParams, obs: Observation) -> Array:
    """``(10, 2)`` float32 waypoints (m, ego frame): the members' medoid plan
    (:func:`medoid_plan` of :func:`member_plans`), for one observation: one member's own plan,
    never a blend of plans that disagree."""
    return medoid_plan(member_plans(params, obs))


def plan_length(plans: Array) -> Array:
    """``(K,)`` float32, m: the length of each of ``plans`` (``(K, 10, 2)`` float32, m, ego
    frame) as a path from the ego (the origin) through its ten waypoints in order."""
    steps = jnp.diff(jnp.concatenate([jnp.zeros_like(plans[:, :1]), plans], axis=1), axis=1)
    return jnp.sum(jnp.sqrt(jnp.sum(steps**2, axis=-1) + 1e-12), axis=-1)


def slowest_plan(plans: Array) -> Array:
    """``(10, 2)`` float32: the one of ``plans`` (``(K, 10, 2)`` float32, m) whose path is
    shortest (:func:`plan_length`), the first such on a tie: the plan of the member that would
    travel least over the next 2.5 s.  It is always a plan some member proposed."""
    return plans[jnp.argmin(plan_length(plans))]


def ensemble_slowest_act(params: LearnedParams, obs: Observation) -> Array:
    """``(10, 2)`` float32 waypoints (m, ego frame): the slowest member's plan
    (:func:`slowest_plan` of :func:`member_plans`), for one observation: the ensemble waits
    wherever one member would."""
    return slowest_plan(member_plans(params, obs))


#: How an ensemble joins its members' plans (``ensemble_policy(..., combine=)``).
COMBINES = {"mean": ensemble_act, "median": ensemble_median_act, "medoid": ensemble_medoid_act,
            "slowest": ensemble_slowest_act}


def _member(item: Policy | str | Path) -> Policy:
    return item if isinstance(item, Policy) else checkpoint_policy(item)


def stacked_params(members: Sequence[Policy]) -> LearnedParams:
    """The members' parameters with their weights stacked along a new leading axis (one
    member per entry); the frozen text tables are the first member's.

    Raises:
        TypeError: naming a member that is not a learned model.
        ValueError: naming the first member whose architecture (configuration, graph,
            weight shapes) or text tables differ from the first member's.
    """
    params = [m.init(jax.random.PRNGKey(0)) for m in members]
    first = params[0]
    for m, p in zip(members, params, strict=True):
        if not isinstance(p, LearnedParams):
            raise TypeError(f"ensemble member {m.name!r}: not a learned model (its parameters "
                            f"are {type(p).__name__}, not LearnedParams)")  # fmt: skip
        if p.config != first.config:
            raise ValueError(f"ensemble member {m.name!r}: architecture {p.config} differs from "
                             f"{members[0].name!r}'s {first.config}")  # fmt: skip
        shapes = jax.tree.map(np.shape, p.model)
        if p.graphdef != first.graphdef or shapes != jax.tree.map(np.shape, first.model):
            raise ValueError(f"ensemble member {m.name!r}: its weights do not have "
                             f"{members[0].name!r}'s structure and shapes")  # fmt: skip
        same_tables = np.shape(p.embedding) == np.shape(first.embedding) and bool(
            np.array_equal(np.asarray(p.embedding), np.asarray(first.embedding))
            and np.array_equal(np.asarray(p.nav_tokens), np.asarray(first.nav_tokens))
        )
        if not same_tables:
            raise ValueError(f"ensemble member {m.name!r}: its token-embedding table or "
                             f"navigation tokens differ from {members[0].name!r}'s")  # fmt: skip
    stacked = jax.tree.map(lambda *w: jnp.stack(w), *[p.model for p in params])
    return first.replace(model=stacked)


def ensemble_policy(name: str, members: Sequence[Policy | str | Path],
                    description: str = "", combine: str = "mean") -> Policy:  # fmt: skip
    """One policy that drives with the mean (median, medoid, slowest) plan of several learned
    models.

    Args:
        name: the name its result rows carry.
        members: at least one learned model of one architecture: registered learned policies
            (``get_policy("learned-closed-loop-rig")``) or checkpoint paths (``.msgpack``,
            :func:`~lantern_jax.policies.learned.checkpoint.checkpoint_policy`).
        description: one line (default: the members' names).
        combine: how the plans are joined, a key of :data:`COMBINES`: ``"mean"``
            (:func:`ensemble_act`), ``"median"`` (:func:`ensemble_median_act`), ``"medoid"``
            (:func:`ensemble_medoid_act`, the plan of the member nearest the others) or
            ``"slowest"`` (:func:`ensemble_slowest_act`, the plan of the member that would
            travel least).

    Returns:
        A stateless :class:`~lantern_jax.policies.base.Policy` whose ``act`` is
        ``COMBINES[combine]`` and whose sensors are the members' (they must declare the same).

    Raises:
        ValueError: for no members, members with other sensors or another architecture
            (naming the member), a bad name, or a ``combine`` not in :data:`COMBINES`.
        TypeError: naming a member that is not a learned model.
        CheckpointError: for a member path that is no valid checkpoint.
    """
    if combine not in COMBINES:
        raise ValueError(f"ensemble_policy: combine {combine!r} is not one of "
                         f"{', '.join(COMBINES)}")  # fmt: skip
    if isinstance(members, (str, Path, Policy)) or len(members) == 0:
        raise ValueError("ensemble_policy: members: expected a sequence of at least one learned "
                         "model or checkpoint path")  # fmt: skip
    policies = [_member(m) for m in members]
    for m in policies[1:]:
        if m.sensors != policies[0].sensors:
            raise ValueError(f"ensemble member {m.name!r}: sensors {m.sensors} differ from "
                             f"{policies[0].name!r}'s {policies[0].sensors}")  # fmt: skip
    params = stacked_params(policies)
    desc = description or f"{combine} plan of {len(policies)} models: " + ", ".join(
        m.name for m in policies
    )
    return Policy(name, lambda key: params, COMBINES[combine], desc, sensors=policies[0].sensors)
