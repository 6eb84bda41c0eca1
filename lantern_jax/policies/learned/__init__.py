"""Learned warning-conditioned driving policies (flax NNX).

* :mod:`~lantern_jax.policies.learned.features` — the policy observation turned into model
  inputs (ego state, navigation, perceived objects, range image, and the text channel: the
  warning's pooled token embedding when a warning is active, else a navigation instruction
  rendered from the route);
* :mod:`~lantern_jax.policies.learned.model` — a small network: object tokens through
  self-attention, range-image and ego/navigation encoders, a trunk conditioned on the language
  embedding (FiLM) and the stated position, ten waypoints out;
* :mod:`~lantern_jax.policies.learned.checkpoint` — trained weights as an ordinary pure
  ``init/act`` policy, saved and loaded with their architecture (a mismatch is refused).
* :mod:`~lantern_jax.policies.learned.ensemble` — several models of one architecture as one
  policy that drives with the mean of their plans (:func:`~lantern_jax.policies.learned.
  ensemble.ensemble_policy`).

Training lives in :mod:`lantern_jax.apps.training` (it reads the open-loop dataset).
"""
