"""Closed-loop rollouts: one execution with ``lax.scan``, a batch with ``vmap`` outside.

The scan carries only the dynamic :class:`~lantern_jax.sim.state.State`; the static
:class:`~lantern_jax.types.world.Scenario` is closed over (one execution) or vmapped alongside.

Two drivers:

* :func:`rollout` — a fixed-horizon ``lax.scan`` of one execution; differentiable end to end
  and able to record the full trajectory (``record=True``) for plots.  Memory stays flat when
  ``record`` is False (the telemetry accumulators are all that is kept).
* :func:`rollout_batch` — the evaluation driver: a ``lax.while_loop`` over chunks of scanned
  ticks for a whole batch, which stops as soon as every execution has ended (finished
  executions are frozen by their ``done`` mask).  Not reverse-differentiable (while loop); use
  :func:`rollout` under ``vmap`` for gradients.
* :func:`rollout_scheduled` — the evaluation driver for large batches: a fixed number of
  *slots* is stepped in chunks of scanned ticks, and after each chunk a slot whose execution
  has ended takes the next waiting one, inside the same ``lax.while_loop`` (no return to the
  host), so the batch never waits in lockstep behind its longest executions.
  :func:`rollout_scheduled_parallel` runs one such scheduler per device.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.sharding import PartitionSpec

from lantern_jax.core.times import ticks
from lantern_jax.sim.distributed import batch_mesh
from lantern_jax.sim.record import TickRecord
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.state import State, init_state
from lantern_jax.sim.step import Driver, step
from lantern_jax.types.world import Scenario

Array = jax.Array


def start_state(
    scenario: Scenario, policy: Driver, policy_params: Any, settings: Settings = DEFAULT_SETTINGS
) -> State:
    """The state of one execution at ``t = 0`` with the policy's initial carry."""
    return init_state(scenario, policy.initial_carry(policy_params), settings.scoring)


def with_carry(states: State, policy: Driver, policy_params: Any) -> State:
    """Batched start states (from ``vmap(init_state)``, no carry) given the policy's initial
    carry in every execution."""
    n = states.t.shape[0]
    carry = policy.initial_carry(policy_params)
    return states.replace(
        policy_carry=jax.tree.map(lambda c: jnp.broadcast_to(c, (n, *jnp.shape(c))), carry)
    )


#: Number of 20 Hz ticks of a horizon of ``seconds`` (:func:`lantern_jax.core.times.ticks`; the
#: name kept for the public API).
horizon_ticks = ticks


def rollout(
    scenario: Scenario,
    policy: Driver,
    policy_params: Any,
    num_ticks: int,
    record: bool = False,
    settings: Settings = DEFAULT_SETTINGS,
    remat: bool = False,
) -> tuple[State, TickRecord | None]:
    """Roll one execution forward for ``num_ticks`` ticks (frozen once it has ended).

    Args:
        scenario: the execution's static scenario (closed over by the scan).
        policy: the :class:`~lantern_jax.policies.base.Policy` (its sensors decide what it
            observes; its carry starts from ``init_carry``).
        policy_params: policy parameters.
        num_ticks: static horizon.
        record: also return the per-tick :class:`TickRecord` (leading axis ``num_ticks``).
        settings: scoring, protocol and text bank (:class:`~lantern_jax.sim.settings.Settings`;
            the soft-score temperature is ``settings.scoring.temperature``).
        remat: recompute each tick's internals in the backward pass instead of storing them
            (``jax.checkpoint``): reverse-mode memory then grows with the carried state only,
            for a second forward pass of compute.

    Returns:
        (final state, records or None).
    """

    def body(state, _):
        new, rec = step(policy, policy_params, scenario, state, settings)
        return new, (rec if record else None)

    if remat:
        body = jax.checkpoint(body)

    start = start_state(scenario, policy, policy_params, settings)
    return jax.lax.scan(body, start, None, length=num_ticks)


def chunk_runner(
    policy: Driver, policy_params: Any, chunk: int, settings: Settings
) -> Callable[[Scenario, State], State]:
    """``run_chunk(scenario, state)``: ``chunk`` scanned ticks of ONE execution (the scan
    carries the state; the scenario is closed over, so its tick-invariant work is hoisted)."""

    def run_chunk(scenario: Scenario, state: State) -> State:
        def body(s, _):
            return step(policy, policy_params, scenario, s, settings)[0], None

        return jax.lax.scan(body, state, None, length=chunk)[0]

    return run_chunk


def on_every_device(fn: Callable[..., Any], *batched: Any) -> Any:
    """``fn(*blocks)`` on every device of :func:`batch_mesh`, each device given its block of
    the leading (batch) axis of every argument (``None`` arguments stay ``None``); the results'
    blocks are joined along the batch axis.  No communication: each device runs on its own.
    The batch must divide by the device count."""

    mesh = batch_mesh()  # every device of every process (lantern_jax.sim.distributed)
    spec = jax.sharding.NamedSharding(mesh, PartitionSpec("batch"))
    batched = tuple(
        None if x is None else jax.lax.with_sharding_constraint(x, spec) for x in batched
    )
    run = jax.shard_map(
        fn,
        mesh=mesh,
        in_specs=tuple(None if x is None else PartitionSpec("batch") for x in batched),
        out_specs=PartitionSpec("batch"),
        check_vma=False,
    )
    return run(*batched)


def rollout_batch(
    scenarios: Scenario,
    policy: Driver,
    policy_params: Any,
    max_ticks: int | Array,
    chunk: int = 40,
    settings: Settings = DEFAULT_SETTINGS,
    start: State | None = None,
) -> State:
    """Roll a batch of executions (leading axis on every leaf) until all have ended.

    Args:
        scenarios: batched scenarios, (B, ...) leaves.
        policy: the policy (or a policy switch), written for ONE scenario; it is vmapped here.
        policy_params: policy parameters shared by the batch.
        max_ticks: upper bound of the horizon (rounded up to whole chunks): a Python int, or a
            traced int32 scalar, so that one compiled program serves every horizon.
        chunk: ticks per scanned chunk between checks of the batch's ``done`` mask.
        settings: scoring, protocol and text bank.
        start: continue these batched states (from an earlier call) instead of starting at
            the scenarios' initial state.

    Returns:
        The batched final states.
    """
    n_chunks = -(-max_ticks // chunk)
    batched_chunk = jax.vmap(chunk_runner(policy, policy_params, chunk, settings))

    def cond(loop):
        i, states = loop
        return (i < n_chunks) & ~jnp.all(states.done)

    def body(loop):
        i, states = loop
        return i + 1, batched_chunk(scenarios, states)

    if start is None:
        starts = jax.vmap(lambda sc: init_state(sc, (), settings.scoring))(scenarios)
        start = with_carry(starts, policy, policy_params)
    states = start
    return jax.lax.while_loop(cond, body, (jnp.asarray(0, jnp.int32), states))[1]


def rollout_batch_parallel(
    scenarios: Scenario,
    policy: Driver,
    policy_params: Any,
    max_ticks: int | Array,
    chunk: int = 40,
    settings: Settings = DEFAULT_SETTINGS,
    start: State | None = None,
) -> State:
    """:func:`rollout_batch` split over all local devices (e.g. the CPU cores exposed with
    ``--xla_force_host_platform_device_count``), each shard stopping independently.

    The batch is padded to a multiple of the device count with copies of its first execution
    and cut back afterwards; every execution is independent, so results do not depend on the
    split.  With one device this is :func:`rollout_batch`.
    """
    n_dev = jax.device_count()
    if n_dev == 1:
        return rollout_batch(scenarios, policy, policy_params, max_ticks, chunk, settings, start)
    n = jax.tree.leaves(scenarios)[0].shape[0]
    pad = (-n) % n_dev

    def pad_tree(tree):
        return jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), tree)

    if pad:
        scenarios = pad_tree(scenarios)
        start = None if start is None else pad_tree(start)
    final = on_every_device(
        lambda sc, s: rollout_batch(sc, policy, policy_params, max_ticks, chunk, settings, s),
        scenarios,
        start,
    )
    return jax.tree.map(lambda x: x[:n], final)


def _take(tree: Any, idx: Array) -> Any:
    return jax.tree.map(lambda x: x[idx], tree)


def scheduled_map(
    advance: Callable[[Any, Any], Any],
    ended: Callable[[Any], Array],
    items: Any,
    starts: Any,
    slots: int,
) -> Any:
    """Run every item's state to its end through ``slots`` slots, refilled as items end.

    Slot ``i`` starts with item ``i``; the others wait in index order.  Every loop step
    applies ``advance`` to every slot whose item has not ended (vmapped; an ended item's
    state is kept as it is), keeps each slot's state as its item's latest, and gives every
    slot whose item has ended the next waiting item, starting from its state in ``starts``;
    ended slots are refilled in slot order.  The loop stops when every slot's item has ended
    and none is waiting.

    Args:
        advance: ``advance(item, state) -> state`` for ONE item (one loop step of it).
        ended: ``ended(states) -> (S,) bool`` for the slots' batched states.
        items: (n, ...) pytree, the items' fixed data.
        starts: (n, ...) pytree, the items' initial states.
        slots: static, items stepped together (1 <= slots <= n).

    Returns:
        (n, ...) the final states, in the order of ``items``.
    """
    n = jax.tree.leaves(items)[0].shape[0]
    if not 1 <= slots <= n:
        raise ValueError(f"scheduled_map: slots must be in 1..{n} (the batch), got {slots}")

    def where(mask, a, b):  # per-slot choice between two batched states
        return jax.tree.map(lambda x, y: jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)),
                                                   x, y), a, b)  # fmt: skip

    def cond(loop):
        return ~jnp.all(ended(loop[1]))

    def body(loop):
        running, states, final, waiting = loop  # (S,) int32, (S,) states, (n,) states, () int32
        states = where(ended(states), states, jax.vmap(advance)(_take(items, running), states))
        final = jax.tree.map(lambda f, x: f.at[running].set(x), final, states)
        over = ended(states)
        following = waiting + jnp.cumsum(over.astype(jnp.int32)) - 1
        refill = over & (following < n)
        running = jnp.where(refill, following, running)
        states = where(refill, _take(starts, running), states)
        return running, states, final, waiting + jnp.sum(refill.astype(jnp.int32))

    running = jnp.arange(slots, dtype=jnp.int32)
    loop = (running, _take(starts, running), starts, jnp.asarray(slots, jnp.int32))
    return jax.lax.while_loop(cond, body, loop)[2]


def rollout_scheduled(
    scenarios: Scenario,
    starts: State,
    policy: Driver,
    policy_params: Any,
    max_ticks: int | Array,
    slots: int,
    chunk: int = 40,
    settings: Settings = DEFAULT_SETTINGS,
) -> State:
    """Roll ``n`` executions through ``slots`` slots until every one has ended
    (:func:`scheduled_map` with ``chunk`` scanned ticks per loop step).

    Slot ``i`` starts with execution ``i``; the others wait in index order (the caller orders
    them, e.g. longest first).  An execution has ended when it is ``done`` or has stepped
    ``max_ticks`` ticks.  An execution's ticks are those of :func:`rollout_batch`: only which
    executions share a chunk differs.

    Args:
        scenarios: (n, ...) batched scenarios.
        starts: (n, ...) their states to start from (e.g. :func:`with_carry` of
            ``vmap(init_state)(scenarios)``); a slot that takes the next execution takes its
            start state, the policy's initial carry included.
        policy: the policy (or a policy switch), written for ONE scenario; it is vmapped here.
        policy_params: policy parameters shared by the batch.
        max_ticks: horizon (rounded up to whole chunks); a Python int or a traced int32
            scalar.
        slots: static, executions stepped together (1 <= slots <= n).
        chunk: static, ticks per loop step.
        settings: scoring, protocol and text bank.

    Returns:
        (n, ...) the final states, in the order of ``scenarios``.
    """
    max_ticks = jnp.asarray(max_ticks, jnp.int32)

    def ended(states: State) -> Array:
        return states.done | (states.tick >= max_ticks)

    run_chunk = chunk_runner(policy, policy_params, chunk, settings)
    return scheduled_map(run_chunk, ended, scenarios, starts, slots)


def rollout_scheduled_parallel(
    scenarios: Scenario,
    starts: State,
    policy: Driver,
    policy_params: Any,
    max_ticks: int | Array,
    slots: int,
    chunk: int = 40,
    settings: Settings = DEFAULT_SETTINGS,
) -> State:
    """:func:`rollout_scheduled` on every device of :func:`batch_mesh`, each with its own
    scheduler over its own block of the batch (no communication; each stops on its own).

    The batch must divide by the device count: device ``d`` runs executions
    ``d * n / D .. (d + 1) * n / D - 1`` with ``slots`` slots of its own (the caller deals the
    executions so that every block is a similar mix).  With one device this is
    :func:`rollout_scheduled`.
    """
    if jax.device_count() == 1:
        return rollout_scheduled(
            scenarios, starts, policy, policy_params, max_ticks, slots, chunk, settings
        )
    return on_every_device(
        lambda sc, st: rollout_scheduled(
            sc, st, policy, policy_params, max_ticks, slots, chunk, settings
        ),
        scenarios,
        starts,
    )
