"""Fixed-cycle traffic lights, and what a light means for the ego at its stop line."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW
from lantern_jax.types.world import TrafficLights

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


def ego_light_state(lights: TrafficLights, ego_light: Array, t: Array) -> Array:
    """() int32 LIGHT_* state of the ego's traffic light at ``t`` (GREEN when it has none).

    Args:
        lights: the scenario's lights, (T,) slots.
        ego_light: () int32, slot of the light governing the ego (-1 = none).
        t: () float32, s.
    """
    states = light_states(lights, t)
    idx = jnp.clip(ego_light, 0, states.shape[0] - 1)
    return jnp.where(ego_light >= 0, states[idx], LIGHT_GREEN).astype(jnp.int32)


def light_holds_ego(
    light: Array, dist_to_stop_line: Array, hold_dist: Array, hold_behind: Array
) -> Array:
    """() bool: a non-green ego light with its stop line just ahead legitimately holds the ego.

    Used by the protocol (it pauses the anti-deadlock countdown) and by the scoring (it
    justifies a Route B stop); the distances are protocol settings
    (:class:`lantern_jax.sim.protocol.ProtocolSettings`).

    Args:
        light: () int32, LIGHT_* state of the ego's light.
        dist_to_stop_line: () float32, m, route arc of the stop line minus the ego's arc.
        hold_dist: () float32, m, the stop line is closer ahead than this ...
        hold_behind: () float32, m, ... and no farther behind than this (negative).
    """
    return (
        (light != LIGHT_GREEN) & (dist_to_stop_line > hold_behind) & (dist_to_stop_line < hold_dist)
    )
