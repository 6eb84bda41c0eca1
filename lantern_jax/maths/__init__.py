"""Layer 1: pure JAX maths on the layer below -- planar geometry and boxes, polylines (arc
length, projection, resampling) and a loop rewrite that keeps XLA from recomputing a producer
per element (:mod:`~lantern_jax.maths.split_map`)."""
