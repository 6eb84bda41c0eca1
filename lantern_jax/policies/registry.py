"""Policies by name: the built-in reference policies and any a user registers.

    from lantern_jax.policies.registry import get_policy, register_policy
    register_policy("mine", lambda: Policy("mine", init, act, "my planner"))
    policy = get_policy("mine")
    name = register_policy_source("my_policy.py:POLICY")   # a user's file, by its Policy.name

A duplicate or unknown name is an error that lists the known names, and so is a name the
command line could not select (:mod:`lantern_jax.policies.names`).  A saved model registers
under the name it was trained under (or one given); a name that is already taken — a built-in
policy, a shipped model, another checkpoint — is refused unless it is the very same checkpoint
(same description hash), so rows labelled with a name always come from the policy of that name.
"""

from __future__ import annotations

from collections.abc import Callable

from lantern_jax.policies import expert, learned_ppo, reference
from lantern_jax.policies.base import Policy
from lantern_jax.policies.external import load_policy_source
from lantern_jax.policies.learned.shipped import SHIPPED_MODELS
from lantern_jax.policies.names import (
    REFERENCE_POLICIES,  # noqa: F401 (re-exported)
    name_problem,
)

_REGISTRY: dict[str, Callable[[], Policy]] = {
    "expert": expert.expert_policy,
    "ego": reference.ego_policy,
    "coop": reference.coop_policy,
    "expert-v1": reference.legacy_expert_policy,
    "ppo": learned_ppo.ppo_policy,
}


def _shipped(name: str) -> Callable[[], Policy]:
    """The factory of a shipped learned model: loads its checkpoint.  Every learned model runs
    through one act function (:func:`~lantern_jax.policies.learned.checkpoint.learned_act`, the
    architecture a static part of its parameters), so a model loaded again is the same program
    and compiles nothing new."""

    def factory() -> Policy:
        # deferred: flax.nnx and the model code load only when a learned model is asked for
        from lantern_jax.policies.learned.checkpoint import checkpoint_policy, shipped_path

        return checkpoint_policy(shipped_path(name), name)

    return factory


for _name in SHIPPED_MODELS:
    _REGISTRY[_name] = _shipped(_name)


#: Description hash (``sha256`` of the ``.json``) of every checkpoint registered by name.
_CHECKPOINT_HASHES: dict[str, str] = {}


def register_policy(name: str, factory: Callable[[], Policy]) -> None:
    """Register a policy factory under ``name``.

    Raises:
        ValueError: for a name already registered or one the command line cannot select.
    """
    if name in _REGISTRY:
        raise ValueError(f"policy {name!r} is already registered; known: {sorted(_REGISTRY)}")
    if name_problem(name):
        raise ValueError(f"policy name: {name_problem(name)}")
    _REGISTRY[name] = factory


def get_policy(name: str) -> Policy:
    """Return the policy registered as ``name``.

    Raises:
        KeyError: listing the known policy names when ``name`` is unknown.
    """
    if name not in _REGISTRY:
        raise KeyError(f"unknown policy {name!r}; known policies: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]()


def _registered_hash(name: str) -> str | None:
    """The description hash of the checkpoint registered as ``name`` (a shipped model's from
    its file), or None for a policy that is not a checkpoint."""
    if name in SHIPPED_MODELS and name not in _CHECKPOINT_HASHES:
        # deferred: flax.nnx and the model code load only when a learned model is asked for
        from lantern_jax.policies.learned.checkpoint import (
            DESCRIPTION_HASH,
            read_meta,
            shipped_path,
        )

        return read_meta(shipped_path(name)).get(DESCRIPTION_HASH)
    return _CHECKPOINT_HASHES.get(name)


def register_checkpoint(path: str, name: str | None = None) -> str:
    """Register a saved learned model (``.msgpack`` + ``.json``) as a policy; returns its name
    (the name it was trained under unless given).

    Registering the same checkpoint (same description hash) under the same name again is
    allowed and changes nothing.

    Raises:
        CheckpointError: for a missing or invalid checkpoint; its subclass
            CheckpointNameTaken for a name that is already registered for another policy (a
            built-in one, a shipped model or another checkpoint).
    """
    # deferred: flax.nnx and the model code load only when a learned model is asked for
    from lantern_jax.policies.learned.checkpoint import (
        DESCRIPTION_HASH,
        CheckpointNameTaken,
        checkpoint_policy,
        read_meta,
    )

    policy = checkpoint_policy(path, name)
    digest = read_meta(path).get(DESCRIPTION_HASH)
    if policy.name in _REGISTRY:
        if _registered_hash(policy.name) == digest:
            return policy.name
        if policy.name in SHIPPED_MODELS:
            what = "a shipped model"
        else:
            what = "another checkpoint" if policy.name in _CHECKPOINT_HASHES else "built in"
        raise CheckpointNameTaken(
            f"{path}: name {policy.name!r} is already registered ({what}); the rows of a name "
            "must come from one policy: register it under another name"
        )  # fmt: skip
    _REGISTRY[policy.name] = lambda: policy
    _CHECKPOINT_HASHES[policy.name] = digest
    return policy.name


#: Where every policy registered from code by :func:`register_policy_source` came from.
_SOURCES: dict[str, dict] = {}


def register_policy_source(spec: str) -> str:
    """Register the policy that ``spec`` names (``path/to/file.py:NAME`` or
    ``package.module:attr``, :func:`~lantern_jax.policies.external.load_policy_source`) under
    its own ``Policy.name``; returns that name.  Its source record (file, SHA-256) is kept for
    the result's manifest (:func:`policy_source`).

    Registering the same spec with the same file content again changes nothing.

    Raises:
        ValueError: for a spec that cannot be loaded, a policy name the command line cannot
            select, or a name already registered for another policy (a built-in one, a shipped
            model, a checkpoint, or other code).
        TypeError: when the named object is neither a Policy nor a factory of one.
    """

    policy, source = load_policy_source(spec)
    problem = name_problem(policy.name)
    if problem:
        raise ValueError(f"policy source {spec!r}: its Policy.name: {problem}")
    if policy.name in _REGISTRY:
        earlier = _SOURCES.get(policy.name)
        if (
            earlier is not None
            and earlier["source_sha256"] == source["source_sha256"]
            and earlier["source_path"] == source["source_path"]
        ):
            return policy.name
        raise ValueError(
            f"policy source {spec!r}: name {policy.name!r} is already registered for another "
            "policy; the rows of a name must come from one policy: give its Policy another name"
        )  # fmt: skip
    _REGISTRY[policy.name] = lambda: policy
    _SOURCES[policy.name] = source
    return policy.name


def policy_source(name: str) -> dict | None:
    """The source record of a policy registered from code (:func:`register_policy_source`;
    the keys of :func:`~lantern_jax.policies.external.load_policy_source`); None for any other
    policy."""
    return _SOURCES.get(name)


def policy_names() -> list[str]:
    """Names of all registered policies."""
    return sorted(_REGISTRY)
