"""split_map: an exact rewrite of a per-item function as loop steps (values unchanged), whose
loop boundary the compiler keeps."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.maths.split_map import STEPS, split_map


def _per_item(items, scale):
    a, b = items
    return {"sum": a.sum(-1) * scale + b, "pair": jnp.stack([a[:, 0], b], -1)}


@pytest.mark.parametrize("n", [6, 7])
def test_equals_the_direct_call(n):
    rng = np.random.default_rng(n)
    items = (
        jnp.asarray(rng.normal(size=(n, 3)), jnp.float32),
        jnp.asarray(rng.normal(size=(n,)), jnp.float32),
    )
    scale = jnp.float32(1.5)
    got = jax.jit(lambda it, s: split_map(_per_item, it, s))(items, scale)
    want = jax.jit(_per_item)(items, scale)
    for key in want:
        assert got[key].shape == want[key].shape
        # the same operations; fused differently, a multiply-add may round differently
        np.testing.assert_allclose(np.asarray(got[key]), np.asarray(want[key]), rtol=0, atol=1e-6)


def test_even_count_keeps_a_loop_and_odd_count_runs_once():
    def compiled_whiles(n):
        items = (jnp.ones((n, 3)), jnp.ones((n,)))
        f = jax.jit(lambda it: split_map(_per_item, it, 2.0))
        return f.lower(items).compile().as_text().count(" while(")

    assert STEPS == 2
    assert compiled_whiles(8) == 1
    assert compiled_whiles(7) == 0


def test_under_vmap_and_grad():
    x = jnp.arange(12.0, dtype=jnp.float32).reshape(3, 4)

    def loss(v):
        return jnp.sum(split_map(lambda it: jnp.sin(it) * it, v) ** 2)

    g = jax.vmap(jax.grad(loss))(x)
    want = jax.vmap(jax.grad(lambda v: jnp.sum((jnp.sin(v) * v) ** 2)))(x)
    np.testing.assert_allclose(np.asarray(g), np.asarray(want), rtol=1e-6)
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0.0)


def test_bad_items_are_refused():
    with pytest.raises(ValueError, match="no arrays"):
        split_map(lambda it: it, ())
    with pytest.raises(ValueError, match="same leading axis"):
        split_map(lambda it: it, (jnp.ones((4,)), jnp.ones((3,))))
