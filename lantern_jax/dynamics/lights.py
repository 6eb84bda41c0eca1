"""Fixed-cycle traffic lights."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.constants import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW
from lantern_jax.world import TrafficLights

Array = jax.Array


def light_states(lights: TrafficLights, t: Array) -> Array:
    """State of every light at time ``t``.

    Each cycle is green, then yellow, then red: with ``phase = (t + offset) mod (green + yellow
    + red)`` the light is green for ``phase < green``, yellow for ``phase < green + yellow`` and
    red otherwise.  Padding slots (``valid = False``) and lights with a non-positive cycle are
    green.

    Args:
        lights: the scenario's lights, (T,) slots.
        t: () float32, s, simulation time.

    Returns:
        (T,) int32 in {LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED}.
    """
    cycle = lights.green + lights.yellow + lights.red
    ok = lights.valid & (cycle > 0.0)
    phase = jnp.mod(t + lights.offset, jnp.where(ok, cycle, 1.0))
    state = jnp.where(
        phase < lights.green,
        LIGHT_GREEN,
        jnp.where(phase < lights.green + lights.yellow, LIGHT_YELLOW, LIGHT_RED),
    )
    return jnp.where(ok, state, LIGHT_GREEN).astype(jnp.int32)
