"""Warning overrides and the warning as language in the observation: a chosen text, position and
window on any execution (Route B included), texts without a position, token ids per tick.

Closed-loop checks share one batched call of the session's jitted runner (``conftest.sim``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MODE_COOP, MODE_EXPERT, select

from lantern_jax.core.constants import DT, PE
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.warnings import (
    get_text,
    non_actionable_text_ids,
    render_warning,
    set_override,
    tier_text_ids,
    token_table,
    warning_string,
)
from lantern_jax.sim.observe import observe
from lantern_jax.sim.sense import locate_on_route, sense
from lantern_jax.sim.state import init_state
from lantern_jax.types import language
from lantern_jax.types.observation import WARNING, stated_position, warning_delivered
from lantern_jax.types.world import NO_OVERRIDE, ProtocolState

HIGH_PE = tier_text_ids("PE", "high")[0]  # "Someone may cross in front of you."
LOW_PE = tier_text_ids("PE", "low")[1]


def empty_road(**kw):
    return straight_scene([], length=100.0, speed=8.0, warning_enabled=False, **kw)


def observation_times(rec) -> np.ndarray:
    """The clock each recorded observation was read at (float32, as the simulator has it)."""
    return np.concatenate([np.zeros(1, np.float32), np.asarray(rec.t[:-1], np.float32)])


def live_ticks(rec) -> int:
    done = np.asarray(rec.done)
    return int(np.argmax(done)) + 1 if done.any() else done.shape[0]


def ego_frame(point, ego_xy, ego_yaw) -> np.ndarray:
    d = np.asarray(point, np.float64) - np.asarray(ego_xy, np.float64)
    c, s = np.cos(float(ego_yaw)), np.sin(float(ego_yaw))
    return np.array([c * d[0] + s * d[1], s * d[0] - c * d[1]])


@pytest.fixture(scope="module")
def scenes(family_pairs):
    """name -> (world, policy mode)."""
    a_pe, b_pe, meta = family_pairs["PE"]
    hand_a = straight_scene(
        [], length=100.0, speed=8.0, s_warn=30.0, s_event=40.0, s_conflict=50.0
    )  # a Route A whose warning point is at 30 m (t ~ 3.75 s); no hazard ever seen
    return {
        "b_world": (
            set_override(b_pe, 0, meta["conflict_xy"], "world", 0.3, 2.1, "warning_point"),
            MODE_EXPERT,
        ),
        "a_early": (set_override(hand_a, LOW_PE, (20.0, -1.0), "ego", 0.52, 1.52), MODE_EXPERT),
        "no_position": (
            set_override(empty_road(), HIGH_PE, (30.0, 2.0), "ego", 1.01, 3.01),
            MODE_EXPERT,
        ),
        "ego_frame": (set_override(empty_road(), 0, (12.0, 0.5), "ego", 1.01, 4.01), MODE_EXPERT),
        "none": (empty_road(), MODE_EXPERT),
        "coop_plain": (empty_road(), MODE_COOP),
        "coop_near": (set_override(empty_road(), 0, (12.0, 0.5), "ego", 1.01, 4.01), MODE_COOP),
        "coop_nonactionable": (
            set_override(empty_road(), non_actionable_text_ids()[1], on_s=1.01),
            MODE_COOP,
        ),
    }


@pytest.fixture(scope="module")
def runs(sim, scenes):
    names = list(scenes)
    final, rec = sim.batch([scenes[n][0] for n in names], [scenes[n][1] for n in names])
    return {n: (scenes[n][0], select(final, i), select(rec, i)) for i, n in enumerate(names)}


def check_window(rec, t_on, t_off, label):
    n = live_ticks(rec)
    t_obs = observation_times(rec)[:n]
    expected = (t_obs >= np.float32(t_on)) & (t_obs < np.float32(t_off))
    active = np.asarray(rec.warning_active)[:n]
    assert expected.any() and (~expected).any(), label
    bad = np.flatnonzero(active != expected)
    assert bad.size == 0, f"{label}: wrong at t = {t_obs[bad[:5]]}"
    return expected, n


def test_route_b_override_is_active_exactly_in_its_window(runs):
    world, final, rec = runs["b_world"]
    assert not bool(world.config.is_route_a) and not bool(world.config.warning_enabled)
    t_wp = np.float32(final.protocol.t_warn_point)
    assert t_wp < 1e8, "Route B records its warning point"
    # Window [t_wp + 0.3, t_wp + 2.1), in the simulator's float32 arithmetic.
    expected, n = check_window(rec, t_wp + np.float32(0.3), t_wp + np.float32(2.1), "Route B")
    tid = np.asarray(rec.warning_text_id)[:n]
    np.testing.assert_array_equal(tid, np.where(expected, 0, -1))
    # A world-frame position is grounded into the ego frame of every tick (x fwd, y right).
    point = np.asarray(world.config.override_x), np.asarray(world.config.override_y)
    for k in np.flatnonzero(expected):
        want = ego_frame(point, rec.ego_xy[k - 1], rec.ego_yaw[k - 1])
        np.testing.assert_allclose(rec.warning_pos[k], want, atol=2e-4, err_msg=f"tick {k}")
    np.testing.assert_array_equal(rec.warning_pos[:n][~expected], 0.0)


def test_override_before_the_protocol_warning_then_the_protocol_warning(runs):
    world, final, rec = runs["a_early"]
    n = live_ticks(rec)
    t_obs = observation_times(rec)[:n]
    tid = np.asarray(rec.warning_text_id)[:n]
    in_window = (t_obs >= np.float32(0.52)) & (t_obs < np.float32(1.52))
    t_wp = float(final.protocol.t_warn_point)
    assert 1.52 < t_wp < 1e8
    protocol_on = t_obs >= np.float32(t_wp)  # never seen: stays on to the end of the run
    np.testing.assert_array_equal(tid, np.where(in_window, LOW_PE, np.where(protocol_on, 0, -1)))
    np.testing.assert_allclose(rec.warning_pos[:n][in_window], [[20.0, -1.0]] * in_window.sum())
    # The override changes what the policy reads, not the protocol: onset = the warning point.
    np.testing.assert_allclose(float(final.protocol.t_warn_on), t_wp)


def test_text_without_a_position_delivers_no_position(runs):
    world, _, rec = runs["no_position"]
    assert not get_text(HIGH_PE).has_position
    expected, n = check_window(rec, 1.01, 3.01, "no position")
    np.testing.assert_array_equal(np.asarray(rec.warning_text_id)[:n][expected], HIGH_PE)
    np.testing.assert_array_equal(rec.warning_pos, 0.0)  # (30, 2) was given, none delivered


def test_ego_frame_override_is_delivered_as_given(runs):
    _, _, rec = runs["ego_frame"]
    expected, n = check_window(rec, 1.01, 4.01, "ego frame")
    np.testing.assert_array_equal(rec.warning_pos[:n][expected], [[12.0, 0.5]] * expected.sum())


def test_no_override_is_data_not_a_branch(runs, scenes):
    world, _, rec = runs["none"]
    for k, v in NO_OVERRIDE.items():
        assert float(getattr(world.config, k)) == float(v), k
    assert not np.asarray(rec.warning_active).any()
    # The scenes with and without an override ran in one batch, i.e. one compiled function.
    assert len({jax.tree.structure(s[0]) for s in scenes.values()}) == 1


def test_policies_read_overrides(runs):
    plain = np.asarray(runs["coop_plain"][2].ego_speed)
    near = np.asarray(runs["coop_near"][2].ego_speed)
    window = slice(int(1.01 / DT), int(4.01 / DT) + 1)  # ticks of the warning window
    assert plain[window].min() > 7.5  # cruising at 8 m/s
    assert near[window].min() < plain[window].min() - 2.0  # braking for a pedestrian 12 m ahead
    # coop only understands the canonical wording: a non-actionable text changes nothing.
    np.testing.assert_array_equal(np.asarray(runs["coop_nonactionable"][2].ego_speed), plain)


# ---------------------------------------------------------------------------------------------
# the language fields of one observation
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def obs_fn():
    @jax.jit
    def fn(world, st):
        arc, dist, progress = locate_on_route(world.route, st.ego.xy, jnp.float32(0.0))
        st = st.replace(percept=sense(world, st.ego, st.actors, arc, dist, progress))
        return observe(world, st, (WARNING,))

    return fn


@pytest.mark.parametrize("text_id", [0, LOW_PE, HIGH_PE, non_actionable_text_ids()[0]])
def test_observation_tokens_and_position_flag(obs_fn, text_id):
    world = set_override(empty_road(), text_id, (15.0, -2.0), "ego", 0.5, 1.5)
    state = init_state(world).replace(t=jnp.float32(1.0))
    obs = obs_fn(world, state)
    has = get_text(text_id).has_position
    assert bool(warning_delivered(obs))
    np.testing.assert_array_equal(np.asarray(obs.warning_tokens), token_table()[text_id])
    assert obs.warning_tokens.shape == (language.MAX_TOKENS,)
    assert (np.asarray(obs.warning_tokens) == language.NUMBER_ID).sum() == 2 * int(has)
    pos, stated = stated_position(obs)
    assert bool(stated) == has
    np.testing.assert_array_equal(np.asarray(pos), [15.0, -2.0] if has else [0, 0])
    assert warning_string(obs.warning_tokens, obs.warning_values) == render_warning(
        text_id, (15.0, -2.0)
    )
    # Outside the window: nothing delivered, all padding.
    late = obs_fn(world, state.replace(t=jnp.float32(1.5)))
    assert not bool(warning_delivered(late)) and not bool(stated_position(late)[1])
    assert (np.asarray(late.warning_tokens) == language.PAD_ID).all()


def test_override_anchored_at_the_warning_point_waits_for_it(obs_fn):
    world = set_override(empty_road(), 0, (15.0, 0.0), "ego", 0.0, 2.0, "warning_point")
    state = init_state(world).replace(t=jnp.float32(5.0))
    assert not bool(warning_delivered(obs_fn(world, state)))  # the warning point never reached
    reached = state.replace(protocol=ProtocolState.initial().replace(t_warn_point=jnp.float32(4.0)))
    assert bool(warning_delivered(obs_fn(world, reached)))
    after = reached.replace(t=jnp.float32(6.0))
    assert not bool(warning_delivered(obs_fn(world, after)))


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(text_id=10_000), "text_id"),
        (dict(text_id=0, frame="car"), "frame"),
        (dict(text_id=0, anchor="event"), "anchor"),
        (dict(text_id=0, position=(1.0, np.nan)), "position"),
        (dict(text_id=0, on_s=2.0, off_s=1.0), "on_s/off_s"),
        (dict(text_id=0, on_s=-DT), "on_s/off_s"),
    ],
)
def test_bad_overrides_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        set_override(empty_road(), **kwargs)


def test_config_validation_of_override_fields():
    world = empty_road()
    cfg = world.config
    for field, value, match in (
        ("override_text_id", -2, "override_text_id"),
        ("override_anchor", 2, "override_anchor"),
        ("override_frame", -1, "override_frame"),
    ):
        bad = cfg.replace(**{field: jnp.asarray(value, jnp.int32)})
        with pytest.raises(ValueError, match=match):
            bad.validate()
    with pytest.raises(ValueError, match="override_off_s"):
        cfg.replace(override_on_s=jnp.float32(3.0), override_off_s=jnp.float32(1.0)).validate()
    assert PE == 0  # canonical text id of the family used above
