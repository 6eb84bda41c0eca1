"""Several policies in one program (:mod:`lantern_jax.sim.switch`): membership, caching, what
each member's branch observes, and the inputs it refuses.  Equality with each policy's own
program is tested on the evaluator (``tests/test_evaluate.py``)."""

from __future__ import annotations

import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.evaluate import shared_program
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import build_suite_scenarios, load_suite
from lantern_jax.sim.state import init_state
from lantern_jax.sim.step import step
from lantern_jax.sim.switch import (
    SHARE_MIN_BYTES,
    SwitchParams,
    policy_switch,
    switch_params,
)


def _plan(obs):
    return jnp.zeros((10, 2), jnp.float32) + obs.ego_speed


def plain_act(params, obs):
    """A member that must see neither the forecast nor the six-camera rig."""
    assert obs.privileged is None and obs.surround is None
    return _plan(obs) + params


def privileged_act(params, obs):
    assert obs.privileged is not None and obs.surround is None
    return _plan(obs) + params + obs.privileged.forecast_x[0, 0]


privileged_act.privileged = True


def surround_act(params, obs):
    assert obs.privileged is None and obs.surround is not None
    return _plan(obs) + params + obs.surround.ranges[0]


surround_act.surround = True


@pytest.fixture(scope="module")
def scenario():
    return build_suite_scenarios(load_suite().select(["pe_0001"]))[0][0]


def test_each_branch_observes_only_what_its_member_reads(scenario):
    """Tracing a step traces every branch: each member's assertions on its observation run."""
    sw = policy_switch((plain_act, privileged_act, surround_act))
    members = (jnp.float32(0.0),) * 3
    state = init_state(scenario)
    for i in range(3):
        out = jax.eval_shape(
            lambda s, i=i: step(sw, switch_params(sw, i, members), scenario, s, jnp.float32(0.05)),
            state,
        )
        assert out[0].ego.xy.shape == (2,)


def test_the_chosen_member_drives():
    """The index picks the member: member 1 adds 1 m to every waypoint of member 0's plan
    (plain members read only the shared observation, so a stand-in for it is enough)."""
    sw = policy_switch((plain_act, lambda p, o: plain_act(p, o) + 1.0))
    obs = types.SimpleNamespace(ego_speed=jnp.float32(3.0), privileged=None, surround=None)
    plans = [sw.choose(switch_params(sw, i, (0.0, 0.0)), obs, None, None) for i in (0, 1)]
    assert float(jnp.max(jnp.abs(plans[0] - 3.0))) == 0.0
    assert float(jnp.max(jnp.abs(plans[1] - 4.0))) == 0.0


def test_equal_large_arrays_enter_the_program_once():
    """Members' equal arrays of at least SHARE_MIN_BYTES share one pool slot (the learned
    models' embedding table); small ones do not; every member's parameters rebuild exactly."""
    sw = policy_switch((plain_act, privileged_act))
    big = np.arange(SHARE_MIN_BYTES // 4, dtype=np.float32)
    small = np.ones(4, np.float32)
    members = ({"emb": big, "w": small}, {"emb": big.copy(), "w": small.copy()})
    sp = switch_params(sw, 1, members)
    assert len(sp.pool) == 3  # one table, two small arrays
    for i, m in enumerate(members):
        got = sp.member(i)
        np.testing.assert_array_equal(got["emb"], m["emb"])
        np.testing.assert_array_equal(got["w"], m["w"])
    assert sp.member(0)["emb"] is sp.member(1)["emb"]


def test_switches_are_cached_by_members():
    assert policy_switch((plain_act, privileged_act)) is policy_switch((plain_act, privileged_act))
    assert policy_switch((privileged_act, plain_act)) is not policy_switch(
        (plain_act, privileged_act)
    )
    sw = policy_switch((plain_act, privileged_act))
    assert sw.any_privileged and sw.index_of(privileged_act) == 1


def test_shared_program_joins_distinct_acts_only():
    expert, ego, coop = (get_policy(n) for n in ("expert", "ego", "coop"))
    assert shared_program([ego, coop], [None, None]) is None  # one act already
    sw, params = shared_program([expert, ego, coop], [None, None, None])
    assert sw.members == (expert.act, ego.act) and len(params) == 2


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda: policy_switch((plain_act,)), ValueError, "at least 2 members"),
        (lambda: policy_switch((plain_act, plain_act)), ValueError, "distinct"),
        (
            lambda: switch_params(policy_switch((plain_act, privileged_act)), 2, (0.0, 0.0)),
            ValueError,
            r"switch_params.index: 2",
        ),
        (
            lambda: switch_params(policy_switch((plain_act, privileged_act)), 0, (0.0,)),
            ValueError,
            "switch_params.members: 1 parameter sets for 2 members",
        ),
        (
            lambda: policy_switch((plain_act, privileged_act)).index_of(surround_act),
            ValueError,
            "not a member",
        ),
        (
            lambda: policy_switch((plain_act, privileged_act))(
                SwitchParams(jnp.int32(0), (0.0,), ((jax.tree.structure(0.0), (0,)),) * 2), None
            ),
            TypeError,
            "run by lantern_jax.sim.step.step",
        ),
    ],
)
def test_bad_inputs(call, error, match):
    with pytest.raises(error, match=match):
        call()
