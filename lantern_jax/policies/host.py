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
without them the model receives the :class:`~lantern_jax.types.observation.Observation` itself with
a leading batch axis on every field and must return ``(B, 10, 2)`` waypoints.  ``sensors`` are
declared as for any policy (``("warning",)`` for a model that reads the warning text).

**Memory.**  With ``carry`` (one execution's initial state: a pytree of NumPy arrays, e.g. a
frame history or a recurrent state) the model is called ``fn(batch, carry_batch)`` and returns
``(outputs, new_carry_batch)``, both with the leading batch axis; the simulator keeps each
execution's carry between ticks and resets it when an execution starts.  The model must be
a pure function of its input (JAX may call it again, e.g. when a rollout is retried), must
return finite values of the promised shape (non-finite or impossibly fast waypoints are
recorded as a controller fault like any policy's), and holds its own weights (the policy's
``params`` are empty).  Not differentiable: gradients do not flow through a host call.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.base import Policy
from lantern_jax.policies.features import action_to_waypoints
from lantern_jax.types.observation import FRONT_CAMERA, Observation

HostFn = Callable[[Any], np.ndarray]


def _batched_call(
    name: str,
    fn: HostFn,
    base_ndims: list[int],
    out_shape: tuple[int, ...],
    carry_spec: Any = None,
):
    """The callback: flatten the vmapped leading axes into one batch, call ``fn``, restore them.

    ``broadcast_all`` hands every argument with the same leading (vmapped) axes in front of the
    unit batch axis :func:`host_act` adds; ``base_ndims`` are the ranks of one execution's
    arguments, so the leading axes (vmapped ones and the unit axis) are what precedes them.
    With ``carry_spec`` (one execution's carry, as shape/dtype structs) the argument is
    ``(input, carry)`` and ``fn`` returns ``(output, new carry)``.
    """

    def call(tree):
        leaves, treedef = jax.tree.flatten(tree)
        lead = leaves[0].shape[: leaves[0].ndim - base_ndims[0]]
        n = int(np.prod(lead)) if lead else 1
        flat = [np.asarray(x).reshape((n, *x.shape[len(lead) :])) for x in leaves]
        got = fn(*jax.tree.unflatten(treedef, flat)) if carry_spec is not None else None
        out = np.asarray(fn(jax.tree.unflatten(treedef, flat)) if got is None else got[0])
        if out.shape != (n, *out_shape):
            raise ValueError(
                f"host policy {name!r} returned shape {out.shape} for a batch of {n}; "
                f"expected {(n, *out_shape)}"
            )
        out = out.astype(np.float32).reshape((*lead, *out_shape))
        if carry_spec is None:
            return out

        def back(spec, x):
            x = np.asarray(x)
            if x.shape != (n, *spec.shape):
                raise ValueError(
                    f"host policy {name!r} returned a carry leaf of shape {x.shape} for a batch "
                    f"of {n}; expected {(n, *spec.shape)}"
                )
            return x.astype(spec.dtype).reshape((*lead, *spec.shape))

        return out, jax.tree.map(back, carry_spec, got[1])

    return call


def host_act(
    name: str,
    fn: HostFn,
    out_shape: tuple[int, ...] = (NUM_WAYPOINTS, 2),
    preprocess: Callable[[Observation], Any] | None = None,
    postprocess: Callable[[jax.Array, Observation], jax.Array] | None = None,
    carry: Any = None,
):
    """The act function of a host policy (see the module docstring for the arguments):
    ``act(params, obs)``, or with ``carry`` ``act(params, carry, obs) -> (waypoints, carry)``."""
    carry_spec = None
    if carry is not None:
        carry_spec = jax.tree.map(lambda c: jax.ShapeDtypeStruct(np.shape(c), np.asarray(c).dtype),
                                  carry)  # fmt: skip

    def run(x, c, obs):
        tree = x if c is None else (x, c)
        base = [jnp.ndim(leaf) for leaf in jax.tree.leaves(tree)]
        # A unit batch axis of our own: the model always sees (B, ...), vmapped or not.
        x1 = jax.tree.map(lambda leaf: jnp.asarray(leaf)[None], tree)
        result = jax.ShapeDtypeStruct((1, *out_shape), jnp.float32)
        if carry_spec is not None:
            unit = jax.tree.map(lambda s: jax.ShapeDtypeStruct((1, *s.shape), s.dtype), carry_spec)
            result = (result, unit)
        call = _batched_call(name, fn, base, out_shape, carry_spec)
        got = jax.pure_callback(call, result, x1, vmap_method="broadcast_all")
        y, new_c = (got, None) if carry_spec is None else got
        y = y[0] if postprocess is None else postprocess(y[0], obs)
        return y, (None if new_c is None else jax.tree.map(lambda v: v[0], new_c))

    if carry_spec is None:

        def act(params: Any, obs: Observation) -> jax.Array:
            del params
            return run(obs if preprocess is None else preprocess(obs), None, obs)[0]

        return act

    def act_with_carry(params: Any, c: Any, obs: Observation) -> tuple[jax.Array, Any]:
        del params
        return run(obs if preprocess is None else preprocess(obs), c, obs)

    return act_with_carry


def host_policy(
    name: str,
    fn: HostFn,
    out_shape: tuple[int, ...] = (NUM_WAYPOINTS, 2),
    preprocess: Callable[[Observation], Any] | None = None,
    postprocess: Callable[[jax.Array, Observation], jax.Array] | None = None,
    description: str = "",
    sensors: tuple[str, ...] = (FRONT_CAMERA,),
    carry: Any = None,
) -> Policy:
    """A :class:`Policy` whose model runs on the host (see the module docstring).

    Args:
        name: policy name.
        fn: the model, ``fn(batch) -> (B, *out_shape)`` NumPy array; with ``carry``,
            ``fn(batch, carry_batch) -> (outputs, new_carry_batch)``.
        out_shape: the model's output shape per execution.
        preprocess: jittable ``observation -> model input`` for one execution.
        postprocess: jittable ``(model output, observation) -> (10, 2)`` waypoints.
        description: shown by ``lantern-jax policies``.
        sensors: what the model reads (:data:`~lantern_jax.types.observation.SENSORS`).
        carry: one execution's initial carry (pytree of arrays), for a model with memory.
    """
    act = host_act(name, fn, out_shape, preprocess, postprocess, carry)
    init_carry = None
    if carry is not None:
        init_carry = host_carry(carry)
    return Policy(name, lambda key: {}, act, description or f"host model {name}",
                  sensors=sensors, init_carry=init_carry)  # fmt: skip


def host_carry(carry: Any) -> Callable[[Any], Any]:
    """``init_carry`` of a host policy: the fixed initial carry, whatever the parameters."""
    arrays = jax.tree.map(np.asarray, carry)

    def init_carry(params: Any) -> Any:
        del params
        return jax.tree.map(jnp.asarray, arrays)

    return init_carry


def actions_to_waypoints(action: jax.Array, obs: Observation) -> jax.Array:
    """``postprocess`` for models that output the two-number action of
    :mod:`lantern_jax.policies.features` (acceleration, curvature in [-1, 1])."""
    return action_to_waypoints(action, obs.ego_speed)
