"""Training learned driving policies on the open-loop dataset (optax, orbax): configs
(:mod:`~lantern_jax.apps.training.config`), examples and recipes
(:mod:`~lantern_jax.apps.training.data`), the behaviour-cloning loop
(:mod:`~lantern_jax.apps.training.behaviour_cloning`)."""
