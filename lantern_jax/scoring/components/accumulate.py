"""Running-accumulator primitives shared by the score components (one execution, scalars).

Every component folds a tick into its state with these few operations: a short ring of the last
values, a first-crossing time, a saturating counter and a run length of consecutive ticks; and
:func:`expected_time` decodes a soft first crossing at the end.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.scoring import thresholds

Array = jax.Array


def push(ring: Array, x: Array) -> Array:
    """Append ``x`` at the end of a ring (oldest first), dropping the oldest entry.

    Args:
        ring: (K,) any dtype, the last K values, oldest first.
        x: () value of the new tick (cast to ``ring.dtype``).

    Returns:
        (K,) the ring after the tick.
    """
    return jnp.concatenate([ring[1:], jnp.asarray(x, ring.dtype)[None]])


def first_time(already: Array, now: Array, t: Array, t_old: Array) -> Array:
    """() float32, s: ``t`` on the first tick ``now`` holds, else ``t_old``.

    Args:
        already: () bool, the condition held on an earlier tick.
        now: () bool, the condition holds on this tick.
        t: () float32, s, time stamp of this tick.
        t_old: () float32, s, the recorded time so far (``times.NEVER`` if none).
    """
    return jnp.where(now & ~already, t, t_old)


def count(n: Array, inc: Array) -> Array:
    """() int32, ticks: ``n + inc`` saturated at ``COUNT_CAP`` (``inc`` () bool)."""
    return jnp.minimum(n + inc.astype(jnp.int32), thresholds.COUNT_CAP)


def run(n: Array, cond: Array) -> Array:
    """() int32, ticks: length of the current run of ticks with ``cond`` (() bool), saturated."""
    return jnp.where(cond, jnp.minimum(n + 1, thresholds.COUNT_CAP), 0)


def expected_time(p: Array, pt: Array) -> tuple[Array, Array]:
    """Decode a soft first crossing: whether it happened and its expected time.

    Args:
        p: () float32, probability that the crossing happened (sum of the per-tick
            probabilities of a first crossing).
        pt: () float32, s, sum of those probabilities times their tick's time.

    Returns:
        ``(has, t)``: () bool, ``p`` above ``thresholds.PROB_EPS``; () float32, s,
        ``E[t | crossed] = pt / p`` (``pt`` itself where ``has`` is False: never divided by ~0).
    """
    has = p > thresholds.PROB_EPS
    return has, pt / jnp.where(has, p, 1.0)
