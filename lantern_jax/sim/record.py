"""Per-tick records of a rollout, kept only when a full trajectory is asked for (plots)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.sim.state import State
from lantern_jax.types.world import Scenario, present

Array = jax.Array


@struct.dataclass
class TickRecord:
    """What is kept per tick when full trajectories are recorded (for plots).

    State fields (``t``, ego, actors, visibility) are those at the END of the tick; the warning
    fields (``warning_active``, ``warning_text_id``, ``warning_pos``: what was delivered, as the
    simulator knows it) and ``waypoints`` (what the policy returned) are those of the START of
    it.  After an execution has ended, records repeat its
    final state (``done`` True) with the policy fields zeroed (text id -1).
    """

    t: Array  # () s
    ego_xy: Array  # (2,) m
    ego_yaw: Array  # () rad
    ego_speed: Array  # () m/s
    ego_accel: Array  # () m/s^2
    actor_xy: Array  # (A, 2) m
    actor_yaw: Array  # (A,) rad
    actor_present: Array  # (A,) bool
    visible: Array  # (A,) bool
    warning_active: Array  # () bool
    warning_text_id: Array  # () int32, delivered text id (-1 when none)
    warning_pos: Array  # (2,) m, ego frame, the position its text grounds (0 when none)
    waypoints: Array  # (10, 2) m, ego frame
    light: Array  # () int32
    done: Array  # () bool


def tick_record(
    scenario: Scenario,
    new: State,
    warning: tuple[Array, Array, Array],
    plan: Array,
    light: Array,
    live: Array,
) -> TickRecord:
    """The record of one tick.

    Args:
        scenario: the execution's static scenario.
        new: the state at the end of the tick (frozen if the execution had ended before it).
        warning: ``(active, text_id, position)`` delivered at the start of the tick
            (:func:`lantern_jax.sim.observe.delivered_warning`).
        plan: (10, 2) float32, m, the (fault-sanitised) waypoints the policy returned.
        light: () int32, the ego's light state at the end of the tick.
        live: () bool, the execution had not ended before this tick.
    """
    on = present(scenario.actors, new.actors)
    return TickRecord(
        t=new.t,
        ego_xy=new.ego.xy,
        ego_yaw=new.ego.yaw,
        ego_speed=new.ego.speed,
        ego_accel=new.ego.accel,
        actor_xy=new.actors.xy,
        actor_yaw=new.actors.yaw,
        actor_present=on,
        visible=new.percept.visible & on,
        warning_active=warning[0] & live,
        warning_text_id=jnp.where(live, warning[1], -1),
        warning_pos=jnp.where(live, warning[2], 0.0),
        waypoints=jnp.where(live, plan, 0.0),
        light=light,
        done=new.done,
    )
