"""The policy interface (the registry of policies by name is :mod:`lantern_jax.policies.registry`).

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
from lantern_jax.observation import Observation

InitFn = Callable[[jax.Array], Any]
ActFn = Callable[[Any, Observation], jax.Array]


@dataclasses.dataclass(frozen=True)
class Policy:
    """A named driving policy: ``init(key) -> params`` and ``act(params, obs) -> (10, 2)``.

    ``privileged`` is a static switch of the simulator: only for such a policy does the
    observation carry ``obs.privileged`` (every actor's forecast from its script), and every
    rollout of it must be run with ``privileged=True`` (:func:`lantern_jax.evaluate.evaluate`
    does this).  ``uses_warning`` is descriptive.
    """

    name: str
    init: InitFn
    act: ActFn
    description: str = ""
    privileged: bool = False
    uses_warning: bool = False


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
