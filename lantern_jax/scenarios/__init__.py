"""Road builder, the six LANTERN scenario families, warnings, the protocol's variants and the frozen
suite (the protocol's per-tick transitions are :mod:`lantern_jax.sim.protocol`)."""
