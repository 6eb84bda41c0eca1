"""Training learned driving policies on the open-loop dataset (optax, orbax): configs
(:mod:`~lantern_jax.training.config`), examples and recipes (:mod:`~lantern_jax.training.data`),
the behaviour-cloning loop (:mod:`~lantern_jax.training.behaviour_cloning`)."""
