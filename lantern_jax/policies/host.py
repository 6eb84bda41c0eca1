"""Policies written outside JAX (a PyTorch, ONNX Runtime or NumPy model) in the jitted rollout.

A host policy's model is a Python function on NumPy batches.  Inside the rollout it runs through
``jax.pure_callback`` with ``vmap_method="broadcast_all"``: the rollout vmaps the policy over
its batch, and JAX turns that into **one call per tick with the whole batch** (per device: a
rollout split over ``n`` devices makes ``n`` calls per tick, one per shard), never one call per
execution::

    def model(x):                     # x: (B, OBS_SIZE) float32 NumPy array
        return my_torch_net(torch.from_numpy(x)).numpy()     # (B, 2) actions in [-1, 1]

    policy = host_policy("mine", model, out_shape=(2,),
                         preprocess=observation_vector, postprocess=actions_to_waypoints)
    register_policy("mine", lambda: policy)          # build once: its act is the compile key

``preprocess`` (jittable, one observation -> one array) runs inside JAX before the call, and
``postprocess`` (jittable, ``(model output, observation) -> (10, 2)`` waypoints) after it;
without them the model receives the :class:`~lantern_jax.observation.Observation` itself with a
leading batch axis on every field and must return ``(B, 10, 2)`` waypoints.  The model must be
a pure function of its input (JAX may call it again, e.g. when a rollout is retried), must
return finite values of the promised shape (non-finite waypoints are recorded as a controller
fault like any policy's), and holds its own weights (the policy's ``params`` are empty).  Not
differentiable: gradients do not flow through a host call.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import NUM_WAYPOINTS
from lantern_jax.observation import Observation
from lantern_jax.policies.base import Policy
from lantern_jax.policies.features import action_to_waypoints

HostFn = Callable[[Any], np.ndarray]


def _batched_call(name: str, fn: HostFn, base_ndims: list[int], out_shape: tuple[int, ...]):
    """The callback: flatten the vmapped leading axes into one batch, call ``fn``, restore them.

    ``broadcast_all`` hands every argument with the same leading (vmapped) axes in front of the
    unit batch axis :func:`host_act` adds; ``base_ndims`` are the ranks of one execution's
    arguments, so the leading axes (vmapped ones and the unit axis) are what precedes them.
    """

    def call(tree):
        leaves, treedef = jax.tree.flatten(tree)
        lead = leaves[0].shape[: leaves[0].ndim - base_ndims[0]]
        n = int(np.prod(lead)) if lead else 1
        flat = [np.asarray(x).reshape((n, *x.shape[len(lead) :])) for x in leaves]
        out = np.asarray(fn(jax.tree.unflatten(treedef, flat)))
        if out.shape != (n, *out_shape):
            raise ValueError(
                f"host policy {name!r} returned shape {out.shape} for a batch of {n}; "
                f"expected {(n, *out_shape)}"
            )
        return out.astype(np.float32).reshape((*lead, *out_shape))

    return call


def host_act(
    name: str,
    fn: HostFn,
    out_shape: tuple[int, ...] = (NUM_WAYPOINTS, 2),
    preprocess: Callable[[Observation], Any] | None = None,
    postprocess: Callable[[jax.Array, Observation], jax.Array] | None = None,
):
    """The ``act(params, obs)`` of a host policy (see the module docstring for the arguments)."""

    def act(params: Any, obs: Observation) -> jax.Array:
        del params
        x = obs if preprocess is None else preprocess(obs)
        base = [jnp.ndim(leaf) for leaf in jax.tree.leaves(x)]
        # A unit batch axis of our own: the model always sees (B, ...), vmapped or not.
        x1 = jax.tree.map(lambda leaf: jnp.asarray(leaf)[None], x)
        result = jax.ShapeDtypeStruct((1, *out_shape), jnp.float32)
        call = _batched_call(name, fn, base, out_shape)
        y = jax.pure_callback(call, result, x1, vmap_method="broadcast_all")[0]
        return y if postprocess is None else postprocess(y, obs)

    return act


def host_policy(
    name: str,
    fn: HostFn,
    out_shape: tuple[int, ...] = (NUM_WAYPOINTS, 2),
    preprocess: Callable[[Observation], Any] | None = None,
    postprocess: Callable[[jax.Array, Observation], jax.Array] | None = None,
    description: str = "",
    uses_warning: bool = False,
) -> Policy:
    """A :class:`Policy` whose model runs on the host (see the module docstring).

    Args:
        name: policy name.
        fn: the model, ``fn(batch) -> (B, *out_shape)`` NumPy array.
        out_shape: the model's output shape per execution.
        preprocess: jittable ``observation -> model input`` for one execution.
        postprocess: jittable ``(model output, observation) -> (10, 2)`` waypoints.
        description: shown by ``lantern-jax policies``.
        uses_warning: the model reads the warning fields.
    """
    act = host_act(name, fn, out_shape, preprocess, postprocess)
    return Policy(name, lambda key: {}, act, description or f"host model {name}",
                  uses_warning=uses_warning)  # fmt: skip


def actions_to_waypoints(action: jax.Array, obs: Observation) -> jax.Array:
    """``postprocess`` for models that output the two-number action of
    :mod:`lantern_jax.policies.features` (acceleration, curvature in [-1, 1])."""
    return action_to_waypoints(action, obs.ego_speed)
