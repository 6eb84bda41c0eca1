"""Streaming large workloads: chunking changes nothing, the stress source is keyed by id."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

from lantern_jax.apps.evaluation import run_executions
from lantern_jax.apps.stream import STRESS_RANGES, stream_executions, stress_source
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.knobs import get_knobs
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.table import REPRODUCIBLE_ATOL


@pytest.fixture(scope="module")
def stress():
    return stress_source(load_suite().subset(1), seed=3)  # 6 pairs -> 18 base executions


def test_stress_draws_depend_only_on_the_execution_id(stress):
    source, max_ticks, n_base = stress
    assert n_base == 18 and max_ticks > 0
    a = source(np.array([0, 20, 40, 41]))
    b = source(np.array([41, 20, 3, 2]))
    speed = lambda sc, i: float(get_knobs(jax.tree.map(lambda x: x[i], sc))["hazard_speed"])  # noqa: E731
    assert speed(a, 1) == speed(b, 1) and speed(a, 3) == speed(b, 0)
    # Copy 0 is the suite's execution itself; later copies are perturbed within the range.
    base = source(np.array([0, 18]))  # execution 0 (a pedestrian crossing) and its copy 1
    lo, hi = STRESS_RANGES["hazard_speed_factor"]
    assert speed(base, 0) > 0.0
    ratio = speed(base, 1) / speed(base, 0)
    assert lo <= ratio <= hi and ratio != 1.0


@pytest.mark.slow
def test_chunks_give_the_one_batch_result(stress):
    source, max_ticks, _ = stress
    ego = get_policy("ego")
    params = ego.init(jax.random.PRNGKey(0))
    count = 22  # 3 chunks of 8, the last one padded
    streamed = stream_executions(ego, params, source, count, max_ticks, chunk=8,
                                 progress=False)  # fmt: skip
    assert streamed.chunks == 3
    final, _ = run_executions(ego, source(np.arange(count)), params, max_ticks)
    whole = jax.tree.map(np.asarray, finalize(final.telemetry))
    assert whole.metrics == () and not any(k.startswith("metrics") for k in streamed.metrics)
    for f in dataclasses.fields(whole):
        if f.name == "metrics":  # the user metrics' values: none in the default settings
            continue
        x, y = streamed.metrics[f.name], getattr(whole, f.name)
        assert x.shape == y.shape == (count,), f.name
        if np.issubdtype(y.dtype, np.floating):
            np.testing.assert_allclose(x, y, atol=REPRODUCIBLE_ATOL, rtol=0, err_msg=f.name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=f.name)


def test_a_tuple_of_values_becomes_one_column_each():
    """ExecutionMetrics.metrics (the user metrics' values) is a tuple: one column per element."""
    from lantern_jax.apps.stream import _flat

    a, u, v = np.zeros(3), np.ones(3), np.full(3, 2.0)
    flat = _flat({"progress": a, "metrics": (u, v), "none": ()})
    assert list(flat) == ["progress", "metrics[0]", "metrics[1]"]
    assert flat["metrics[1]"] is v
