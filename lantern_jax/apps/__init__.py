"""The applications, above the simulator (:mod:`lantern_jax.sim`) and the report
(:mod:`lantern_jax.report`): the evaluation of policies on a suite, suite generation, stress
testing, the dataset, the language diagnostics, the ablation table, the brax environment,
chunked evaluation, training and the transfer to unseen hazards.  The command line
(:mod:`lantern_jax.commands`) and the plots (:mod:`lantern_jax.viz`) sit above them."""
