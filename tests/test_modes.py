"""A driving model whose head proposes several plans and scores them (``ModelConfig.modes``):
the winner-takes-all loss on hand-built plans, the plan it drives, one mode as the model of one
plan, the loss training minimises, what a description and a config may say, and a tiny fit in
which two plans learn the two answers an expert gives for one observation."""

from __future__ import annotations

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from flax import nnx

from lantern_jax.apps.training.config import ConfigError, load_config
from lantern_jax.apps.training.fit import make_loss
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.learned.checkpoint import (
    CheckpointError,
    description_hash,
    load_model,
    new_model,
    save_model,
)
from lantern_jax.policies.learned.features import features, nav_token_table
from lantern_jax.policies.learned.model import MODE_SCORE_WEIGHT, ModelConfig, modes_loss

ONE = ModelConfig(width=16, heads=2)
THREE = dataclasses.replace(ONE, modes=3)


@pytest.fixture(scope="module")
def tables(embedding):
    return embedding, jnp.asarray(nav_token_table())


def _straight(speed_mps: float) -> np.ndarray:
    """(10, 2) float32 m, a plan along x at a constant speed (0.25 s between waypoints)."""
    x = np.arange(1, NUM_WAYPOINTS + 1, dtype=np.float32) * 0.25 * speed_mps
    return np.stack([x, np.zeros_like(x)], -1)


def test_the_loss_of_hand_built_plans():
    """Two plans 0.5 m and 0.1 m off the target in every coordinate, the first scored higher:
    the loss is the nearer plan's L1 (0.1 m) plus the weight times the cross-entropy of the
    scores against it, ln(e^2 + e^0) - 0; the plan driven is the first, 0.5 m off."""
    target = _straight(6.0)
    plans = jnp.asarray(np.stack([target + 0.5, target - 0.1]))
    scores = jnp.asarray([2.0, 0.0])
    objective, driven = modes_loss(plans, scores, jnp.asarray(target))
    expected = 0.1 + MODE_SCORE_WEIGHT * math.log(math.exp(2.0) + 1.0)
    np.testing.assert_allclose(float(objective), expected, rtol=1e-6)
    np.testing.assert_allclose(float(driven), 0.5, rtol=1e-6)
    # scored the other way round, the plan driven is the nearer one and the scores' loss small
    objective, driven = modes_loss(plans, scores[::-1], jnp.asarray(target))
    expected = 0.1 + MODE_SCORE_WEIGHT * math.log1p(math.exp(-2.0))
    np.testing.assert_allclose(float(objective), expected, rtol=1e-6)
    np.testing.assert_allclose(float(driven), 0.1, rtol=1e-6)


def _plans_and_driven(model):
    """A jitted ``f -> (plans, scores, the plan driven)`` of ``model`` (one program)."""
    graphdef, params = nnx.split(model)

    @jax.jit
    def run(p, f):
        m = nnx.merge(graphdef, p)
        return (*m.plans(f), m(f))

    return lambda f: run(params, f)


def test_the_model_drives_the_plan_it_scores_highest(obs, tables):
    f = features(obs, "front", *tables)
    plans, scores, driven = _plans_and_driven(new_model(THREE, seed=3))(f)
    assert plans.shape == (3, NUM_WAYPOINTS, 2) and scores.shape == (3,)
    assert np.all(np.isfinite(np.asarray(plans))) and np.all(np.isfinite(np.asarray(scores)))
    assert len({tuple(np.asarray(p).ravel().round(4)) for p in plans}) == 3  # three plans
    best = int(np.argmax(np.asarray(scores)))
    np.testing.assert_array_equal(np.asarray(driven), np.asarray(plans[best]))


def test_one_mode_is_the_model_of_one_plan(obs, tables):
    """The default head proposes one plan with a score of zero, and the model drives it."""
    assert ModelConfig().modes == 1
    model = new_model(ONE, seed=3)
    f = features(obs, "front", *tables)
    plans, scores = model.plans(f)
    assert plans.shape == (1, NUM_WAYPOINTS, 2)
    np.testing.assert_array_equal(np.asarray(scores), [0.0])
    np.testing.assert_array_equal(np.asarray(model(f)), np.asarray(plans[0]))
    assert nnx.state(model, nnx.Param)["head"]["layers"][1]["kernel"][...].shape == (16, 20)
    head = nnx.state(new_model(THREE, seed=3), nnx.Param)["head"]["layers"][1]["kernel"][...]
    assert head.shape == (16, 3 * 20 + 3)  # three plans' increments and three scores


def _batch(obs, n: int) -> dict:
    """``n`` copies of ``obs`` as the example columns training reads."""
    names = [f.name for f in dataclasses.fields(obs) if getattr(obs, f.name) is not None]
    return {k: jnp.stack([getattr(obs, k)] * n) for k in names}


def _modes_loss_reference(plans: np.ndarray, scores: np.ndarray, target: np.ndarray):
    """NumPy reference of :func:`modes_loss` for one example (float64)."""
    l1 = np.abs(plans.astype(np.float64) - target[None]).mean(axis=(1, 2))
    nearest = int(np.argmin(l1))
    s = scores.astype(np.float64)
    cross_entropy = np.log(np.exp(s - s.max()).sum()) + s.max() - s[nearest]
    return l1[nearest] + MODE_SCORE_WEIGHT * cross_entropy, l1[int(np.argmax(s))]


def test_the_training_loss_and_the_validation_figure(obs, tables):
    """``make_loss`` of a three-plan model is the batch's mean :func:`modes_loss` (against a
    NumPy reference); with ``driven`` the mean L1 of the plans driven; its gradient is finite
    and reaches the scores' and the plans' weights."""
    model = new_model(THREE, seed=8)
    graphdef, params = nnx.split(model)
    batch = _batch(obs, 4)
    targets = np.stack([_straight(v) for v in (0.0, 2.0, 5.0, 9.0)])
    plans, scores, _ = _plans_and_driven(model)(features(obs, "front", *tables))
    by_hand = np.asarray([_modes_loss_reference(np.asarray(plans), np.asarray(scores), t)
                          for t in targets])  # fmt: skip

    @jax.jit  # the tables an argument, as training passes them (not a 33 MB captured constant)
    def figures(p, g, t, tabs):
        loss, driven = (make_loss(g, "front", driven=d) for d in (False, True))
        return (loss(p, batch, t, *tabs), driven(p, batch, t, *tabs),
                jax.grad(loss)(p, batch, t, *tabs))  # fmt: skip

    objective, driven, grads = figures(params, graphdef, jnp.asarray(targets), tables)
    np.testing.assert_allclose(float(objective), by_hand[:, 0].mean(), rtol=1e-5)
    np.testing.assert_allclose(float(driven), by_hand[:, 1].mean(), rtol=1e-5)
    kernel = np.asarray(grads["head"]["layers"][1]["kernel"][...])  # (16, 63)
    assert np.all(np.isfinite(kernel))
    assert np.abs(kernel[:, :60]).max() > 0 and np.abs(kernel[:, 60:]).max() > 0


def test_two_plans_learn_both_answers_the_expert_gives_for_one_observation(obs, tables):
    """One observation, labelled half the time with a stop and half the time with a drive at 8
    m/s, as the expert labels a restart the model cannot tell apart.  Any one plan lies at
    least half their distance (5.5 m on the L1 of the last waypoint) from one of them; after
    training, each of a two-plan model's answers lies within a tenth of that of one of its
    plans, and the scores split about evenly."""
    targets = np.stack([_straight(0.0), _straight(8.0)] * 8)  # (16, 10, 2)
    f = features(obs, "front", *tables)
    batch = jax.tree.map(lambda x: jnp.stack([x] * len(targets)), f)
    graphdef, params = nnx.split(new_model(dataclasses.replace(ONE, modes=2), seed=4))
    tx = optax.adam(3e-3)
    opt = tx.init(params)

    def loss(p):
        plans, scores = jax.vmap(nnx.merge(graphdef, p).plans)(batch)
        return jnp.mean(jax.vmap(modes_loss)(plans, scores, jnp.asarray(targets))[0])

    @jax.jit
    def step(p, s):
        g = jax.grad(loss)(p)
        u, s = tx.update(g, s, p)
        return optax.apply_updates(p, u), s

    for _ in range(400):
        params, opt = step(params, opt)
    plans, scores = nnx.merge(graphdef, params).plans(f)
    plans = np.asarray(plans)
    for answer in (_straight(0.0), _straight(8.0)):
        nearest = np.min(np.abs(plans - answer[None]).mean(axis=(1, 2)))
        assert nearest < 0.1 * 0.5 * np.abs(_straight(8.0)).mean(), nearest
    p = np.asarray(jax.nn.softmax(scores))
    assert np.all(np.abs(p - 0.5) < 0.15), p


def test_bad_modes_are_refused(tmp_path):
    """A config's ``modes`` below one names the field; a description without ``modes`` is a
    model of one plan (written before the field existed); one saying 0, true or "3" names
    ``config.modes``; a model of three plans is not one of one."""
    path = tmp_path / "t.toml"
    path.write_text('[train]\nname = "x"\nrecipe = "base"\nmodes = 0\n')
    with pytest.raises(ConfigError, match=r"modes: must be >= 1, got 0"):
        load_config(path)
    save_model(new_model(ONE, seed=1), tmp_path / "m")
    meta_path = tmp_path / "m.json"
    meta = json.loads(meta_path.read_text())
    del meta["config"]["modes"]
    meta["sha256"] = description_hash(meta)
    meta_path.write_text(json.dumps(meta))
    assert load_model(tmp_path / "m", expect=ONE).config == ONE
    for bad in (0, True, "3"):
        meta["config"]["modes"] = bad
        meta["sha256"] = description_hash(meta)
        meta_path.write_text(json.dumps(meta))
        with pytest.raises(CheckpointError, match=r"config\.modes"):
            load_model(tmp_path / "m")
    save_model(new_model(THREE, seed=1), tmp_path / "three")
    with pytest.raises(CheckpointError, match=r"config\.modes"):
        load_model(tmp_path / "three", expect=ONE)
    assert load_model(tmp_path / "three").config == THREE
