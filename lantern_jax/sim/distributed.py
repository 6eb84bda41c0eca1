"""Where a batch of executions lives: this process's devices, or a global mesh across processes.

With JAX's distributed runtime (``jax.distributed.initialize``: one process per host, each with
its local devices), ``jax.devices()`` lists every device of every process and a jitted batched
rollout runs on a **global mesh**: each process holds and steps only its shard of the batch.
The executions are independent, so the rollout itself needs no communication; only the final
states are gathered (``process_allgather``) so that every process can score the whole batch.

:func:`placement` picks the right pair of functions for the current run:

* one process — the batch stays as it is (the rollout splits it over the local devices
  itself, :func:`lantern_jax.sim.rollout.rollout_scheduled_parallel`);
* several processes — ``put`` builds global arrays sharded along the batch over
  :func:`batch_mesh` (every process builds the same host batch, each process then hands over
  only its own shard: ``jax.make_array_from_callback``), parameters are replicated, and
  ``get`` gathers a result back into ordinary local arrays on every process.

The batch must divide by the global device count (``Placement.multiple``); the evaluation's
layout pads it (:func:`lantern_jax.sim.engine.schedule_layout`).

Before the rollout program runs, every process waits for the others at a barrier of the
distributed runtime's key-value store (``Placement.align``, :func:`wait_for_every_process`).
Without it, two processes on a loaded 2-core machine failed in the program's first collective
("Gloo context initialization failed: ... GetKeyValue() timed out ... 30 s"; XLA's CPU
collectives wait 30 s and JAX exposes no setting for it) in 2 of 2 runs; with it they passed in
2 of 2 (``tests/test_multihost.py`` beside two busy loops, one run each).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

BATCH_AXIS = "batch"
#: s, how long a process waits at a barrier for the others to arrive (another process may still
#: be compiling the program: minutes on a cold cache)
BARRIER_TIMEOUT_S = 3600

_BARRIERS = itertools.count()  # every barrier of a run has its own name, the same on every process


def batch_mesh() -> jax.sharding.Mesh:
    """A 1-D mesh over every device of every process, axis ``"batch"``."""
    return jax.make_mesh(
        (jax.device_count(),), (BATCH_AXIS,), axis_types=(jax.sharding.AxisType.Auto,)
    )


@dataclasses.dataclass(frozen=True)
class Placement:
    """How to hand a batch to the jitted rollout and how to read the result back."""

    put: Callable[[Any], Any]  # batched tree -> its placed version
    replicate: Callable[[Any], Any]  # parameters -> placed on every device
    get: Callable[[Any], Any]  # result -> ordinary arrays of this process (whole batch)
    multiple: int  # the batch given to ``put`` must divide by this
    processes: int
    align: Callable[[str], None]  # wait until every process gets here (wait_for_every_process)


def _identity(tree: Any) -> Any:
    return tree


def wait_for_every_process(what: str) -> None:
    """Under JAX's distributed runtime, block until every process has called this (the
    runtime's key-value store barrier, not a device collective); at once with one process.

    Every process must call it the same number of times, in the same order (as every process
    runs the same evaluation).  ``what`` (a few words) names the point in the barrier's name,
    which a timeout's error message shows.

    Raises:
        jax.errors.JaxRuntimeError: when another process does not arrive within
            :data:`BARRIER_TIMEOUT_S`.
    """
    # deferred, private: JAX's only barrier that is not a device collective (its own
    # checkpointing waits at it the same way)
    from jax._src import distributed

    client = distributed.global_state.client
    if client is None or jax.process_count() == 1:
        return
    name = f"lantern_jax/{next(_BARRIERS)}/{what}"
    client.wait_at_barrier(name, timeout_in_ms=BARRIER_TIMEOUT_S * 1000)


def _global(tree: Any, spec: PartitionSpec) -> Any:
    sharding = NamedSharding(batch_mesh(), spec)

    def make(x):
        host = np.asarray(x)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(make, tree)


def _gather(tree: Any) -> Any:
    # deferred: only in a run of several processes
    from jax.experimental import multihost_utils

    return jax.tree.map(jnp.asarray, multihost_utils.process_allgather(tree, tiled=True))


def placement() -> Placement:
    """The placement for this run (see the module docstring)."""
    if jax.process_count() == 1:
        return Placement(_identity, _identity, _identity, 1, 1, wait_for_every_process)
    return Placement(
        put=lambda tree: _global(tree, PartitionSpec(BATCH_AXIS)),
        replicate=lambda tree: _global(tree, PartitionSpec()),
        get=_gather,
        multiple=jax.device_count(),
        processes=jax.process_count(),
        align=wait_for_every_process,
    )
