"""Times: the one sentinel for "has not happened" and the test for it, and seconds to ticks.

Every time the simulator records once (warning point, event, warning termination, clearance,
first collision, ...) starts at :data:`NEVER` (``constants.INF_TIME``, a finite stand-in for
+inf so that no infinity reaches arithmetic or gradients) and is written once.  Anything that
asks "has this time happened?" uses :func:`happened`; anything that reports a time to a user
uses :func:`time_or_nan`.

Every conversion of seconds to a count of ``DT`` ticks goes through :func:`ticks` (the nearest
count: a window or a delay) or :func:`ticks_covering` (the fewest ticks that reach a time: a
horizon).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import DT, INF_TIME

Array = jax.Array

NEVER = INF_TIME  # s, value of a time that has not happened
HAPPENED_BELOW = 0.5 * INF_TIME  # s, a recorded time is below this


def happened(t: Array) -> Array:
    """(...) bool: the time ``t`` (s) has been recorded (is not :data:`NEVER`)."""
    return t < HAPPENED_BELOW


def time_or_nan(t: Array) -> Array:
    """(...) float32, s: ``t`` where it happened, NaN where it did not."""
    return jnp.where(happened(t), t, jnp.nan)


def ticks(seconds: float) -> int:
    """The number of ``DT`` (0.05 s) ticks nearest to ``seconds``: ``round(seconds / DT)``
    (a window or a delay given in seconds)."""
    return int(round(seconds / DT))


def ticks_covering(seconds: float, slack: float = 0.0) -> int:
    """The fewest ``DT`` ticks whose span reaches ``seconds``: ``ceil(seconds / DT - slack)``
    (a horizon); ``slack`` (ticks) absorbs float error of a time that is a whole number of
    ticks."""
    return int(math.ceil(seconds / DT - slack))
