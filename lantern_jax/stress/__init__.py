"""Scenario stress testing: search a family's scenario knobs for the hazards that break a policy.

* :mod:`~lantern_jax.stress.space` — the search space of a family (its knobs and documented
  ranges, :data:`lantern_jax.scenarios.families.KNOB_RANGES`) and the map from an unconstrained
  vector into it (a sigmoid per knob, so every candidate is a valid scenario);
* :mod:`~lantern_jax.stress.objective` — smooth failure surrogates computed through the
  differentiable simulator, and their gradients: first-order (pathwise), zeroth-order (Gaussian
  smoothing) and a blend of the two chosen by a bias test;
* :mod:`~lantern_jax.stress.verify` — the exact (hard) verification of candidates: the policy's
  pair CUS and gates, and the plausibility guard (the privileged expert must still pass);
* :mod:`~lantern_jax.stress.search` — gradient search, random search and CMA-ES at equal
  wall-clock budget with the same restarts and the same verification;
* :mod:`~lantern_jax.stress.report` — the comparison table, the found scenarios (as a suite file
  any evaluation can run) and the convergence plot.
"""
