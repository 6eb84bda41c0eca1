"""Non-JAX policies through a host callback: one batched call per tick, same waypoints as JAX."""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.policies.features import OBS_SIZE
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import rollout, rollout_batch
from lantern_jax.sim.state import init_state
from lantern_jax.types.world import tree_stack

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import host_models  # noqa: E402

WEIGHTS = host_models.make_weights(seed=3)


class Counting:
    """The NumPy model, recording the batch size of every call."""

    def __init__(self):
        self.model = host_models.numpy_model(WEIGHTS)
        self.batches: list[int] = []

    def __call__(self, x):
        assert x.ndim == 2 and x.shape[1] == OBS_SIZE
        self.batches.append(x.shape[0])
        return self.model(x)


def _scenes(n: int):
    """n straight scenes that differ in their start speed (6, 7, ... m/s)."""
    return tree_stack([straight_scene([], speed=6.0 + k) for k in range(n)])


_OBSERVE = jax.jit(jax.vmap(lambda sc: observe(sc, init_state(sc), ("warning",))))


def _observations(scenarios):
    return _OBSERVE(scenarios)


def test_same_waypoints_as_the_jax_model_in_one_batched_call():
    counting = Counting()
    host = host_models.numpy_policy(WEIGHTS, fn=counting)
    obs = _observations(_scenes(5))
    got = jax.jit(jax.vmap(lambda o: host.act({}, o)))(obs)
    want = jax.jit(jax.vmap(lambda o: host_models.jax_act(WEIGHTS)({}, o)))(obs)
    assert counting.batches == [5]  # one call for the whole batch, not five
    assert got.shape == (5, 10, 2)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=0, atol=1e-5)


def test_unbatched_and_nested_vmap_reach_the_model_as_one_flat_batch():
    counting = Counting()
    host = host_models.numpy_policy(WEIGHTS, fn=counting)
    obs = _observations(_scenes(6))
    single = jax.jit(lambda o: host.act({}, o))(jax.tree.map(lambda x: x[0], obs))
    nested = jax.tree.map(lambda x: x.reshape((2, 3, *x.shape[1:])), obs)
    both = jax.jit(jax.vmap(jax.vmap(lambda o: host.act({}, o))))(nested)
    assert counting.batches == [1, 6]
    assert single.shape == (10, 2) and both.shape == (2, 3, 10, 2)
    np.testing.assert_allclose(np.asarray(both[0, 0]), np.asarray(single), atol=1e-5)


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_one_call_per_tick_in_the_batched_rollout():
    counting = Counting()
    host = host_models.numpy_policy(WEIGHTS, fn=counting)
    scenes = _scenes(3)
    # 40 ticks = one chunk of the early-exit driver; the batch does not end within it.
    jax.block_until_ready(rollout_batch(scenes, host, {}, 40, chunk=40))
    assert counting.batches == [3] * 40


@pytest.mark.slow
def test_closed_loop_rollout_matches_the_jax_model():
    host = host_models.numpy_policy(WEIGHTS)
    jax_policy = host_models.jax_policy(WEIGHTS)
    scene = straight_scene([], speed=8.0)
    run = lambda pol: jax.jit(lambda sc: rollout(sc, pol, {}, 120, record=True))(scene)  # noqa: E731
    (_, rec_h), (_, rec_j) = run(host), run(jax_policy)
    # Same model, same observations -> same plans tick after tick (float32 rounding only).
    np.testing.assert_allclose(np.asarray(rec_h.waypoints), np.asarray(rec_j.waypoints), atol=1e-3)
    np.testing.assert_allclose(np.asarray(rec_h.ego_xy), np.asarray(rec_j.ego_xy), atol=1e-3)


def test_wrong_output_shape_names_the_policy():
    host = host_models.numpy_policy(WEIGHTS, "bad-shape", fn=lambda x: np.zeros((x.shape[0], 3)))
    obs = _observations(_scenes(2))
    with pytest.raises(Exception, match="bad-shape"):
        jax.block_until_ready(jax.jit(jax.vmap(lambda o: host.act({}, o)))(obs))


def test_onnx_runtime_example_matches_the_jax_model():
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    onnx = host_models.numpy_policy(WEIGHTS, "onnx-mlp", host_models.onnx_model(WEIGHTS))
    obs = _observations(_scenes(4))
    got = jax.jit(jax.vmap(lambda o: onnx.act({}, o)))(obs)
    want = jax.jit(jax.vmap(lambda o: host_models.jax_act(WEIGHTS)({}, o)))(obs)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-4)
    assert jnp.all(jnp.isfinite(got))


def test_a_host_model_of_the_wrong_shape_is_one_line_on_the_command_line(tmp_path, capfd):
    """A host model returning the wrong shape from a policy file: the command ends with one
    line naming the policy and both shapes (no runtime wrapper, no logged traceback), the
    callback's error named as raised in the user's file when it is raised there."""
    from lantern_jax.cli import main

    path = tmp_path / "bad_host.py"
    path.write_text(
        "import numpy as np\n"
        "from lantern_jax.policies.host import host_policy\n"
        "from lantern_jax.policies.features import observation_vector\n"
        "def model(x):\n"
        "    return np.zeros((x.shape[0], 3, 2), np.float32)\n"
        "def broken(x):\n"
        "    return x.no_such_attribute\n"
        "SHAPE = host_policy('badshape', model, preprocess=observation_vector)\n"
        "RAISES = host_policy('raises', broken, preprocess=observation_vector)\n"
    )
    code = main(["evaluate", "--policy", f"{path}:SHAPE", "--pairs", "pe_0001",
                 "--out", str(tmp_path / "r"), "--quiet"])  # fmt: skip
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if "error" in ln.lower() or "Traceback" in ln]
    assert code == 1 and len(lines) == 1, err
    assert "'badshape'" in lines[0] and "(48, 3, 2)" in lines[0] and "(48, 10, 2)" in lines[0]
    assert "Runtime" not in lines[0] and "pure_callback" not in err
    assert main(["evaluate", "--policy", f"{path}:RAISES", "--pairs", "pe_0001",
                 "--out", str(tmp_path / "r2"), "--quiet"]) == 1  # fmt: skip
    err = capfd.readouterr().err
    assert "AttributeError" in err and "bad_host.py:7" in err and "Traceback" not in err, err
