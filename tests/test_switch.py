"""Several policies in one program (:mod:`lantern_jax.sim.switch`): membership, caching, what
each member's branch observes, carries, and the inputs it refuses.  Equality with each policy's
own program is tested on the evaluator (``tests/test_evaluate.py``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.apps.evaluation import shared_program
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import build_suite_scenarios, load_suite
from lantern_jax.sim.engine import Program
from lantern_jax.sim.state import init_state
from lantern_jax.sim.step import policy_waypoints, step
from lantern_jax.sim.switch import SHARE_MIN_BYTES, policy_switch, switch_params
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import PRIVILEGED, SURROUND_RIG, WARNING


def _plan(obs):
    return jnp.zeros((10, 2), jnp.float32) + obs.ego_speed


def plain_act(params, obs):
    """A member that must see neither ground truth nor the six-camera rig."""
    assert obs.privileged is None and obs.surround is None
    return _plan(obs) + params


def privileged_act(params, obs):
    assert obs.privileged is not None and obs.surround is None
    return _plan(obs) + params + obs.privileged.forecast_x[0, 0]


def surround_act(params, obs):
    assert obs.privileged is None and obs.surround is not None
    return _plan(obs) + params + obs.surround.ranges[0]


def text_act(params, obs):
    """Its plan says how many tokens of text it was given."""
    return _plan(obs) * 0.0 + params + jnp.sum(obs.warning_tokens != PAD_ID)


def zero(key):
    return jnp.float32(0.0)


PLAIN = Policy("plain", zero, plain_act)
PRIV = Policy("priv", zero, privileged_act, sensors=(PRIVILEGED,))
RIG = Policy("rig", zero, surround_act, sensors=(SURROUND_RIG,))
MUTE = Policy("mute", zero, text_act)  # the same act without the warning sensor ...
READER = Policy("reader", zero, text_act, sensors=(WARNING,))  # ... and with it


def counting_act(params, carry, obs):
    """A stateful member: counts its own ticks; its plan is the count."""
    return _plan(obs) * 0.0 + carry, carry + 1.0


COUNTER = Policy("counter", zero, counting_act, init_carry=lambda p: jnp.float32(0.0))


@pytest.fixture(scope="module")
def scenario():
    return build_suite_scenarios(load_suite().select(["pe_0001"]))[0][0]


@pytest.fixture(scope="module")
def warned_state(scenario):
    """A state at which the protocol delivers the warning (the ego at the warning point)."""
    state = init_state(scenario)
    return state.replace(protocol=state.protocol.replace(t_warn_point=jnp.float32(0.0)))


def test_each_branch_observes_only_what_its_member_reads(scenario):
    """Tracing a step traces every branch: each member's assertions on its observation run."""
    sw = policy_switch((PLAIN, PRIV, RIG))
    members = (jnp.float32(0.0),) * 3
    for i in range(3):
        params = switch_params(sw, i, members)
        state = init_state(scenario, sw.initial_carry(params))
        out = jax.eval_shape(lambda s, p=params: step(sw, p, scenario, s), state)
        assert out[0].ego.xy.shape == (2,)


def test_the_chosen_member_drives(scenario):
    """The index picks the member: member 1 adds 1 m to every waypoint of member 0's plan."""
    other = Policy("plus-one", zero, lambda p, o: plain_act(p, o) + 1.0)
    sw = policy_switch((PLAIN, other))
    state = init_state(scenario)
    speed = float(state.ego.speed)
    for i, offset in ((0, 0.0), (1, 1.0)):
        params = switch_params(sw, i, (0.0, 0.0))
        st = state.replace(policy_carry=sw.initial_carry(params))
        plan, _ = policy_waypoints(sw, params, scenario, st)
        np.testing.assert_allclose(np.asarray(plan), speed + offset, rtol=1e-6)


def test_members_differing_only_in_the_warning_share_a_branch(scenario, warned_state):
    """``mute`` and ``reader`` have one act function: one branch, and only the member with the
    warning sensor is given the text (the other reads padding)."""
    sw = policy_switch((MUTE, READER))
    assert sw.num_branches == 1 and sw.branch_of == (0, 0)
    counts = []
    for i in (0, 1):
        params = switch_params(sw, i, (0.0, 0.0))
        st = warned_state.replace(policy_carry=sw.initial_carry(params))
        plan, _ = jax.jit(lambda p, s: policy_waypoints(sw, p, scenario, s))(params, st)
        counts.append(float(plan[0, 0]))
    assert counts[0] == 0.0 and counts[1] > 10.0  # the canonical PE text: 21 tokens


def test_a_stateful_member_keeps_its_own_carry(scenario):
    """The switch's carry holds one entry per branch; only the driving member's entry moves."""
    sw = policy_switch((PLAIN, COUNTER))
    assert sw.num_branches == 2
    params = switch_params(sw, 1, (0.0, 0.0))
    state = init_state(scenario, sw.initial_carry(params))
    run = jax.jit(lambda s: step(sw, params, scenario, s)[0])
    for _ in range(3):
        state = run(state)
    assert state.policy_carry[0] == ()
    assert float(state.policy_carry[1]) == 3.0


def test_equal_large_arrays_enter_the_program_once():
    """Members' equal arrays of at least SHARE_MIN_BYTES share one pool slot (the learned
    models' embedding table); small ones do not; every member's parameters rebuild exactly."""
    sw = policy_switch((PLAIN, PRIV))
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


def test_switches_of_the_same_programs_are_one_program():
    """Two switches over members with the same programs are one static ``jit`` argument
    (:class:`~lantern_jax.sim.engine.Program`): one compilation serves both."""
    assert Program(policy_switch((PLAIN, PRIV))) == Program(policy_switch((PLAIN, PRIV)))
    assert hash(Program(policy_switch((PLAIN, PRIV)))) == hash(
        Program(policy_switch((PLAIN, PRIV)))
    )
    assert Program(policy_switch((PRIV, PLAIN))) != Program(policy_switch((PLAIN, PRIV)))
    # a policy of the same program under another name is the same member
    renamed = Policy("plain-again", zero, plain_act)
    assert Program(policy_switch((renamed, PRIV))) == Program(policy_switch((PLAIN, PRIV)))
    sw = policy_switch((PLAIN, PRIV))
    assert sw.any_privileged and sw.index_of(PRIV) == 1 and sw.index_of(renamed) == 0


def test_shared_program_joins_distinct_programs_only():
    expert, ego, coop = (get_policy(n) for n in ("expert", "ego", "coop"))
    assert shared_program([PLAIN, PLAIN], [None, None]) is None  # one program
    assert shared_program([PLAIN], [None]) is None
    sw, params = shared_program([expert, ego, coop], [None, None, None])
    assert [m.name for m in sw.members] == ["expert", "ego", "coop"] and len(params) == 3
    assert sw.branch_of == (0, 1, 1)  # ego and coop: one planner branch


def test_any_reference_policies_share_the_main_commands_program():
    """``coop`` alone, ``ego`` and ``coop`` in either order and all three run one program (the
    reference switch, in the reference order); another policy joins it after them."""
    expert, ego, coop = (get_policy(n) for n in ("expert", "ego", "coop"))
    main = Program(shared_program([expert, ego, coop], [None] * 3)[0])
    for pols in ([coop], [ego], [coop, ego], [ego, coop], [coop, expert]):
        sw, params = shared_program(pols, [None] * len(pols))
        assert Program(sw) == main, [p.name for p in pols]
        assert len(params) == 3
    sw, params = shared_program([PLAIN, coop], [jnp.float32(2.0), None])
    assert [m.name for m in sw.members] == ["expert", "ego", "coop", PLAIN.name]
    assert float(params[3]) == 2.0


@pytest.mark.parametrize(
    "call, error, match",
    [
        (lambda: policy_switch((PLAIN,)), ValueError, "at least 2 members"),
        (
            lambda: policy_switch((PLAIN, Policy("same", zero, plain_act))),
            ValueError,
            "distinct programs",
        ),
        (
            lambda: switch_params(policy_switch((PLAIN, PRIV)), 2, (0.0, 0.0)),
            ValueError,
            r"switch_params.index: 2",
        ),
        (
            lambda: switch_params(policy_switch((PLAIN, PRIV)), 0, (0.0,)),
            ValueError,
            "switch_params.members: 1 parameter sets for 2 members",
        ),
        (lambda: policy_switch((PLAIN, PRIV)).index_of(RIG), ValueError, "not a member"),
    ],
)
def test_bad_inputs(call, error, match):
    with pytest.raises(error, match=match):
        call()
