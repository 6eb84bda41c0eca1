"""The LANTERN temporal protocol as masked state transitions (paper §3.2 and appendix D).

Every transition is a ``jnp.where`` on flags and times — no Python control flow — so the
protocol batches under ``vmap`` and traces once.  Times start at ``NEVER`` and are written
once.  Per execution:

* ``t_warn_point`` — the ego reaches the route-relative warning point (both conditions and both
  routes record it: it is the anticipation reference ``t_ref`` and opens Route B's matched
  false-brake interval).  Interpolated inside the tick from the progress crossing, so that it
  varies smoothly with scenario parameters.
* ``t_event = min(t_geom, t_warn_point + tau_force)`` — the anti-deadlock rule.  The countdown
  only advances while the ego is not legitimately held (red/yellow light ahead, or a queue of
  ordinary traffic); ``force_event`` is False for Right-Turn Yield, whose event point equals its
  warning point.  The rule only moves the scenario actor: the event time feeds the scripted
  actors' trigger, never the ego's control.
* ``t_warn_off`` — the first tick at/after the event at which the hazard is visible to the front
  camera.  A hazard that clears (is removed) before it was ever seen ends the warning at
  clearance, so that a warning never outlives its hazard.
* ``t_clear`` — the family's clearance condition: the hazard reached ``clear_s`` on its path, or
  ``clear_time_limit`` seconds passed since the event (``clear_by_limit`` records that a limit,
  rather than a geometric clearance, ended the interaction, when a geometric one was defined),
  or (``clear_on_ego_stop``) the ego has stood still for 1 s after seeing the hazard.

Warning delivery (what a policy reads) is a reading of these times and the ablation switches,
:mod:`lantern_jax.sensors.warning_delivery` (the warning sensor reads it, one layer below the
tick): active on ``[t_on, t_warn_off + warn_hold_extra)`` with ``t_on = t_warn_point`` (or
``t_event`` with the late-onset ablation), and only in the warning condition of Route A.  A
warning override (``ExecutionConfig.override_*``, :func:`delivered_warning`) delivers a chosen
text in a chosen window on any execution, Route B included; it changes what the policy reads,
never these times.  Those reads are importable from here too, so the protocol's whole interface
reads from one module.

The protocol's own thresholds (what counts as stopped, as a queue, as a light holding the ego)
are :class:`ProtocolSettings`, a frozen pytree passed as an argument (defaults: the values
below).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import BIG, DT, EGO_HALF_WIDTH, ROLE_BACKGROUND
from lantern_jax.core.times import NEVER, happened
from lantern_jax.dynamics.lights import light_holds_ego
from lantern_jax.sensors.warning_delivery import (
    delivered_warning,
    override_window,
    warning_active,
    warning_onset,
)
from lantern_jax.types.world import ActorState, ExecutionConfig, ProtocolState

Array = jax.Array

__all__ = [
    "DEFAULT_PROTOCOL", "ProtocolSettings", "advance_hazard", "advance_markers", "crossing_time",
    "delivered_warning", "despawn_cleared", "ego_held", "override_window", "record_onset",
    "warning_active", "warning_onset",
]  # fmt: skip


@struct.dataclass
class ProtocolSettings:
    """Thresholds of the temporal protocol (every field a traced float)."""

    still_speed_mps: float = 0.1  # m/s, "stopped"
    still_time_for_clear_s: float = 1.0  # s, ego response that lets the Obstacle Reveal object
    #                                      be removed (``clear_on_ego_stop``)
    queue_dist_m: float = 12.0  # m, a slow background vehicle this close ahead in the corridor
    #                             is a queue ...
    queue_behind_m: float = -1.0  # m, ... or overlapping the ego front by up to 1 m
    queue_lateral_margin_m: float = 0.5  # m, corridor half width = ego half width + this
    queue_speed_mps: float = 1.0  # m/s, a queueing vehicle is slower than this
    light_hold_dist_m: float = 30.0  # m, a red or yellow light whose stop line is this close
    #                                  ahead holds the ego ...
    light_hold_behind_m: float = -1.0  # m, ... or up to 1 m past the line (stopped on it)

    def light_holds(self, light: Array, dist_to_stop_line: Array) -> Array:
        """() bool: :func:`~lantern_jax.dynamics.lights.light_holds_ego` with these distances."""
        return light_holds_ego(
            light, dist_to_stop_line, self.light_hold_dist_m, self.light_hold_behind_m
        )


#: The protocol's defaults.
DEFAULT_PROTOCOL = ProtocolSettings()


def ego_held(
    light: Array,
    dist_to_stop_line: Array,
    gap: Array,
    lateral: Array,
    present: Array,
    role: Array,
    speed: Array,
    settings: ProtocolSettings = DEFAULT_PROTOCOL,
) -> Array:
    """() bool: a red/yellow light or a queue legitimately holds the ego (pauses the countdown).

    Args:
        light: () int32, LIGHT_* state of the ego's light.
        dist_to_stop_line: () float32, m, route arc of the ego's stop line minus the ego's arc.
        gap: (A,) float32, m, route gap from the ego front to each actor
            (:func:`lantern_jax.types.observation.corridor_gaps`).
        lateral: (A,) float32, m, each actor's distance from the route minus its half size.
        present: (A,) bool, actors in the world.
        role: (A,) int32, ROLE_*; only ordinary (background) traffic forms a queue.
        speed: (A,) float32, m/s.
        settings: the queue and light distances.
    """
    s = settings
    queue = (
        present
        & (lateral < EGO_HALF_WIDTH + s.queue_lateral_margin_m)
        & (role == ROLE_BACKGROUND)
        & (gap > s.queue_behind_m)
        & (gap < s.queue_dist_m)
        & (speed < s.queue_speed_mps)
    )
    return s.light_holds(light, dist_to_stop_line) | jnp.any(queue)


def crossing_time(t_next: Array, prev: Array, cur: Array, threshold: Array, dt: float) -> Array:
    """Sub-tick time at which a monotone quantity crossed ``threshold`` during the last tick.

    Args:
        t_next: () s, time at the end of the tick.
        prev: () value at the start of the tick.
        cur: () value at the end of the tick (``cur >= threshold > prev`` assumed by caller).
        threshold: () crossing level.
        dt: tick length, s.

    Returns:
        () s, linear interpolation of the crossing inside ``[t_next - dt, t_next]``.
    """
    span = cur - prev
    safe = jnp.where(span > 1e-6, span, 1.0)
    frac = jnp.where(span > 1e-6, (threshold - prev) / safe, 1.0)
    return t_next - dt + jnp.clip(frac, 0.0, 1.0) * dt


def advance_markers(
    proto: ProtocolState,
    config: ExecutionConfig,
    t_next: Array,
    progress_prev: Array,
    progress: Array,
    ego_held: Array,
    dt: float = DT,
) -> ProtocolState:
    """Warning point, anti-deadlock countdown and event onset after the ego moved.

    Args:
        proto: protocol state at the start of the tick.
        config: the execution's markers, rules and switches.
        t_next: () s, time at the end of the tick.
        progress_prev: () m, route progress at the start of the tick.
        progress: () m, route progress at the end of the tick.
        ego_held: () bool, a red light or a queue legitimately holds the ego (pauses the
            countdown).

    Returns:
        The protocol state with ``t_warn_point``, ``countdown`` and ``t_event`` updated.
    """
    reach_warn = (~happened(proto.t_warn_point)) & (progress >= config.s_warn)
    t_warn_point = jnp.where(
        reach_warn,
        crossing_time(t_next, progress_prev, progress, config.s_warn, dt),
        proto.t_warn_point,
    )
    event_pending = ~happened(proto.t_event)
    counting = happened(t_warn_point) & event_pending & config.force_event & ~ego_held
    # Seconds of this tick that lie after the warning point (sub-tick on the first tick).
    tick_share = jnp.clip(t_next - jnp.maximum(t_warn_point, t_next - dt), 0.0, dt)
    countdown = proto.countdown + jnp.where(counting, tick_share, 0.0)

    geom = event_pending & (progress >= config.s_event)
    t_geom = crossing_time(t_next, progress_prev, progress, config.s_event, dt)
    # RTY: the event point is the warning point, so the event coincides with it exactly.
    t_geom = jnp.where(config.s_event <= config.s_warn, t_warn_point, t_geom)
    forced = event_pending & counting & (countdown >= config.force_delay)
    t_forced = t_next - (countdown - config.force_delay)
    t_new = jnp.minimum(jnp.where(geom, t_geom, NEVER), jnp.where(forced, t_forced, NEVER))
    forced = forced & ~(geom & (t_geom <= t_forced))
    t_event = jnp.where(geom | forced, t_new, proto.t_event)
    return proto.replace(
        t_warn_point=t_warn_point,
        countdown=countdown,
        t_event=t_event,
        event_forced=proto.event_forced | forced,
    )


def advance_hazard(
    proto: ProtocolState,
    config: ExecutionConfig,
    t_next: Array,
    hazard_visible: Array,
    hazard_s: Array,
    ego_speed: Array,
    settings: ProtocolSettings = DEFAULT_PROTOCOL,
    dt: float = DT,
) -> ProtocolState:
    """Clearance and warning termination after the actors moved and visibility was computed.

    Args:
        proto: protocol state after :func:`advance_markers`.
        config: the execution's markers, rules and switches.
        t_next: () s, time at the end of the tick.
        hazard_visible: () bool, the hazard is visible to the front camera now.
        hazard_s: () m, the hazard's arc along its own path.
        ego_speed: () m/s.
        settings: what counts as stopped, and for how long.

    Returns:
        The protocol state with ``t_clear``, ``t_warn_off`` and the ego-still timer updated.
    """
    still = jnp.where(ego_speed < settings.still_speed_mps, proto.ego_still_time + dt, 0.0)
    after_event = happened(proto.t_event) & (t_next >= proto.t_event)
    pending = ~happened(proto.t_clear)
    geometric = hazard_s >= config.clear_s
    by_limit = (t_next - proto.t_event) >= config.clear_time_limit
    by_stop = (
        config.clear_on_ego_stop
        & happened(proto.t_warn_off)
        & (still >= settings.still_time_for_clear_s)
    )
    clear_now = pending & after_event & (geometric | by_limit | by_stop)
    t_clear = jnp.where(clear_now, t_next, proto.t_clear)
    limit_flag = clear_now & by_limit & ~geometric & ~by_stop & (config.clear_s < BIG * 0.5)

    seen = after_event & hazard_visible & ~happened(proto.t_warn_off)
    t_warn_off = jnp.where(seen, t_next, proto.t_warn_off)
    # A hazard removed before it was ever seen ends the warning at clearance.
    t_warn_off = jnp.where(happened(t_clear) & ~happened(t_warn_off), t_clear, t_warn_off)
    return proto.replace(
        t_clear=t_clear,
        t_warn_off=t_warn_off,
        clear_by_limit=proto.clear_by_limit | limit_flag,
        ego_still_time=still,
    )


def record_onset(
    proto: ProtocolState,
    before: ProtocolState,
    config: ExecutionConfig,
    hazard_visible: Array,
    shown: Array,
) -> ProtocolState:
    """Warning bookkeeping of a tick: onset time, whether the hazard was camera-visible at the
    warning point, whether the camera saw it at any tick of the approach up to it, and how many
    ticks the policy has been shown the warning.

    Args:
        proto: protocol state after this tick's transitions.
        before: protocol state at the start of the tick (to see whether the warning point was
            crossed during it).
        config: the execution's switches.
        hazard_visible: () bool, the front camera sees the hazard now.
        shown: () bool, the policy's observation of this tick carried an active warning.
    """
    first = happened(proto.t_warn_point) & ~happened(before.t_warn_point)
    approaching = ~happened(before.t_warn_point)  # this tick ends at or before the warning point
    return proto.replace(
        t_warn_on=warning_onset(proto, config),
        hazard_visible_at_warn=jnp.where(first, hazard_visible, proto.hazard_visible_at_warn),
        warning_ticks=proto.warning_ticks + shown.astype(jnp.int32),
        hazard_seen_before_warn=proto.hazard_seen_before_warn | (approaching & hazard_visible),
    )


def despawn_cleared(
    actors: ActorState, proto: ProtocolState, config: ExecutionConfig
) -> ActorState:
    """Remove the hazard actor once it has cleared, where the family says so."""
    h = config.hazard_index
    gone = happened(proto.t_clear) & config.despawn_on_clear
    return actors.replace(active=actors.active.at[h].set(actors.active[h] & ~gone))
