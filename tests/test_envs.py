"""The brax environment: contract, brax's own wrappers, true resets, reward, the PPO policy."""

from __future__ import annotations

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import EGO_MAX_BRAKE, WAYPOINT_DT
from lantern_jax.policies.features import (
    ACTION_SIZE,
    ACTOR_FEATURES,
    KAPPA_MAX,
    OBS_SIZE,
    action_to_waypoints,
    observation_vector,
)
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state

pytest.importorskip("brax")
from brax import envs as brax_envs  # noqa: E402
from brax.envs.wrappers import training as brax_training  # noqa: E402

import lantern_jax.apps.envs as lenvs  # noqa: E402
from lantern_jax.apps.envs.reward import GATE_PENALTY  # noqa: E402


@pytest.fixture(scope="module")
def env():
    bank = lenvs.build_bank(pairs_per_family=1, families=("PE", "VC"))
    return brax_envs.get_environment("lantern", bank=bank)


def test_importing_lantern_jax_does_not_import_brax():
    code = (
        "import sys, lantern_jax, lantern_jax.apps.evaluation, lantern_jax.cli, "
        "lantern_jax.policies.registry; assert 'brax' not in sys.modules, 'brax imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_importing_the_environment_prints_no_third_party_noise():
    """MJX's "Failed to import warp" lines (brax imports it) stay out of the terminal; a line
    printed by anything else during the import still gets through."""
    code = (
        "from lantern_jax.apps.envs.quiet import filtered_stdout\n"
        "with filtered_stdout():\n"
        "    print('Failed to import warp: x'); print('kept line')\n"
        "import lantern_jax.apps.envs"
    )
    done = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                          text=True)  # fmt: skip
    assert "Failed to import" not in done.stdout + done.stderr
    assert done.stdout.splitlines() == ["kept line"]


def test_registered_with_brax_and_sizes(env):
    assert isinstance(env, lenvs.LanternEnv)
    assert env.bank.size == 6  # 2 families x 1 pair x (A warning, A no-warning, B)
    assert (env.observation_size, env.action_size, env.backend) == (OBS_SIZE, ACTION_SIZE, "jax")
    assert OBS_SIZE == 276


# --- the action and observation mappings (no simulator) --------------------------------------
def test_zero_action_keeps_speed_and_heading():
    wp = np.asarray(action_to_waypoints(jnp.zeros(2), jnp.float32(8.0)))
    t = WAYPOINT_DT * np.arange(1, 11)
    np.testing.assert_allclose(wp[:, 0], 8.0 * t, atol=1e-5)  # x = v t
    np.testing.assert_allclose(wp[:, 1], 0.0, atol=1e-6)


def test_full_brake_stops_within_the_braking_distance():
    # From 8 m/s at 8 m/s^2 the ego stops after 1 s having covered 8^2 / (2 * 8) = 4 m.
    wp = np.asarray(action_to_waypoints(jnp.asarray([-1.0, 0.0]), jnp.float32(8.0)))
    assert EGO_MAX_BRAKE == 8.0
    np.testing.assert_allclose(wp[3:, 0], 4.0, atol=1e-5)  # from t = 1.0 s on
    np.testing.assert_allclose(wp[0, 0], 8.0 * 0.25 - 0.5 * 8.0 * 0.25**2, atol=1e-5)


def test_curvature_puts_waypoints_on_a_circle_to_the_left():
    # kappa = KAPPA_MAX: a circle of radius 1 / kappa centred at (0, -R) in (x fwd, y right).
    wp = np.asarray(action_to_waypoints(jnp.asarray([0.0, 1.0]), jnp.float32(6.0)), np.float64)
    radius = 1.0 / KAPPA_MAX
    np.testing.assert_allclose(np.hypot(wp[:, 0], wp[:, 1] + radius), radius, rtol=1e-4)
    assert np.all(wp[:, 1] < 0.0)  # left = negative y (y points right)
    # arc length of the last waypoint = v t = 15 m
    angle = np.arctan2(wp[-1, 0], wp[-1, 1] + radius)  # about 2 rad: more than a quarter turn
    np.testing.assert_allclose(radius * angle, 15.0, rtol=1e-4)


def test_observation_vector_hides_unseen_actors():
    from lantern_jax.scenarios.handmade import ActorSpec

    car = ActorSpec(path=[(20.0, 0.0)])
    hidden = ActorSpec(path=[(-30.0, 0.0)])  # behind the ego: not in the camera
    sc = straight_scene([car, hidden])
    x = np.asarray(jax.jit(lambda sc: observation_vector(observe(sc, init_state(sc))))(sc))
    assert x.shape == (OBS_SIZE,) and np.all(np.isfinite(x))
    actors = x[33 : 33 + 16 * ACTOR_FEATURES].reshape(16, ACTOR_FEATURES)
    assert actors[0, 0] == 1.0 and actors[1, 0] == 0.0
    np.testing.assert_allclose(actors[0, 1:3], [20.0 / 50.0, 0.0], atol=1e-5)
    assert not actors[1:].any()  # the hidden car and the empty slots are all zeros


# --- brax's own wrappers ----------------------------------------------------------------------
def _run(wrapped, steps: int, num_envs: int, action=(0.2, 0.0)):
    reset = jax.jit(wrapped.reset)
    state0 = reset(jax.random.split(jax.random.PRNGKey(1), num_envs))
    act = jnp.tile(jnp.asarray([action], jnp.float32), (num_envs, 1))

    def body(state, _):
        nxt = wrapped.step(state, act)
        out = (nxt.done, nxt.reward, nxt.info["steps"], nxt.pipeline_state.index, nxt.obs)
        return nxt, out

    return state0, jax.jit(lambda s: jax.lax.scan(body, s, None, length=steps))(state0)


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_brax_wrap_with_episode_length_and_auto_reset(env):
    wrapped = brax_training.wrap(env, episode_length=12)
    state0, (_, (done, reward, steps, index, obs)) = _run(wrapped, 26, 4)
    assert done.dtype == reward.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(reward)))
    done, steps = np.asarray(done), np.asarray(steps)
    # Truncation after 12 steps: done on steps 12 and 24 (index 11, 23), then counting restarts.
    assert np.all(done[[11, 23]] == 1.0)
    np.testing.assert_array_equal(steps[:12, 0], np.arange(1, 13))
    np.testing.assert_array_equal(steps[12:15, 0], [1, 2, 3])
    # brax's AutoResetWrapper restores the FIRST state: same scene, same first observation.
    np.testing.assert_array_equal(np.asarray(index)[11], np.asarray(state0.pipeline_state.index))
    np.testing.assert_allclose(np.asarray(obs)[11], np.asarray(state0.obs), atol=0)


@pytest.mark.slow
def test_scene_reset_wrapper_draws_new_scenes(env):
    wrapped = lenvs.wrap_for_training(env, episode_length=5)
    state0, (_, (done, _, steps, index, obs)) = _run(wrapped, 40, 8)
    done, index = np.asarray(done), np.asarray(index)
    assert np.all(done[4::5] == 1.0)
    # Eight episodes per slot: with six scenes, some slot must have changed scene.
    assert max(len(set(index[4::5, k])) for k in range(8)) > 1
    # The state after a reset is the bank scene's own first state.
    first = jax.jit(jax.vmap(env.start))(jnp.asarray(index[9]))
    np.testing.assert_allclose(np.asarray(obs)[9], np.asarray(first.obs), atol=0)


@pytest.mark.slow
def test_episode_return_is_the_route_score_or_the_gate_penalty(env):
    """Rewards telescope: their sum over an episode is the final running score R, which is the
    route's score in [0, 1] or -GATE_PENALTY (a gate failed)."""
    step = jax.jit(env.step)
    for index, action in ((0, (0.0, 0.0)), (2, (-1.0, 0.0)), (3, (0.3, 1.0))):
        state = jax.jit(env.start)(jnp.int32(index))
        total, n = 0.0, 0
        while float(state.done) == 0.0 and n < 2000:
            state = step(state, jnp.asarray(action, jnp.float32))
            total += float(state.reward)
            n += 1
        score = float(state.pipeline_state.score)
        assert float(state.done) == 1.0
        assert total == pytest.approx(score, abs=1e-4)
        assert score == -GATE_PENALTY or 0.0 <= score <= 1.0
        if bool(state.pipeline_state.failed):
            assert score == -GATE_PENALTY


def test_ppo_policy_network_matches_brax_inference():
    from brax.training.acme import running_statistics
    from brax.training.agents.ppo import networks as ppo_networks

    from lantern_jax.policies.learned_ppo import network_action

    nets = ppo_networks.make_ppo_networks(
        OBS_SIZE, ACTION_SIZE, preprocess_observations_fn=running_statistics.normalize
    )
    key = jax.random.PRNGKey(0)
    policy = nets.policy_network.init(key)
    x = jax.random.normal(jax.random.PRNGKey(1), (7, OBS_SIZE))
    stats = running_statistics.init_state(jax.ShapeDtypeStruct((OBS_SIZE,), jnp.float32))
    stats = running_statistics.update(stats, x * 3.0 + 1.0)
    infer = ppo_networks.make_inference_fn(nets)((stats, policy), deterministic=True)
    want, _ = infer(x, key)
    layers = [policy["params"][f"hidden_{i}"] for i in range(len(policy["params"]))]
    got = network_action({"obs_mean": stats.mean, "obs_std": stats.std, "layers": layers}, x)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-5)


@pytest.mark.slow
def test_a_few_ppo_iterations_write_a_loadable_policy(tmp_path, monkeypatch):
    from lantern_jax.apps.envs.ppo_training import train
    from lantern_jax.policies.learned_ppo import CHECKPOINT_ENV
    from lantern_jax.policies.registry import get_policy

    ck = tmp_path / "ppo.msgpack"
    curve = train(
        tmp_path, ck, minutes=10, num_timesteps=2 * 8 * 4 * 10, num_evals=2,
        pairs_per_family=1, num_envs=8, batch_size=8, num_minibatches=4, unroll_length=10,
        num_updates_per_batch=1, episode_length=40, num_eval_envs=8,
    )  # fmt: skip
    assert [r["env_steps"] for r in curve] == [0, 640]
    assert all(np.isfinite(r["eval_return"]) for r in curve)
    assert (tmp_path / "learning_curve.csv").exists() and (tmp_path / "learning_curve.png").exists()
    monkeypatch.setenv(CHECKPOINT_ENV, str(ck))
    pol = get_policy("ppo")
    params = pol.init(jax.random.PRNGKey(0))
    sc = straight_scene([])
    wp = jax.jit(pol.act)(params, observe(sc, init_state(sc)))
    assert wp.shape == (10, 2) and np.all(np.isfinite(np.asarray(wp)))
