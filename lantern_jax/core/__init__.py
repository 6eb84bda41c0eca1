"""Layer 0, the bottom of the package: its constants (one home for every value and threshold),
the time sentinel and seconds-to-ticks, wall-clock breakdowns, the known family codes, array
checks, actor tracks, named registries, loading user code, JAX's set-up and the old names of
moved modules.  Nothing here imports another layer; ``import lantern_jax`` loads
:mod:`~lantern_jax.core.jax_setup` and :mod:`~lantern_jax.core.renamed` without JAX."""
