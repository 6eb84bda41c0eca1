"""The information boundary: a policy reads what its declared sensors deliver and nothing else.

* hidden actors are the zero sentinel in every observation of a recorded rollout;
* a policy that ignores ``visible`` cannot brake for a pedestrian before the camera sees it,
  the same policy with ground truth (``"privileged"``) can;
* the warning reaches a policy only as the delivered text (no id, flag or position field);
* ``coop``'s keyword rule reads the words;
* policies with memory: the carry runs in the evaluator (and resets when a slot is reused),
  in a host-callback policy and in an agent loop over the brax environment.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.apps.diagnostics import run_recorded
from lantern_jax.apps.evaluation import build_executions, run_executions
from lantern_jax.apps.language_sensitivity import LANGUAGE_VARIANTS, language_table
from lantern_jax.core.constants import KIND_PEDESTRIAN, NUM_WAYPOINTS, WAYPOINT_DT
from lantern_jax.policies.base import Policy, check_policy_output
from lantern_jax.policies.host import host_policy
from lantern_jax.policies.reference import (
    SEM_CUT_IN,
    SEM_LANE_OBSTACLE,
    SEM_NONE,
    SEM_YIELD_TURN,
    text_response,
)
from lantern_jax.scenarios.families import family
from lantern_jax.scenarios.suite import build_suite_scenarios, load_suite
from lantern_jax.scenarios.warnings import EMPTY_TEXT_ID, TEMPLATES, non_actionable_text_ids
from lantern_jax.scenarios.warnings import token_table as bank_tokens
from lantern_jax.sensors.registry import normalize_sensors
from lantern_jax.sim import programs
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import (
    PRIVILEGED,
    SENSORS,
    WARNING,
    Observation,
    warning_delivered,
)

BRAKE_RANGE_M = 40.0  # m ahead: the probe brakes for any pedestrian slot this close


def _stop_plan() -> jax.Array:
    return jnp.zeros((NUM_WAYPOINTS, 2), jnp.float32)


def _cruise_plan(speed: jax.Array) -> jax.Array:
    k = jnp.arange(1, NUM_WAYPOINTS + 1, dtype=jnp.float32) * WAYPOINT_DT
    return jnp.stack([k * speed, jnp.zeros_like(k)], -1)


def _pedestrian_ahead(xy: jax.Array, kind: jax.Array) -> jax.Array:
    """() bool: a pedestrian slot lies within BRAKE_RANGE_M ahead (no regard for ``visible``)."""
    ahead = (xy[:, 0] > 0.0) & (xy[:, 0] < BRAKE_RANGE_M) & (jnp.abs(xy[:, 1]) < 10.0)
    return jnp.any(ahead & (kind == KIND_PEDESTRIAN))


def _first_brake_policy(name: str, privileged: bool) -> Policy:
    """Brakes as soon as any pedestrian slot is within 40 m ahead, ignoring ``visible``; its
    carry is ``(tick, first tick it braked or -1)``."""

    def act(params, carry, obs):
        tick, first = carry
        src = obs.privileged if privileged else obs
        brake = _pedestrian_ahead(src.actor_xy, src.actor_kind)
        first = jnp.where((first < 0) & brake, tick, first)
        plan = jnp.where(brake, _stop_plan(), _cruise_plan(obs.v_ref))
        return plan, (tick + 1, first)

    sensors = (PRIVILEGED,) if privileged else ()
    carry0 = lambda p: (jnp.int32(0), jnp.int32(-1))  # noqa: E731
    return Policy(name, lambda k: None, act, sensors=sensors, init_carry=carry0)


@pytest.fixture(scope="module")
def pe_no_warning():
    """Route A of every PE pair of the built-in suite, without the warning."""
    suite = load_suite()
    pe = suite.select([p.pair_id for p in suite.pairs if p.family == "PE"])
    scenarios = build_suite_scenarios(pe)[0]
    off = jnp.asarray(False)
    return [sc.replace(config=sc.config.replace(warning_enabled=off)) for sc in scenarios]


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_camera_policy_cannot_brake_for_a_hidden_pedestrian(pe_no_warning):
    """On every PE pair without warning, a policy that brakes for any pedestrian slot within
    40 m ahead, ignoring ``visible``, never brakes before the tick at which the front camera
    first sees the pedestrian; declared privileged, the same rule brakes earlier."""
    camera = _first_brake_policy("ped-brake", privileged=False)
    truth = _first_brake_policy("ped-brake-privileged", privileged=True)
    final_c, rec_c, _ = run_recorded(camera, None, pe_no_warning)
    final_t, _, _ = run_recorded(truth, None, pe_no_warning)
    h = np.asarray([int(sc.config.hazard_index) for sc in pe_no_warning])
    seen = rec_c.visible[np.arange(len(h)), :, h]  # (pairs, ticks): camera sees the hazard
    # the observation of tick k is built from the state after tick k - 1
    first_seen = np.where(seen.any(axis=1), seen.argmax(axis=1) + 1, np.iinfo(np.int32).max)
    braked_c = np.asarray(final_c.policy_carry[1])
    braked_t = np.asarray(final_t.policy_carry[1])
    # with the camera: never before the pedestrian is in view (-1: it never braked at all)
    assert ((braked_c < 0) | (braked_c >= first_seen)).all(), (braked_c, first_seen)
    assert (braked_c >= 0).sum() >= 5  # it does brake once it sees the pedestrian
    # with ground truth: on every pair, before the camera sees the pedestrian
    assert (braked_t >= 0).all() and (braked_t < first_seen).all(), (braked_t, first_seen)


def _spy_policy() -> Policy:
    """Counts, per execution, the ticks at which some actor slot it does not see carries any
    nonzero field, and the slot-ticks it sees (so the check cannot pass vacuously)."""

    def act(params, carry, obs):
        bad, seen = carry
        hidden = ~obs.visible
        fields = (obs.actor_xy, obs.actor_vel, obs.actor_dir, obs.actor_extent)
        leak = jnp.any(hidden & (obs.actor_kind != 0))
        for f in fields:
            leak = leak | jnp.any(hidden[:, None] & (f != 0.0))
        plan = _cruise_plan(obs.v_ref * 0.8)
        return plan, (bad + leak.astype(jnp.int32), seen + jnp.sum(obs.visible))

    carry0 = lambda p: (jnp.int32(0), jnp.int32(0))  # noqa: E731
    return Policy("spy", lambda k: None, act, init_carry=carry0)


def test_hidden_actors_are_the_sentinel_at_every_tick():
    """Two pairs of every family, all three executions: no observation of the rollout leaks a
    field of an actor the camera does not see, while some actors are seen."""
    suite = load_suite()
    pairs = [p.pair_id for f in ("PE", "VC", "OR", "LWW", "RWW", "RTY") for p in
             [q for q in suite.pairs if q.family == f][:2]]  # fmt: skip
    # the split path: the session's stored world program and the spy's own small program (its
    # observations are observe()'s, tests/test_split.py)
    execs = build_executions(suite.select(pairs), bucket=True)
    final, _ = run_executions(_spy_policy(), execs.scenarios, None, execs.max_ticks,
                              path="split")  # fmt: skip
    bad, seen = (np.asarray(x) for x in final.policy_carry)
    assert (bad == 0).all(), bad
    assert (seen > 0).sum() >= len(seen) // 2  # most executions see some actor
    # the premise held: the hazard was present and hidden at the warning point on Route A
    hidden = ~np.asarray(final.protocol.hazard_visible_at_warn[: len(pairs)], bool)
    assert hidden.sum() >= 8


def test_the_warning_reaches_a_policy_only_as_its_text():
    names = {f.name for f in dataclasses.fields(Observation)}
    for gone in ("warning_active", "warning_text_id", "warning_pos", "warning_has_position",
                 "present"):  # fmt: skip
        assert gone not in names
    assert {n for n in names if n.startswith("warning")} == {"warning_tokens", "warning_values"}
    suite = load_suite().select(["pe_0001"])
    sc = build_suite_scenarios(suite)[0][0]
    state = init_state(sc)
    state = state.replace(protocol=state.protocol.replace(t_warn_point=jnp.float32(0.0)))
    camera = jax.jit(lambda s: observe(sc, s))(state)
    reader = jax.jit(lambda s: observe(sc, s, (WARNING,)))(state)
    assert camera.privileged is None and camera.surround is None
    assert (np.asarray(camera.warning_tokens) == PAD_ID).all()  # no warning sensor: no text
    assert not np.asarray(camera.warning_values).any()
    np.testing.assert_array_equal(np.asarray(reader.warning_tokens), bank_tokens()[0])


def test_sensor_declarations_are_checked():
    assert normalize_sensors(()) == ("front_camera",)
    assert normalize_sensors(("warning", "front_camera")) == ("front_camera", "warning")
    with pytest.raises(ValueError, match="unknown lidar; known: " + ", ".join(SENSORS)):
        normalize_sensors(("lidar",))
    with pytest.raises(ValueError, match="string 'warning'"):
        Policy("p", lambda k: None, lambda p, o: o.route[:10], sensors="warning")
    with pytest.raises(TypeError, match="init_carry must be callable"):
        Policy("p", lambda k: None, lambda p, o: o.route[:10], init_carry=3)


def test_a_carry_that_changes_shape_is_refused():
    sc = build_suite_scenarios(load_suite().select(["pe_0001"]))[0][0]
    obs = jax.eval_shape(lambda: observe(sc, init_state(sc)))
    bad = Policy("grows", lambda k: None, lambda p, c, o: (o.route[:10], jnp.zeros(3)),
                 init_carry=lambda p: jnp.zeros(2))  # fmt: skip
    with pytest.raises(ValueError, match="'grows': act returned a carry"):
        check_policy_output(bad, None, obs)


# ---------------------------------------------------------------------------------------------
# coop reads the words
# ---------------------------------------------------------------------------------------------
def test_the_keyword_rule_answers_each_canonical_text_as_its_family_asks():
    rows = bank_tokens()
    lookup = jax.jit(text_response)
    want = {"lane_obstacle": SEM_LANE_OBSTACLE, "cut_in": SEM_CUT_IN, "yield_turn": SEM_YIELD_TURN}
    for f in range(len(TEMPLATES)):
        assert int(lookup(jnp.asarray(rows[f]))) == want[family(f).response], TEMPLATES[f]
    assert int(lookup(jnp.asarray(rows[EMPTY_TEXT_ID]))) == SEM_NONE
    for tid in non_actionable_text_ids():  # none of the paper's five says yield/cut into/lane
        assert int(lookup(jnp.asarray(rows[tid]))) == SEM_NONE


# ---------------------------------------------------------------------------------------------
# policies with memory
# ---------------------------------------------------------------------------------------------
def _warning_counter() -> Policy:
    """Counts the ticks at which it was given a warning text; drives like a cautious cruise."""

    def act(params, carry, obs):
        return _cruise_plan(obs.v_ref), carry + warning_delivered(obs).astype(jnp.int32)

    return Policy("counter", lambda k: None, act, sensors=(WARNING,),
                  init_carry=lambda p: jnp.int32(0))  # fmt: skip


@pytest.fixture(scope="module")
def six_pairs():
    suite = load_suite()
    return suite.select([p.pair_id for f in ("PE", "VC", "OR", "LWW", "RWW", "RTY")
                         for p in [q for q in suite.pairs if q.family == f][:1]])  # fmt: skip


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_carry_resets_when_a_slot_takes_the_next_execution(six_pairs, monkeypatch):
    """Through two slots per device refilled every 20 ticks, every execution's final count is
    the number of ticks its own warning was delivered (a carry left over from the slot's
    previous execution would add to it)."""
    from lantern_jax.sim import engine

    monkeypatch.setattr(engine, "compact_slots", lambda backend=None: 2)
    execs = build_executions(six_pairs)
    final, _ = run_executions(_warning_counter(), execs.scenarios, None, execs.max_ticks,
                              compact=True)  # fmt: skip
    count = np.asarray(final.policy_carry)
    shown = np.asarray(final.protocol.warning_ticks)
    np.testing.assert_array_equal(count, shown)
    assert (count[:6] > 0).sum() >= 3 and (count[6:] == 0).all()  # Route A warning only


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_a_host_policy_with_memory(six_pairs):
    """The same counter as a host (NumPy) model: the carry travels through the callback."""

    def model(x, carry):
        delivered = (x != PAD_ID).any(axis=1)
        speed = np.full((len(x), 2), 0.0, np.float32)
        return speed, carry + delivered.astype(np.int32)

    def to_waypoints(y, obs):
        return _cruise_plan(obs.v_ref) + 0.0 * y[0]

    pol = host_policy("host-counter", model, out_shape=(2,),
                      preprocess=lambda obs: obs.warning_tokens, postprocess=to_waypoints,
                      sensors=(WARNING,), carry=np.int32(0))  # fmt: skip
    execs = build_executions(six_pairs.select(["pe_0001", "lww_0001"]))
    final, _ = run_executions(pol, execs.scenarios, {}, execs.max_ticks)
    np.testing.assert_array_equal(
        np.asarray(final.policy_carry), np.asarray(final.protocol.warning_ticks)
    )
    assert int(np.asarray(final.policy_carry)[0]) > 0


LANGUAGE_COLUMNS = ["PE", "VC", "OR", "LWW", "RWW", "RTY", "Overall"]


def test_language_sensitivity_of_coop(six_pairs):
    """The diagnostic's rows, all from the evaluation's program (the probe sentences are rows of
    the bank's tables, an argument): the empty text is no warning (the policy cannot tell them
    apart); coop's PE gain goes with the pedestrian's words -- another family's canonical text,
    a paraphrase of another straight-road family and the bakery sentence keep none of it -- but
    its keyword rule reads "ego lane" in the negated sentence and keeps all of it: the
    diagnostic shows that it does not understand negation."""
    language_table("coop", six_pairs, variants=())  # the delivered text: compiles the program
    before = set(programs._EXECUTABLES)
    table = language_table("coop", six_pairs).set_index("Variant")
    assert list(table.index[:7]) == list(LANGUAGE_VARIANTS)
    np.testing.assert_allclose(
        table.loc["empty text", LANGUAGE_COLUMNS].to_numpy(float),
        table.loc["no warning", LANGUAGE_COLUMNS].to_numpy(float),
        atol=1e-6,
    )
    assert table.loc["delivered text", "PE"] > table.loc["no warning", "PE"] + 50.0
    lo, est, hi = table.loc["delivered text", ["Overall_lo", "Overall", "Overall_hi"]]
    assert lo <= est <= hi
    kept = table["PE"]
    assert kept["gain kept by other family's text (%)"] < 30.0
    for v in ("same road type, other family's paraphrase", "irrelevant sentence with the position",
              "empty text"):  # fmt: skip
        assert kept[f"gain kept by {v} (%)"] == pytest.approx(0.0, abs=1e-6), v
    negated = kept["gain kept by negated sentence with the position (%)"]
    assert negated == pytest.approx(100.0, abs=1e-3)
    assert set(programs._EXECUTABLES) == before, "a replaced text compiled a program"


def test_an_agent_with_memory_in_the_brax_environment():
    """An agent loop over the environment keeps its own carry (ticks with the warning slot on)
    and resets it with the episode: at the end it equals the simulator's delivered ticks."""
    pytest.importorskip("brax")
    from lantern_jax.apps.envs.bank import ScenarioBank
    from lantern_jax.apps.envs.env import LanternEnv
    from lantern_jax.types.world import tree_stack

    suite = load_suite().select(["pe_0001"])
    a, b, _ = build_suite_scenarios(suite)
    sc = tree_stack([a[0].replace(config=a[0].config.replace(warning_enabled=jnp.asarray(True)))])
    bank = ScenarioBank(sc, jax.jit(jax.vmap(init_state))(sc), np.zeros(1, np.int32),
                        np.zeros(1, np.int32))  # fmt: skip
    env = LanternEnv(bank)
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    step = jax.jit(env.step)
    carry = 0
    for _ in range(400):
        carry += int(state.obs[261] > 0.5)  # the warning slot of the observation vector
        state = step(state, jnp.asarray([0.0, 0.0]))
        if bool(state.done):
            break
    assert carry > 0
    assert carry == int(state.pipeline_state.sim.protocol.warning_ticks)
