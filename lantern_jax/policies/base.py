"""The policy interface and the registry of policies by name.

A policy is a pure pair::

    params = policy.init(key)                   # any pytree
    waypoints = policy.act(params, obs)         # (10, 2) float32, ego frame x fwd / y right

Both must be jittable and vmappable; ``act`` sees one scenario (no batch axis).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.constants import NUM_WAYPOINTS
from lantern_jax.policies.observation import Observation

InitFn = Callable[[jax.Array], Any]
ActFn = Callable[[Any, Observation], jax.Array]


@dataclasses.dataclass(frozen=True)
class Policy:
    """A named driving policy: ``init(key) -> params`` and ``act(params, obs) -> (10, 2)``."""

    name: str
    init: InitFn
    act: ActFn
    description: str = ""
    privileged: bool = False
    uses_warning: bool = False


_REGISTRY: dict[str, Callable[[], Policy]] = {}


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
    # Importing the reference module registers the built-in policies.
    from lantern_jax.policies import reference  # noqa: F401

    if name not in _REGISTRY:
        raise KeyError(f"unknown policy {name!r}; known policies: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]()


def policy_names() -> list[str]:
    """Names of all registered policies."""
    from lantern_jax.policies import reference  # noqa: F401

    return sorted(_REGISTRY)


def check_policy_output(policy: Policy, params: Any, obs: Observation) -> None:
    """Trace ``policy.act`` abstractly and check its output shape and dtype.

    Raises:
        ValueError: naming the policy and the expected shape when the output is wrong.
    """
    out = jax.eval_shape(policy.act, params, obs)
    shape = getattr(out, "shape", None)
    if shape != (NUM_WAYPOINTS, 2) or not jnp.issubdtype(out.dtype, jnp.floating):
        raise ValueError(
            f"policy {policy.name!r} returned {shape} {getattr(out, 'dtype', type(out))}; "
            f"expected waypoints of shape ({NUM_WAYPOINTS}, 2) float (ego frame, x forward, "
            "y right, 0.25 s apart)"
        )
