"""Policies by name: the built-in reference policies and any a user registers.

    from lantern_jax.policies.registry import get_policy, register_policy
    register_policy("mine", lambda: Policy("mine", init, act, "my planner"))
    policy = get_policy("mine")

A duplicate or unknown name is an error that lists the known names.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from lantern_jax.policies import expert, learned_ppo, reference
from lantern_jax.policies.base import Policy
from lantern_jax.policies.learned.shipped import SHIPPED_MODELS

_REGISTRY: dict[str, Callable[[], Policy]] = {
    "expert": expert.expert_policy,
    "ego": reference.ego_policy,
    "coop": reference.coop_policy,
    "expert-v1": reference.legacy_expert_policy,
    "ppo": learned_ppo.ppo_policy,
}


def _shipped(name: str) -> Callable[[], Policy]:
    """The factory of a shipped learned model: loads its checkpoint once per process and
    returns that same policy afterwards.  Its ``act`` is the key of every compiled program
    (:func:`lantern_jax.evaluate.compiled_rollout`), so a fresh ``act`` per call would compile
    the whole rollout again on every evaluation that names the model."""

    @functools.cache
    def factory() -> Policy:
        from lantern_jax.policies.learned.checkpoint import checkpoint_policy, shipped_path

        return checkpoint_policy(shipped_path(name), name)

    return factory


for _name in SHIPPED_MODELS:
    _REGISTRY[_name] = _shipped(_name)


def register_policy(name: str, factory: Callable[[], Policy]) -> None:
    """Register a policy factory under ``name``; a duplicate name is an error."""
    if name in _REGISTRY:
        raise ValueError(f"policy {name!r} is already registered; known: {sorted(_REGISTRY)}")
    _REGISTRY[name] = factory


def get_policy(name: str) -> Policy:
    """Return the policy registered as ``name``.

    Raises:
        KeyError: listing the known policy names when ``name`` is unknown.
    """
    if name not in _REGISTRY:
        raise KeyError(f"unknown policy {name!r}; known policies: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]()


def register_checkpoint(path: str, name: str | None = None) -> str:
    """Register a saved learned model (``.msgpack`` + ``.json``) as a policy; returns its name
    (the name it was trained under unless given)."""
    from lantern_jax.policies.learned.checkpoint import checkpoint_policy

    policy = checkpoint_policy(path, name)
    _REGISTRY[policy.name] = lambda: policy
    return policy.name


def policy_names() -> list[str]:
    """Names of all registered policies."""
    return sorted(_REGISTRY)
