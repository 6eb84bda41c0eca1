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
from lantern_jax.sim.step import SimState, TickRecord, init_state, tick
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

    def body(state, _):
        new, rec = tick(act, params, state, temperature)
        return new, (rec if record else None)

    final, recs = jax.lax.scan(body, init_state(world), None, length=num_ticks)
    return final, recs


def rollout_batch(
    worlds: World,
    act: ActFn,
    params: Any,
    max_ticks: int,
    chunk: int = 40,
    temperature: float | Array = 0.05,
) -> SimState:
    """Roll a batch of executions (leading axis on every leaf) until all have ended.

    Args:
        worlds: batched initial worlds, (B, ...) leaves.
        act: policy ``act(params, obs)`` for ONE scenario; it is vmapped here.
        params: policy parameters shared by the batch.
        max_ticks: static upper bound of the horizon (rounded up to whole chunks).
        chunk: ticks per scanned chunk between checks of the batch's ``done`` mask.
        temperature: soft-score temperature.

    Returns:
        The batched final carry.
    """
    temperature = jnp.asarray(temperature, jnp.float32)
    n_chunks = -(-max_ticks // chunk)

    def run_chunk(state: SimState) -> SimState:
        def body(s, _):
            return tick(act, params, s, temperature)[0], None

        return jax.lax.scan(body, state, None, length=chunk)[0]

    batched_chunk = jax.vmap(run_chunk)

    def cond(carry):
        i, state = carry
        return (i < n_chunks) & ~jnp.all(state.done)

    def body(carry):
        i, state = carry
        return i + 1, batched_chunk(state)

    state0 = jax.vmap(init_state)(worlds)
    _, final = jax.lax.while_loop(cond, body, (jnp.asarray(0, jnp.int32), state0))
    return final
