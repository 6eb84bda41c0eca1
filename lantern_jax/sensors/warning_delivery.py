"""What the warning channel delivers at a time: a reading of the protocol's times (paper §3.2).

The protocol's per-tick transitions (:mod:`lantern_jax.sim.protocol`) write the execution's
times once each; this module reads them, with the execution's switches, into what is delivered
at time ``t``: the protocol's warning, active on ``[t_on, t_warn_off + warn_hold_extra)`` with
``t_on = t_warn_point`` (or ``t_event`` with the late-onset ablation) in the warning condition
of Route A only, or an override text in its own window (``ExecutionConfig.override_*``) on any
execution. The warning sensor (:mod:`lantern_jax.sensors.views`) and the protocol's onset
bookkeeping read it; nothing here changes a state.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import OVERRIDE_ANCHOR_WARN_POINT
from lantern_jax.core.times import NEVER, happened
from lantern_jax.types.world import ExecutionConfig, ProtocolState

Array = jax.Array


def warning_onset(proto: ProtocolState, config: ExecutionConfig) -> Array:
    """() s, start of warning delivery (NEVER when no warning is delivered at all)."""
    t_on = jnp.where(config.late_onset, proto.t_event, proto.t_warn_point)
    delivered = config.warning_enabled & config.is_route_a
    return jnp.where(delivered, t_on, NEVER)


def warning_active(proto: ProtocolState, config: ExecutionConfig, t: Array) -> Array:
    """() bool: the warning text is delivered to the policy at time ``t``.

    Active on ``[t_on, t_warn_off + warn_hold_extra)``; ``t_warn_off`` is NEVER until the
    hazard is seen, so the interval stays open until then.
    """
    t_on = warning_onset(proto, config)
    t_off = jnp.where(happened(proto.t_warn_off), proto.t_warn_off + config.warn_hold_extra, NEVER)
    return happened(t_on) & (t >= t_on) & (t < t_off)


def override_window(proto: ProtocolState, config: ExecutionConfig, t: Array) -> Array:
    """() bool: the warning override is open at time ``t``.

    Open on ``[anchor + override_on_s, anchor + override_off_s)`` where the anchor is ``0`` or
    the time the ego reached the warning point (``override_anchor``); never open for a negative
    ``override_text_id``, an empty window, or an anchor that has not happened.
    """
    at_warn = config.override_anchor == OVERRIDE_ANCHOR_WARN_POINT
    anchor = jnp.where(at_warn, proto.t_warn_point, 0.0)
    return (
        (config.override_text_id >= 0)
        & happened(anchor)
        & (t >= anchor + config.override_on_s)
        & (t < anchor + config.override_off_s)
    )


def delivered_warning(
    proto: ProtocolState, config: ExecutionConfig, t: Array
) -> tuple[Array, Array, Array]:
    """The warning the policy reads at time ``t``: the override while its window is open, else
    the protocol's warning.

    Returns:
        active: () bool, a warning is delivered.
        text_id: () int32, its text-bank id (-1 when inactive).
        overridden: () bool, it is the override (its position is ``override_x/y``).
    """
    overridden = override_window(proto, config, t)
    normal = warning_active(proto, config, t)
    text_id = jnp.where(overridden, config.override_text_id, jnp.where(normal, config.text_id, -1))
    return overridden | normal, text_id.astype(jnp.int32), overridden
