"""lantern_jax: LANTERN cooperative-warning benchmark in JAX."""
