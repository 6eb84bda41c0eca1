"""The Gymnasium-style vector environment: arrays, same-step autoreset, determinism, checks."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE

pytest.importorskip("brax")
import lantern_jax.apps.envs as lenvs  # noqa: E402
from lantern_jax.apps.envs.reward import GATE_PENALTY  # noqa: E402
from lantern_jax.apps.envs.vector import LanternVectorEnv  # noqa: E402

# the vector environment compiles its own step (about a minute on two cores): the slow tier
pytestmark = pytest.mark.slow

B, STEPS, CAP, SEED = 4, 60, 40, 3


def _actions(steps: int) -> np.ndarray:
    """(steps, B, 2) float32: throttle in [0, 1] and a hard left turn (curvature in [0.8, 1]),
    so that some episodes fail the lane gate within a second and the others reach the cap."""
    rng = np.random.default_rng(0)
    accel = rng.uniform(0.0, 1.0, (steps, B))
    curv = rng.uniform(0.8, 1.0, (steps, B))
    return np.stack([accel, curv], axis=-1).astype(np.float32)


@pytest.fixture(scope="module")
def bank():
    return lenvs.build_bank(pairs_per_family=1, families=("PE", "VC"))


@pytest.fixture(scope="module")
def run(bank):
    env = LanternVectorEnv(B, bank=bank, seed=SEED, max_episode_steps=CAP)
    obs0, info0 = env.reset()
    steps = [env.step(a) for a in _actions(STEPS)]
    return env, obs0, info0, steps


def test_exported_and_spaces(bank, run):
    env = run[0]
    assert lenvs.LanternVectorEnv is LanternVectorEnv
    assert env.num_envs == B
    assert env.single_observation_space.shape == (OBS_SIZE,)
    assert env.single_action_space.shape == (ACTION_SIZE,)
    assert env.observation_space.shape == (B, OBS_SIZE)
    assert env.action_space.shape == (B, ACTION_SIZE)
    for space in (env.single_observation_space, env.observation_space):
        assert space.dtype == np.float32
    for space in (env.single_action_space, env.action_space):
        assert space.dtype == np.float32
        assert np.all(space.low == -1.0) and np.all(space.high == 1.0)
    assert str(env.metadata["autoreset_mode"]).lower().replace("_", "").endswith("samestep")


def test_shapes_dtypes_and_finite_rewards(run):
    _, obs0, info0, steps = run
    assert obs0.shape == (B, OBS_SIZE) and obs0.dtype == np.float32 and info0 == {}
    for obs, rew, term, trunc, infos in steps:
        assert obs.shape == (B, OBS_SIZE) and obs.dtype == np.float32
        assert np.all(np.isfinite(obs))
        assert rew.shape == (B,) and rew.dtype == np.float32 and np.all(np.isfinite(rew))
        assert term.shape == trunc.shape == (B,) and term.dtype == trunc.dtype == np.bool_
        assert not np.any(term & trunc)
        ended = term | trunc
        if not ended.any():
            assert infos == {}
            continue
        assert infos["final_obs"].shape == (B, OBS_SIZE)
        assert infos["final_obs"].dtype == np.float32
        np.testing.assert_array_equal(infos["_final_obs"], ended)
        np.testing.assert_array_equal(infos["_episode"], ended)
        ep = infos["episode"]
        assert ep["r"].dtype == ep["t"].dtype == np.float32 and ep["l"].dtype == np.int32
        for key in ("r", "l", "t", "progress", "gate_failure", "completed", "route_timeout"):
            assert ep[key].shape == (B,)
            assert not np.any(ep[key][~ended])  # rows of running episodes are zeros


def test_autoreset_same_step(bank, run):
    """Every slot ends at least once (a gate failure from the hard turn, or the step cap); on the
    ending step the reward and ``infos`` belong to the ending episode and ``obs`` is the first
    observation of a bank scene (the next episode's)."""
    _, obs0, _, steps = run
    start = jax.jit(jax.vmap(lenvs.LanternEnv(bank).start))
    firsts = np.asarray(start(jnp.arange(bank.size, dtype=jnp.int32)).obs)  # (N, OBS_SIZE)
    ret, length = np.zeros(B), np.zeros(B, int)
    ends = {"term": 0, "trunc": 0}
    for obs, rew, term, trunc, infos in steps:
        ret += rew
        length += 1
        for i in np.nonzero(term | trunc)[0]:
            ep = infos["episode"]
            assert ep["r"][i] == pytest.approx(ret[i], abs=1e-5)  # the episode's own return
            assert ep["l"][i] == length[i]
            assert ep["t"][i] >= 0.0
            assert np.any(np.all(obs[i] == firsts, axis=1)), "obs after an end is a scene start"
            assert not np.array_equal(infos["final_obs"][i], obs[i])
            if term[i]:
                ends["term"] += 1
                assert ep["gate_failure"][i] == 1.0
                assert ep["r"][i] == pytest.approx(-GATE_PENALTY, abs=1e-5)
            else:
                ends["trunc"] += 1
                assert ep["l"][i] == CAP and ep["gate_failure"][i] == 0.0
                assert not ep["route_timeout"][i]
            ret[i], length[i] = 0.0, 0
    assert ends["term"] >= 1 and ends["trunc"] >= 1, ends


def test_same_seed_same_actions_same_observations(bank, run):
    env, obs0, _, steps = run
    other = LanternVectorEnv(B, bank=bank, seed=SEED, max_episode_steps=CAP)
    obs, _ = other.reset()
    np.testing.assert_array_equal(obs, obs0)
    for a, (want, rew_want, term_want, *_rest) in zip(
        _actions(STEPS)[:20], steps[:20], strict=True
    ):
        obs, rew, term, _, _ = other.step(a)
        np.testing.assert_array_equal(obs, want)
        np.testing.assert_array_equal(rew, rew_want)
        np.testing.assert_array_equal(term, term_want)
    # reset(seed=...) replays from the start; another seed draws other scenes
    np.testing.assert_array_equal(other.reset(seed=SEED)[0], obs0)
    assert not np.array_equal(other.reset(seed=SEED + 1)[0], obs0)
    other.close()


def test_route_timeout_is_a_termination(bank, run):
    """With a 1 s route timeout on the VC scenes, slots that survive the turn for 20 ticks on
    them end at the timeout: a termination (a failed gate, return -1) marked ``route_timeout``.
    A bank of the same size reuses the compiled step."""
    cfg = bank.scenarios.config
    short = jnp.where(jnp.arange(bank.size) >= 3, 1.0, cfg.timeout_s)  # s
    scenarios = bank.scenarios.replace(config=cfg.replace(timeout_s=short))
    short_bank = dataclasses.replace(bank, scenarios=scenarios)
    env = LanternVectorEnv(B, bank=short_bank, seed=SEED, max_episode_steps=CAP)
    env.reset()
    timeouts = 0
    for a in _actions(STEPS)[:30]:
        _, _, term, trunc, infos = env.step(a)
        assert not trunc.any()
        if term.any():
            ep = infos["episode"]
            for i in np.nonzero(ep["route_timeout"])[0]:
                timeouts += 1
                assert term[i] and ep["l"][i] == 20 and ep["gate_failure"][i] == 1.0
                assert ep["r"][i] == pytest.approx(-GATE_PENALTY, abs=1e-5)
    assert timeouts >= 1
    env.close()


def test_bad_actions_and_calls_are_refused(bank, run):
    env = run[0]
    shape = f"({B}, {ACTION_SIZE})"
    good = np.zeros((B, ACTION_SIZE), np.float32)
    for bad in (good[:, :1], good[:2], good.ravel(), np.zeros((B, ACTION_SIZE), np.int32)):
        with pytest.raises(ValueError, match=rf"\({B}, {ACTION_SIZE}\)"):
            env.step(bad)
    for value in (np.nan, np.inf):
        bad = good.copy()
        bad[2, 1] = value
        with pytest.raises(ValueError, match="finite") as err:
            env.step(bad)
        assert shape in str(err.value)
    fresh = LanternVectorEnv(B, bank=bank, seed=SEED, max_episode_steps=CAP)
    with pytest.raises(RuntimeError, match="reset"):
        fresh.step(good)
    with pytest.raises(ValueError, match="seed"):
        fresh.reset(seed=1.5)
    with pytest.raises(ValueError, match="options"):
        fresh.reset(options={"reset_mask": np.ones(B, bool)})
    fresh.close()
    fresh.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        fresh.reset()
    with pytest.raises(ValueError, match="num_envs"):
        LanternVectorEnv(0, bank=bank)
