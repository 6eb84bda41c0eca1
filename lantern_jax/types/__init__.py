"""Layer 2, the data every layer above passes around: the scenario and the world state
(:mod:`~lantern_jax.types.world`), what a policy observes (:mod:`~lantern_jax.types.observation`)
and the warning's tokens (:mod:`~lantern_jax.types.language`)."""
