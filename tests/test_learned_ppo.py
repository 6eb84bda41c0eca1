"""The shipped ``ppo`` policy: its checkpoint loads without brax, it acts, it evaluates."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.policies import learned_ppo
from lantern_jax.policies.base import check_policy_output
from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state


def _tiny_checkpoint(path, obs_size=OBS_SIZE, out=2 * ACTION_SIZE):
    rng = np.random.default_rng(0)
    layers = {
        "hidden_0": {"kernel": rng.normal(size=(obs_size, 8)), "bias": np.zeros(8)},
        "hidden_1": {"kernel": rng.normal(size=(8, out)), "bias": np.zeros(out)},
    }
    learned_ppo.save_checkpoint(path, np.zeros(obs_size), np.ones(obs_size), layers, {"x": 1})


def test_shipped_checkpoint_loads_and_acts(monkeypatch):
    monkeypatch.delenv(learned_ppo.CHECKPOINT_ENV, raising=False)
    assert learned_ppo.SHIPPED_CHECKPOINT.is_file()
    ck = learned_ppo.load_checkpoint()
    assert ck["meta"]["obs_size"] == OBS_SIZE and "env_steps" in ck["meta"]
    pol = get_policy("ppo")
    params = pol.init(jax.random.PRNGKey(0))
    sc = straight_scene([])
    obs = observe(sc, init_state(sc))
    check_policy_output(pol, params, obs)
    wp = np.asarray(jax.jit(pol.act)(params, obs))
    assert wp.shape == (10, 2) and np.all(np.isfinite(wp))


def test_checkpoint_round_trip_and_bad_files(tmp_path, monkeypatch):
    good = tmp_path / "good.msgpack"
    _tiny_checkpoint(good)
    monkeypatch.setenv(learned_ppo.CHECKPOINT_ENV, str(good))
    params = get_policy("ppo").init(jax.random.PRNGKey(0))
    assert [p["kernel"].shape for p in params["layers"]] == [(OBS_SIZE, 8), (8, 4)]
    x = np.zeros((3, OBS_SIZE), np.float32)
    a = np.asarray(learned_ppo.network_action(params, x))
    assert a.shape == (3, ACTION_SIZE) and np.all(np.abs(a) <= 1.0)
    with pytest.raises(FileNotFoundError, match=learned_ppo.CHECKPOINT_ENV):
        learned_ppo.load_checkpoint(tmp_path / "missing.msgpack")
    small = tmp_path / "small.msgpack"
    _tiny_checkpoint(small, obs_size=OBS_SIZE - 1)
    with pytest.raises(ValueError, match="observation size"):
        learned_ppo.load_checkpoint(small)
    wide = tmp_path / "wide.msgpack"
    _tiny_checkpoint(wide, out=6)
    with pytest.raises(ValueError, match="output size"):
        learned_ppo.load_checkpoint(wide)


@pytest.mark.slow
def test_ppo_evaluates_like_any_policy(monkeypatch):
    """On the split path: the test session's world program, only the policy's own compiled."""
    monkeypatch.delenv(learned_ppo.CHECKPOINT_ENV, raising=False)
    result = evaluate(["ppo"], suite=load_suite().subset(1), progress=False, path="split")
    assert len(result.route_table) == 12 and set(result.route_table["model"]) == {"ppo"}
    assert np.all(np.isfinite(result.family_table.drop(columns=["model", "condition"])))
