"""The slot scheduler of large evaluations (``sim.rollout.scheduled_map``) and the order in which
devices take a batch (``evaluate.schedule_layout``), on hand-made items whose end is known.

A toy item is a duration ``d`` (int32 ticks); its state is a clock advanced ``CHUNK`` ticks per
loop step, ended once it reaches ``d``: whatever the number of slots, every item must end with
its clock at ``ceil(d / CHUNK) * CHUNK``.  The simulator's own use (``rollout_scheduled``) is
compared with stepping every execution at once in ``test_evaluate.py`` (slow set).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.sim.engine import schedule_layout
from lantern_jax.sim.rollout import scheduled_map

CHUNK = 3  # ticks per loop step of the toy items


def advance(duration, state):
    clock = state["clock"] + CHUNK
    return {"clock": clock, "steps": state["steps"] + 1, "done": clock >= duration}


def ended(states):
    return states["done"]


def fresh(n: int) -> dict:
    z = jnp.zeros(n, jnp.int32)
    return {"clock": z, "steps": z, "done": jnp.zeros(n, bool)}


def run(durations, slots: int, starts=None) -> dict:
    d = jnp.asarray(durations, jnp.int32)
    starts = fresh(len(durations)) if starts is None else starts
    fn = jax.jit(lambda d, s: scheduled_map(advance, ended, d, s, slots))
    return jax.tree.map(np.asarray, fn(d, starts))


def test_every_item_ends_as_if_run_alone_whatever_the_slot_count():
    durations = [7, 1, 30, 3, 12, 4, 4, 9]
    want = -(-np.asarray(durations) // CHUNK) * CHUNK
    for slots in range(1, len(durations) + 1):
        got = run(durations, slots)
        np.testing.assert_array_equal(got["clock"], want, err_msg=f"{slots} slots")
        np.testing.assert_array_equal(got["steps"], want // CHUNK, err_msg=f"{slots} slots")
        assert got["done"].all()


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(1, 40), min_size=1, max_size=12), st.data())
def test_property_final_states_do_not_depend_on_the_slots(durations, data):
    slots = data.draw(st.integers(1, len(durations)))
    got = run(durations, slots)
    want = -(-np.asarray(durations) // CHUNK) * CHUNK
    np.testing.assert_array_equal(got["clock"], want)


def test_an_item_that_starts_ended_is_not_advanced():
    starts = fresh(3)
    starts["clock"] = jnp.asarray([0, 5, 0], jnp.int32)
    starts["done"] = jnp.asarray([False, True, False])
    got = run([6, 100, 2], slots=2, starts=starts)
    np.testing.assert_array_equal(got["clock"], [6, 5, 3])
    np.testing.assert_array_equal(got["steps"], [2, 0, 1])


@pytest.mark.parametrize("slots", [0, 4])
def test_slot_count_outside_the_batch_is_refused(slots):
    with pytest.raises(ValueError, match=r"slots must be in 1\.\.3"):
        scheduled_map(advance, ended, jnp.ones(3, jnp.int32), fresh(3), slots)


def test_devices_are_dealt_the_longest_executions_first_round_robin():
    timeouts = np.array([1.0, 5.0, 3.0, 4.0, 2.0])  # longest first: 1, 3, 2, 4, 0
    layout = schedule_layout(timeouts, devices=2)
    # padded to 6 with a copy of the shortest (0); device 0 takes 1, 2, 0 and device 1 3, 4, 0
    np.testing.assert_array_equal(layout, [1, 2, 0, 3, 4, 0])
    np.testing.assert_array_equal(schedule_layout(timeouts, devices=1), [1, 3, 2, 4, 0])
    # equal timeouts keep the batch order (stable)
    np.testing.assert_array_equal(schedule_layout(np.ones(4), devices=2), [0, 2, 1, 3])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(1.0, 60.0), min_size=1, max_size=40), st.integers(1, 8))
def test_property_layout_holds_every_execution_in_equal_blocks(timeouts, devices):
    layout = schedule_layout(np.asarray(timeouts), devices)
    assert len(layout) % devices == 0 and len(layout) - len(timeouts) < devices
    assert set(layout.tolist()) == set(range(len(timeouts)))
    blocks = layout.reshape(devices, -1)
    t = np.asarray(timeouts)[blocks]
    # every block starts with its longest execution and runs longest first
    assert (np.diff(t, axis=1) <= 0).all()


def test_padding_executions_queue_after_every_real_one():
    """``run_executions(pad_to=...)`` gives its padding rows a timeout of -inf: every device
    takes them last (and they start ended, so they are never stepped)."""
    timeouts = np.array([3.0, 9.0, 5.0, -np.inf, -np.inf, -np.inf])
    layout = schedule_layout(timeouts, devices=2).reshape(2, -1)
    np.testing.assert_array_equal(layout, [[1, 0, 4], [2, 3, 5]])


def test_padding_below_the_batch_is_refused(shipped_pair_executions):
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.sim.engine import run_executions

    ego = get_policy("ego")
    with pytest.raises(ValueError, match=r"pad_to=2 is smaller than the batch \(3\)"):
        run_executions(ego, shipped_pair_executions, {}, 10, pad_to=2)


@pytest.fixture(scope="module")
def shipped_pair_executions():
    """The three executions of one shipped pair (built on the host, nothing compiled)."""
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.sim.engine import build_executions

    return build_executions(load_suite().select(["pe_0001"])).scenarios
