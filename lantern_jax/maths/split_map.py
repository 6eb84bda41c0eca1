"""Evaluate a per-item function in two loop steps, so that XLA computes its inputs once.

XLA's CPU compiler fuses producers into their consumers and will re-evaluate a producer for
every element of a larger consumer: an actor pose feeding a (rays x boxes) test is re-derived
for every ray, together with everything upstream of it in the tick (IDM, path interpolation,
event timing).  ``jax.lax.optimization_barrier`` does not stop this on CPU: XLA's CPU pipeline
expands the barrier after its simplification passes and before layout assignment and fusion
(its pass dumps show the order), so the barrier only shields values from the algebraic
simplifier.  A loop boundary does stop it: the operands of a ``while`` loop are computed into
buffers before the loop starts, and its results are buffers too.

:func:`split_map` applies ``fn`` to the two halves of the items' leading axis in a two-step
:func:`jax.lax.map` (one step cannot be used: the compiler inlines single-trip loops).  It is
a rewrite with the same operations: the values are those of ``fn`` applied to all items at
once, up to float rounding where the compiler contracts a multiply-add differently.  An odd item
count runs ``fn`` once, without the boundary.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax

STEPS = 2  # loop steps; the smallest count the compiler keeps as a loop


def split_map(fn: Callable[..., Any], items: Any, *shared: Any) -> Any:
    """``fn(items, *shared)`` computed as ``STEPS`` loop steps over slices of ``items``.

    Args:
        fn: maps a pytree of arrays with leading axis ``m`` (and the shared arguments) to a
            pytree of arrays with leading axis ``m``; it must treat items independently
            (as a ``vmap``-ed per-item function does).
        items: pytree of arrays sharing the leading axis ``n``.
        *shared: arguments passed unchanged to every step (loop-invariant).

    Returns:
        The pytree ``fn(items, *shared)``, leading axis ``n``.
    """
    leaves = jax.tree.leaves(items)
    if not leaves:
        raise ValueError("split_map: items has no arrays")
    n = leaves[0].shape[0]
    if any(x.shape[:1] != (n,) for x in leaves):
        raise ValueError("split_map: every array of items needs the same leading axis length")
    if n % STEPS:
        return fn(items, *shared)
    halves = jax.tree.map(lambda x: x.reshape(STEPS, n // STEPS, *x.shape[1:]), items)
    out = jax.lax.map(lambda part: fn(part, *shared), halves)
    return jax.tree.map(lambda x: x.reshape(n, *x.shape[2:]), out)
