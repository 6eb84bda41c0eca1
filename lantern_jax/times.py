"""Protocol and event times: the one sentinel for "has not happened" and the test for it.

Every time the simulator records once (warning point, event, warning termination, clearance,
first collision, ...) starts at :data:`NEVER` (``constants.INF_TIME``, a finite stand-in for
+inf so that no infinity reaches arithmetic or gradients) and is written once.  Anything that
asks "has this time happened?" uses :func:`happened`; anything that reports a time to a user
uses :func:`time_or_nan`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.constants import INF_TIME

Array = jax.Array

NEVER = INF_TIME  # s, value of a time that has not happened
HAPPENED_BELOW = 0.5 * INF_TIME  # s, a recorded time is below this


def happened(t: Array) -> Array:
    """(...) bool: the time ``t`` (s) has been recorded (is not :data:`NEVER`)."""
    return t < HAPPENED_BELOW


def time_or_nan(t: Array) -> Array:
    """(...) float32, s: ``t`` where it happened, NaN where it did not."""
    return jnp.where(happened(t), t, jnp.nan)
