"""Distractor drives of the closed-loop recipe (:mod:`lantern_jax.apps.training.distractor_drives`):
Route A told a training distractor sentence in place of its warning, each visit labelled with
the learner's own plan without the sentence."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.apps.training import closed_loop as cl
from lantern_jax.apps.training import distractor_drives as dd
from lantern_jax.apps.training.config import ConfigError, load_config
from lantern_jax.apps.training.counterfactual import distractor_bank
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.learned.checkpoint import learned_act, learned_params, new_model
from lantern_jax.policies.learned.model import ModelConfig
from lantern_jax.scenarios.warning_texts import DISTRACTOR_SETS, PROBE_IRRELEVANT, PROBE_NEGATED
from lantern_jax.scenarios.warnings import warning_language

BIGRAM = ModelConfig(width=16, heads=2, text_encoder="bigram")  # the recipe's word reader


def _specs(families):
    from lantern_jax.apps.dataset.scenes import SceneSpec
    from lantern_jax.scenarios.families import sample_params

    rng = np.random.default_rng(0)
    return [SceneSpec(i, f, "clear_day", sample_params(f, rng), "")
            for i, f in enumerate(families)]  # fmt: skip


def test_the_label_is_the_learners_plan_for_the_observation_without_its_sentence(obs, embedding):
    """``own_plans`` of a (B, V) batch of observations told a distractor sentence is, entry by
    entry, the learner's plan for the observation as no warning reads it (every token padding,
    every value 0) -- here the fixture's own observation, which holds no text -- and not its
    plan with the sentence, which a word reader reads."""
    params = learned_params(new_model(BIGRAM, seed=3), embedding)
    bank, ids = distractor_bank("position_lane_negations")
    told = []
    for k, text_id in enumerate(ids[:6]):
        tokens, values = warning_language(jnp.int32(text_id), jnp.bool_(True),
                                          jnp.asarray((20.0 + 5 * k, 1.5), jnp.float32),
                                          bank)  # fmt: skip
        told.append(obs.replace(warning_tokens=tokens, warning_values=values))
    batch = jax.tree.map(lambda *x: jnp.stack(x).reshape(2, 3, *x[0].shape), *told)
    assert dd.text_in_view(batch).all() and not dd.text_in_view(obs)

    plans = np.asarray(own_plans := dd.own_plans(params, batch))
    assert own_plans.shape == (2, 3, NUM_WAYPOINTS, 2) and np.isfinite(plans).all()
    quiet = np.asarray(learned_act(params, obs))
    np.testing.assert_allclose(plans, np.broadcast_to(quiet, plans.shape), rtol=1e-6, atol=1e-6)
    with_text = np.asarray(jax.vmap(learned_act, (None, 0))(params, jax.tree.map(
        lambda x: x.reshape(6, *x.shape[2:]), batch)))  # fmt: skip
    assert np.abs(with_text - quiet).max(axis=(1, 2)).min() > 1e-4


def test_a_drive_tells_a_training_distractor_where_its_warning_would_be():
    """Route A in the warning condition, each pair told a sentence of the chosen distractor set
    (never a language-check probe), from a bank that holds it; the draw is the seed's and the
    round's."""
    route_a = cl._route_a_batch(_specs(["PE", "VC", "LWW", "RTY"]))
    scenarios, settings, told = dd.distractor_scenarios(route_a, "position", seed=0, r=0)
    cfg = scenarios.config
    assert np.asarray(cfg.is_route_a).all() and np.asarray(cfg.warning_enabled).all()
    np.testing.assert_array_equal(np.asarray(cfg.text_id).reshape(-1), told)
    bank, ids = distractor_bank("position")
    assert set(told.tolist()) <= set(ids.tolist())
    assert settings.bank == bank
    texts = [settings.bank.entries[i].text for i in told]
    assert all(t in DISTRACTOR_SETS["position"] for t in texts)
    assert PROBE_IRRELEVANT not in texts and PROBE_NEGATED not in texts
    again = dd.distractor_scenarios(route_a, "position", seed=0, r=0)[2]
    np.testing.assert_array_equal(again, told)
    rounds = {tuple(dd.distractor_scenarios(route_a, "position", seed=0, r=r)[2]) for r in range(4)}
    assert len(rounds) > 1


@pytest.mark.parametrize(("line", "key"), [
    ("distractor_drives = 1.5", "distractor_drives"),
    ("distractor_drives = -0.1", "distractor_drives"),
    ("distractor_drive_every_s = 0.0", "distractor_drive_every_s"),
])  # fmt: skip
def test_distractor_drive_settings_are_checked(tmp_path, line, key):
    bad = tmp_path / "bad.toml"
    base = '[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
    bad.write_text(base + line + "\n")
    with pytest.raises(ConfigError, match=rf"train\.{key}:"):
        load_config(bad)
    bad.write_text(base + "distractor_drives = 1.0\ndistractor_drive_every_s = 0.25\n")
    cfg = load_config(bad)
    assert cfg.distractor_drives == 1.0 and cfg.distractor_drive_every_s == 0.25
