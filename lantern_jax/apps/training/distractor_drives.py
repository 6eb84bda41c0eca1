"""Distractor drives: Route A told a distractor sentence in place of its warning, each visit
labelled with the learner's own plan for the same observation without the sentence.

The counterfactual frames (:mod:`lantern_jax.apps.training.counterfactual`) tell Route B frames
a distractor sentence ("The cafe at position (x, y) opens at nine ...") with the ordinary
label: a stated position alone is no reason to react.  But Route B holds no hazard actor, so
they never show the model a sentence that names the position of a car it can see waiting to
cut in, and that is where the language check's irrelevant sentence moved the word readers
(``docs/learned.md``, "Visits without the warning"): their VC drives kept up to 40 % of the
warning's gain under a sentence about a bakery.

A distractor drive is the closed-loop round's Route A of a pair, its protocol delivering one of
the training distractor sentences (the set ``distractor_texts`` names, never the language
check's probes) where the warning would be, at the warning's own stated position; the learner
drives alone (beta 0).  Every visit at which the sentence is in the learner's observation is
kept, and its label is what the learner itself plans for the same observation *without* the
sentence (:func:`own_plans`: the warning tokens all padding, which is how no warning reads).
The label asks for one thing: that the sentence change nothing.  The expert is not asked:
without the warning the privileged expert still anticipates the hazard it cannot see.

What it does, measured (``docs/learned.md``, "Distractor drives"): the sentence's effect on VC
shrinks a little, but the label is the learner's own unwarned plan, late reaction included,
in Route A states that no expert label reaches, so each round copies that reaction back and it
can drift: in two of three seeds VC's unwarned driving got markedly worse, which is what made
the VC warning gain (and the language check's shares) larger.  Pairing these drives with
expert-labelled no-warning visits (``no_warning``) would anchor those states; it was not tried.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.apps.dataset.record import data_settings
from lantern_jax.apps.training.counterfactual import distractor_bank
from lantern_jax.policies.learned.checkpoint import LearnedParams, learned_act
from lantern_jax.sim.settings import Settings
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import Observation
from lantern_jax.types.world import Scenario

#: Sequence-id suffix of a distractor drive's visits (``<family>_<index>_A-distractor``).
SEQUENCE_SUFFIX = "_A-distractor"


def distractor_scenarios(route_a: Scenario, texts: str, seed: int, r: int,
                         settings: Settings | None = None
                         ) -> tuple[Scenario, Settings, np.ndarray]:  # fmt: skip
    """``route_a`` (stacked Route A scenarios, leading axis n) in the warning condition, each
    told a distractor sentence of the set ``texts`` in place of its warning (drawn per
    scenario, seeded by ``seed`` and round ``r``).

    Returns:
        the scenarios, ``settings`` (default :func:`~lantern_jax.apps.dataset.record
        .data_settings`) with a bank that holds the distractor sentences, and the (n,) int32
        text ids told.
    """
    settings = data_settings() if settings is None else settings
    bank, ids = distractor_bank(texts)
    cfg = route_a.config
    told = np.random.default_rng([seed, 44, r]).choice(ids, cfg.family.shape[0]).astype(np.int32)
    text_id = jnp.asarray(told).reshape(np.shape(cfg.text_id))
    warned = cfg.replace(text_id=text_id, warning_enabled=jnp.ones_like(cfg.warning_enabled))
    return route_a.replace(config=warned), settings.replace(bank=bank), told


def text_in_view(obs: Observation) -> np.ndarray:
    """(..., ) bool: the observations that hold a text (any warning token not padding), over
    ``obs.warning_tokens`` (..., L)."""
    return np.any(np.asarray(obs.warning_tokens) != PAD_ID, axis=-1)


def without_text(obs: Observation) -> Observation:
    """``obs`` as it reads with no warning: every warning token padding, every value 0."""
    return obs.replace(warning_tokens=jnp.full_like(obs.warning_tokens, PAD_ID),
                       warning_values=jnp.zeros_like(obs.warning_values))  # fmt: skip


@jax.jit
def own_plans(params: LearnedParams, obs: Observation) -> jax.Array:
    """(B, V, 10, 2) float32, m, ego frame: the learner's plan for each observation of ``obs``
    (leading axes (B, V)) read without its text."""
    plan = jax.vmap(jax.vmap(learned_act, (None, 0)), (None, 0))
    return plan(params, without_text(obs))
