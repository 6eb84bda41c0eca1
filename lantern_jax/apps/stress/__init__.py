"""Scenario stress testing: search a scenario for the hazards that break a policy, plausibly.

* :mod:`~lantern_jax.apps.stress.space` — search spaces behind one interface: a family's knobs
  (documented ranges, :data:`lantern_jax.scenarios.families.KNOB_RANGES`), adversarial tracks of
  its actors (:mod:`lantern_jax.dynamics.adversary`; knots and knot length chosen by the user),
  or both; a sigmoid maps an unconstrained vector into the space, so every candidate is valid;
* :mod:`~lantern_jax.apps.stress.plausibility` — what counts as a plausible failure (the privileged
  expert drives the scene with margin; no actor freezes in the ego's path, leaves the road or
  exceeds its limits) and the smooth terms that target it;
* :mod:`~lantern_jax.apps.stress.watch` — rollouts that also watch the actors a search controls;
* :mod:`~lantern_jax.apps.stress.objective` — the smooth surrogate (the policy's part and the
  expert's part) through the differentiable simulator, and its gradients: first-order
  (pathwise), zeroth-order (Gaussian smoothing) and a blend chosen by a bias test;
* :mod:`~lantern_jax.apps.stress.verify` — the exact (hard) verification every method shares;
* :mod:`~lantern_jax.apps.stress.search` — gradient search, random search and CMA-ES, interleaved in
  one process, with rollouts counted by kind and per restart;
* :mod:`~lantern_jax.apps.stress.catalogue` — the distinct failures (the near-duplicate rule on the
  adversary's trajectory), each a suite pair with a one-line description and a view;
* :mod:`~lantern_jax.apps.stress.report` — the whole run, the comparison table, the result files and
  the gradient check;
* :mod:`~lantern_jax.apps.stress.fragility` — every pair's first-order distance to a collision over
  its normalised knobs, from one vmapped backward pass over the suite, verified by hard rollouts.
"""
