"""Smooth relaxations used by the soft (differentiable) Cooperative Unified Score.

Every relaxation takes a ``temperature`` in the natural unit of its argument and converges to the
hard operation as ``temperature -> 0``:

* :func:`smooth_clip01` -> ``clip(x, 0, 1)`` (error <= ``temperature * log 2``);
* :func:`soft_gate` -> ``margin > 0`` (a sigmoid of a signed margin);
* :func:`softmin_decode` -> ``min`` of the samples folded into a log-sum-exp accumulator, together
  with an optional cap (error <= ``temperature * log(n + 1)`` for ``n`` samples).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

Array = jax.Array

LSE_EMPTY = -1.0e30  # log-sum-exp accumulator of an empty sample set (finite: safe gradients)


def smooth_clip01(x: Array, temperature: Array) -> Array:
    """Softplus-based smooth ``clip(x, 0, 1)``.

    ``T softplus(x / T) - T softplus((x - 1) / T)``: equals ``x`` inside ``(0, 1)`` up to
    ``O(T)``, tends to 0 below and 1 above, and is strictly increasing.
    """
    t = jnp.asarray(temperature, jnp.float32)
    return t * jax.nn.softplus(x / t) - t * jax.nn.softplus((x - 1.0) / t)


def soft_gate(margin: Array, temperature: Array) -> Array:
    """Smooth pass indicator ``sigmoid(margin / T)``; the hard gate passes iff ``margin > 0``."""
    return jax.nn.sigmoid(margin / jnp.asarray(temperature, jnp.float32))


def lse_add(acc: Array, x: Array, temperature: Array, log_weight: Array = 0.0) -> Array:
    """Fold one sample ``x`` (weight ``exp(log_weight)``) into a soft-min accumulator.

    The accumulator holds ``log sum_i w_i exp(-x_i / T)``; start from :data:`LSE_EMPTY`.
    """
    return jnp.logaddexp(acc, log_weight - x / temperature)


def softmin_decode(acc: Array, temperature: Array, cap: Array | None = None) -> Array:
    """Soft minimum ``-T log(sum_i w_i exp(-x_i / T) [+ exp(-cap / T)])`` of an accumulator.

    With ``cap`` the result is a soft ``min(cap, x_1, ..., x_n)``, which is also defined for an
    empty accumulator (it is then ``cap``).
    """
    t = jnp.asarray(temperature, jnp.float32)
    if cap is not None:
        acc = jnp.logaddexp(acc, -jnp.asarray(cap, jnp.float32) / t)
    return -t * acc
