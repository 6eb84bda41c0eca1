"""Large workloads (100,000 executions and more) in chunks, with flat memory and a progress bar.

A workload is a *source* — a function from execution ids to a batch of scenarios — and a
count.  :func:`stream_executions` builds one chunk at a time, runs it with the evaluator's
rollout (:func:`lantern_jax.apps.evaluation.run_executions`: refilled slots, all local devices, or
the global mesh under JAX's distributed runtime), keeps only the per-execution outputs of
:func:`~lantern_jax.scoring.metrics.finalize` (about 40 numbers per execution) and drops the
chunk's scenarios and states before the next one.  Every chunk has the same shape (the last
one is padded), so the rollout compiles once; memory is one chunk plus the outputs, whatever
the count.  Execution ``i``'s result depends only on the source and ``i`` (not on the chunk
size), up to the float32 rounding of a differently shaped program
(:data:`lantern_jax.scoring.table.REPRODUCIBLE_ATOL`).

:func:`stress_source` is the built-in stress batch: the executions of a suite, cycled, each
copy with its hazard perturbed by a counter-based random draw (:data:`STRESS_RANGES`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import SUITE_ID
from lantern_jax.core.progress import tqdm
from lantern_jax.core.times import ticks_covering
from lantern_jax.scenarios.knobs import get_knobs, set_knobs
from lantern_jax.scenarios.suite import Suite, load_suite
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.engine import build_executions, run_executions
from lantern_jax.types.world import Scenario

Source = Callable[[np.ndarray], Scenario]

#: Stress perturbation of every copy: the hazard's speed scaled by a factor in this range and
#: its trigger delayed by this many seconds (uniform draws keyed by the execution id).
STRESS_RANGES = {"hazard_speed_factor": (0.8, 1.25), "hazard_delay_add_s": (0.0, 0.5)}


def stress_source(suite: Suite | str = SUITE_ID, seed: int = 0, ablation: str = "none"):
    """Execution ``i`` = the suite's execution ``i mod (3 * pairs)`` (the order of
    :class:`~lantern_jax.sim.engine.Executions`) with its hazard perturbed
    (:data:`STRESS_RANGES`), drawn from ``fold_in(PRNGKey(seed), i)``; copy 0 of every execution
    (``i < 3 * pairs``) is unperturbed.

    Returns:
        ``(source, max_ticks, base_count)``: the source, the static horizon covering every
        execution, the number of distinct base executions.
    """
    s = load_suite(suite) if isinstance(suite, str) else suite
    execs = build_executions(s, ablation)
    base = execs.scenarios
    n_base = execs.num_executions
    (lo_f, hi_f), (lo_d, hi_d) = STRESS_RANGES.values()

    def one(i: jax.Array) -> Scenario:
        sc = jax.tree.map(lambda x: x[i % n_base], base)
        u = jax.random.uniform(jax.random.fold_in(jax.random.PRNGKey(seed), i), (2,))
        first = i < n_base
        factor = jnp.where(first, 1.0, lo_f + (hi_f - lo_f) * u[0])
        delay = jnp.where(first, 0.0, lo_d + (hi_d - lo_d) * u[1])
        k = get_knobs(sc, ("hazard_speed", "hazard_delay"))
        return set_knobs(
            sc, hazard_speed=k["hazard_speed"] * factor, hazard_delay=k["hazard_delay"] + delay
        )

    make = jax.jit(jax.vmap(one))
    slack = ticks_covering(hi_d)  # a later trigger may need more ticks
    return (lambda ids: make(jnp.asarray(ids, jnp.int32))), execs.max_ticks + slack, n_base


@jax.jit
def _finalize(states) -> Any:
    return finalize(states.telemetry)


def _flat(out: dict[str, Any]) -> dict[str, Any]:
    """Per-execution arrays by name: a tuple value (``ExecutionMetrics.metrics``, the user
    metrics' values) becomes one entry per element, ``name[i]``."""
    flat: dict[str, Any] = {}
    for name, value in out.items():
        if isinstance(value, tuple):
            flat.update({f"{name}[{i}]": v for i, v in enumerate(value)})
        else:
            flat[name] = value
    return flat


@dataclasses.dataclass
class StreamResult:
    """Per-execution outputs of a streamed workload."""

    metrics: dict[str, np.ndarray]  # what ``collect`` keeps (ExecutionMetrics), (count, ...)
    seconds_compile: float
    seconds_total: float
    chunks: int


def stream_executions(
    policy,
    policy_params: Any,
    source: Source,
    count: int,
    max_ticks: int,
    chunk: int = 4096,
    progress: bool = True,
    collect: Callable[[Any], Any] | None = None,
) -> StreamResult:
    """Run ``count`` executions from ``source`` in chunks of ``chunk``; keep their outputs.

    Args:
        policy: the :class:`~lantern_jax.policies.base.Policy` (one execution).
        policy_params: its parameters.
        source: ``source(ids: (chunk,) int) -> Scenario`` with a leading ``chunk`` axis.
        count: number of executions.
        max_ticks: static horizon (covers every execution).
        chunk: executions per chunk (the last one is padded with copies of its first id).
        progress: show a progress bar (executions).
        collect: what to keep of a chunk's final states: ``collect(states)`` -> a flat
            dataclass or dict of per-execution arrays (default: ``finalize`` of the telemetry,
            the :class:`~lantern_jax.scoring.metrics.ExecutionMetrics`).
    """
    metrics: dict[str, np.ndarray] = {}
    t0, t_compile, n_chunks = time.perf_counter(), 0.0, 0
    bar = None
    if progress:
        bar = tqdm(total=count, unit="exec", desc="executions", smoothing=0.1)
    try:
        for start in range(0, count, chunk):
            ids = np.arange(start, min(start + chunk, count))
            padded = np.concatenate([ids, np.full(chunk - len(ids), ids[0])])
            final, tc = run_executions(policy, source(padded), policy_params, max_ticks)
            out = (collect or _finalize)(final)
            if dataclasses.is_dataclass(out):
                out = {f.name: getattr(out, f.name) for f in dataclasses.fields(out)}
            for name, value in _flat(out).items():
                col = np.asarray(value)[: len(ids)]
                if name not in metrics:
                    metrics[name] = np.empty((count, *col.shape[1:]), col.dtype)
                metrics[name][start : start + len(ids)] = col
            t_compile += tc if n_chunks == 0 else 0.0
            n_chunks += 1
            if bar is not None:
                bar.update(len(ids))
    finally:
        if bar is not None:
            bar.close()
    return StreamResult(metrics, t_compile, time.perf_counter() - t0, n_chunks)
