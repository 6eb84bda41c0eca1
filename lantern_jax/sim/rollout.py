"""Closed-loop rollouts: one execution with ``lax.scan``, a batch with ``vmap`` outside.

Two drivers:

* :func:`rollout` — a fixed-horizon ``lax.scan`` of one execution; differentiable end to end
  and able to record the full trajectory (``record=True``) for plots.  Memory stays flat when
  ``record`` is False (the telemetry accumulators are all that is kept).
* :func:`rollout_batch` — the evaluation driver: a ``lax.while_loop`` over chunks of scanned
  ticks for a whole batch, which stops as soon as every execution has ended (finished
  executions are frozen by their ``done`` mask).  Not reverse-differentiable (while loop); use
  :func:`rollout` under ``vmap`` for gradients.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.constants import DT
from lantern_jax.sim.step import (
    SimState,
    TickRecord,
    from_carry,
    init_state,
    tick_carry,
    to_carry,
)
from lantern_jax.world import World

Array = jax.Array
ActFn = Callable[[Any, Any], Array]


def horizon_ticks(seconds: float) -> int:
    """Number of 20 Hz ticks covering ``seconds``."""
    return int(round(seconds / DT))


def rollout(
    world: World,
    act: ActFn,
    params: Any,
    num_ticks: int,
    record: bool = False,
    temperature: float | Array = 0.05,
) -> tuple[SimState, TickRecord | None]:
    """Roll one execution forward for ``num_ticks`` ticks (frozen once it has ended).

    Args:
        world: the initial world of one execution.
        act: policy ``act(params, obs) -> (10, 2)``.
        params: policy parameters.
        num_ticks: static horizon.
        record: also return the per-tick :class:`TickRecord` (leading axis ``num_ticks``).
        temperature: soft-score temperature for the smooth telemetry accumulators.

    Returns:
        (final carry, records or None).
    """
    temperature = jnp.asarray(temperature, jnp.float32)

    def body(carry, _):
        new, rec = tick_carry(act, params, world, carry, temperature)
        return new, (rec if record else None)

    final, recs = jax.lax.scan(body, to_carry(init_state(world)), None, length=num_ticks)
    return from_carry(world, final), recs


def rollout_batch(
    worlds: World,
    act: ActFn,
    params: Any,
    max_ticks: int,
    chunk: int = 40,
    temperature: float | Array = 0.05,
    start: SimState | None = None,
) -> SimState:
    """Roll a batch of executions (leading axis on every leaf) until all have ended.

    Args:
        worlds: batched initial worlds, (B, ...) leaves.
        act: policy ``act(params, obs)`` for ONE scenario; it is vmapped here.
        params: policy parameters shared by the batch.
        max_ticks: static upper bound of the horizon (rounded up to whole chunks).
        chunk: ticks per scanned chunk between checks of the batch's ``done`` mask.
        temperature: soft-score temperature.
        start: continue these batched states (from an earlier call) instead of starting at
            ``worlds``' initial state.

    Returns:
        The batched final carry.
    """
    temperature = jnp.asarray(temperature, jnp.float32)
    n_chunks = -(-max_ticks // chunk)

    def run_chunk(world: World, carry):
        def body(c, _):
            return tick_carry(act, params, world, c, temperature)[0], None

        return jax.lax.scan(body, carry, None, length=chunk)[0]

    batched_chunk = jax.vmap(run_chunk)

    def cond(loop):
        i, carry = loop
        return (i < n_chunks) & ~jnp.all(carry.done)

    def body(loop):
        i, carry = loop
        return i + 1, batched_chunk(worlds, carry)

    if start is None:
        carry0 = jax.vmap(lambda w: to_carry(init_state(w)))(worlds)
    else:
        carry0 = jax.vmap(to_carry)(start)
    _, final = jax.lax.while_loop(cond, body, (jnp.asarray(0, jnp.int32), carry0))
    return jax.vmap(from_carry)(worlds, final)


def rollout_batch_parallel(
    worlds: World,
    act: ActFn,
    params: Any,
    max_ticks: int,
    chunk: int = 40,
    temperature: float | Array = 0.05,
    start: SimState | None = None,
) -> SimState:
    """:func:`rollout_batch` split over all local devices (e.g. the CPU cores exposed with
    ``--xla_force_host_platform_device_count``), each shard stopping independently.

    The batch is padded to a multiple of the device count with copies of its first execution
    and cut back afterwards; every execution is independent, so results do not depend on the
    split.  With one device this is :func:`rollout_batch`.
    """
    n_dev = jax.device_count()
    if n_dev == 1:
        return rollout_batch(worlds, act, params, max_ticks, chunk, temperature, start)
    from jax.sharding import PartitionSpec

    n = jax.tree.leaves(worlds)[0].shape[0]
    pad = (-n) % n_dev
    def pad_tree(tree):
        return jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), tree)

    if pad:
        worlds = pad_tree(worlds)
        start = None if start is None else pad_tree(start)
    mesh = jax.make_mesh((n_dev,), ("batch",), axis_types=(jax.sharding.AxisType.Auto,))
    spec = jax.sharding.NamedSharding(mesh, PartitionSpec("batch"))
    worlds = jax.lax.with_sharding_constraint(worlds, spec)
    if start is not None:
        start = jax.lax.with_sharding_constraint(start, spec)
    run = jax.shard_map(
        lambda w, s: rollout_batch(w, act, params, max_ticks, chunk, temperature, s),
        mesh=mesh,
        in_specs=(PartitionSpec("batch"), PartitionSpec("batch") if start is not None else None),
        out_specs=PartitionSpec("batch"),
        check_vma=False,
    )
    final = run(worlds, start)
    return jax.tree.map(lambda x: x[:n], final)
