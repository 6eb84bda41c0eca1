"""Closed-loop rollouts: one execution with ``lax.scan``, a batch with ``vmap`` outside.

The scan carries only the dynamic :class:`~lantern_jax.sim.state.State`; the static
:class:`~lantern_jax.world.Scenario` is closed over (one execution) or vmapped alongside.

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
from lantern_jax.sim.distributed import batch_mesh
from lantern_jax.sim.record import TickRecord
from lantern_jax.sim.state import State, init_state
from lantern_jax.sim.step import step
from lantern_jax.world import Scenario

Array = jax.Array
ActFn = Callable[[Any, Any], Array]


def horizon_ticks(seconds: float) -> int:
    """Number of 20 Hz ticks covering ``seconds``."""
    return int(round(seconds / DT))


def rollout(
    scenario: Scenario,
    act: ActFn,
    policy_params: Any,
    num_ticks: int,
    record: bool = False,
    temperature: float | Array = 0.05,
    remat: bool = False,
    privileged: bool = False,
) -> tuple[State, TickRecord | None]:
    """Roll one execution forward for ``num_ticks`` ticks (frozen once it has ended).

    Args:
        scenario: the execution's static scenario (closed over by the scan).
        act: policy ``act(policy_params, obs) -> (10, 2)``.
        policy_params: policy parameters.
        num_ticks: static horizon.
        record: also return the per-tick :class:`TickRecord` (leading axis ``num_ticks``).
        temperature: soft-score temperature for the smooth telemetry accumulators.
        remat: recompute each tick's internals in the backward pass instead of storing them
            (``jax.checkpoint``): reverse-mode memory then grows with the carried state only,
            for a second forward pass of compute.
        privileged: static; fill ``obs.privileged`` for a privileged policy
            (``Policy.privileged``, e.g. the ``expert``).

    Returns:
        (final state, records or None).
    """
    temperature = jnp.asarray(temperature, jnp.float32)

    def body(state, _):
        new, rec = step(act, policy_params, scenario, state, temperature, privileged)
        return new, (rec if record else None)

    if remat:
        body = jax.checkpoint(body)

    return jax.lax.scan(body, init_state(scenario), None, length=num_ticks)


def rollout_batch(
    scenarios: Scenario,
    act: ActFn,
    policy_params: Any,
    max_ticks: int | Array,
    chunk: int = 40,
    temperature: float | Array = 0.05,
    start: State | None = None,
    privileged: bool = False,
) -> State:
    """Roll a batch of executions (leading axis on every leaf) until all have ended.

    Args:
        scenarios: batched scenarios, (B, ...) leaves.
        act: policy ``act(policy_params, obs)`` for ONE scenario; it is vmapped here.
        policy_params: policy parameters shared by the batch.
        max_ticks: upper bound of the horizon (rounded up to whole chunks): a Python int, or a
            traced int32 scalar, so that one compiled program serves every horizon.
        chunk: ticks per scanned chunk between checks of the batch's ``done`` mask.
        temperature: soft-score temperature.
        start: continue these batched states (from an earlier call) instead of starting at
            the scenarios' initial state.
        privileged: static; fill ``obs.privileged`` (``Policy.privileged``).

    Returns:
        The batched final states.
    """
    temperature = jnp.asarray(temperature, jnp.float32)
    n_chunks = -(-max_ticks // chunk)

    def run_chunk(scenario: Scenario, state: State) -> State:
        def body(s, _):
            return step(act, policy_params, scenario, s, temperature, privileged)[0], None

        return jax.lax.scan(body, state, None, length=chunk)[0]

    batched_chunk = jax.vmap(run_chunk)

    def cond(loop):
        i, states = loop
        return (i < n_chunks) & ~jnp.all(states.done)

    def body(loop):
        i, states = loop
        return i + 1, batched_chunk(scenarios, states)

    states = jax.vmap(init_state)(scenarios) if start is None else start
    return jax.lax.while_loop(cond, body, (jnp.asarray(0, jnp.int32), states))[1]


def rollout_batch_parallel(
    scenarios: Scenario,
    act: ActFn,
    policy_params: Any,
    max_ticks: int | Array,
    chunk: int = 40,
    temperature: float | Array = 0.05,
    start: State | None = None,
    privileged: bool = False,
) -> State:
    """:func:`rollout_batch` split over all local devices (e.g. the CPU cores exposed with
    ``--xla_force_host_platform_device_count``), each shard stopping independently.

    The batch is padded to a multiple of the device count with copies of its first execution
    and cut back afterwards; every execution is independent, so results do not depend on the
    split.  With one device this is :func:`rollout_batch`.
    """
    n_dev = jax.device_count()
    if n_dev == 1:
        return rollout_batch(
            scenarios, act, policy_params, max_ticks, chunk, temperature, start, privileged
        )
    from jax.sharding import PartitionSpec

    n = jax.tree.leaves(scenarios)[0].shape[0]
    pad = (-n) % n_dev

    def pad_tree(tree):
        return jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), tree)

    if pad:
        scenarios = pad_tree(scenarios)
        start = None if start is None else pad_tree(start)
    mesh = batch_mesh()  # every device of every process (lantern_jax.sim.distributed)
    spec = jax.sharding.NamedSharding(mesh, PartitionSpec("batch"))
    scenarios = jax.lax.with_sharding_constraint(scenarios, spec)
    if start is not None:
        start = jax.lax.with_sharding_constraint(start, spec)
    run = jax.shard_map(
        lambda sc, s: rollout_batch(
            sc, act, policy_params, max_ticks, chunk, temperature, s, privileged
        ),
        mesh=mesh,
        in_specs=(PartitionSpec("batch"), PartitionSpec("batch") if start is not None else None),
        out_specs=PartitionSpec("batch"),
        check_vma=False,
    )
    final = run(scenarios, start)
    return jax.tree.map(lambda x: x[:n], final)
