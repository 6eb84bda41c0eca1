"""Response measures of the paper's unseen-hazard case study (appendix "Protocol Extension to
Unseen Hazards"), from the per-tick records of one execution.

* **Brake signal** of a waypoint policy (:func:`brake_signal`): the paper's models output a
  brake command in [0, 1] through their controller; a policy here outputs waypoints, and the
  simulator's controller (:func:`lantern_jax.dynamics.controller.track_waypoints`) turns them
  into a commanded longitudinal acceleration.  The brake signal is that command's deceleration
  as a share of the brake limit, ``clip(-accel_cmd / brake_limit(friction), 0, 1)`` — the
  pedal position that would command it in a vehicle whose full brake gives the brake limit
  (8 m/s^2 here).  ``brake >= 0.5`` is a commanded deceleration of at least 4 m/s^2.  It is
  recomputed from the recorded plan and the ego's speed at the start of each tick, by the very
  function the simulator runs, so it is the command, not the deceleration achieved (a standing
  ego holding its brake has brake 1).
* **Response time** (:func:`response_time`): the start of the first of ``RESPONSE_STEPS`` (3)
  consecutive 20-Hz control steps with brake at least ``RESPONSE_BRAKE`` (0.5), searched from a
  given time on (the warning point: a stop for a red light on the approach is not a response);
  **response lead** = event-on time minus response time (positive: braking before the hazard
  starts to move).
* **Pre-event speed reduction** (:func:`pre_event_speed_drop`): the speed at the onset time
  (warning onset; the warning point where no warning is delivered) minus the lowest speed from
  then until the event.

These are separate from the CUS Anticipation component (a 0.5-s sustained-response window on
acceleration or speed drop, :mod:`lantern_jax.scoring.components`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import DT
from lantern_jax.dynamics.bicycle import brake_limit
from lantern_jax.dynamics.controller import track_waypoints
from lantern_jax.scoring.thresholds import RESPONSE_BRAKE, RESPONSE_STEPS
from lantern_jax.types.world import EgoState

Array = jax.Array


def brake_signal(speed: Array, waypoints: Array, friction: Array) -> Array:
    """() float32 in [0, 1]: the brake signal of one control step.

    Args:
        speed: () float32, m/s, the ego's speed at the start of the step.
        waypoints: (10, 2) float32, m, the plan of the step (ego frame, x forward, y right).
        friction: () float32, tyre-road friction coefficient.
    """
    z = jnp.zeros((), jnp.float32)
    ego = EgoState(jnp.zeros((2,), jnp.float32), z, jnp.asarray(speed, jnp.float32), z, z)
    _, accel = track_waypoints(ego, jnp.asarray(waypoints, jnp.float32), friction)
    limit = jnp.maximum(brake_limit(friction), 1e-6)
    return jnp.clip(-jnp.nan_to_num(accel, nan=-limit) / limit, 0.0, 1.0)


#: (T,) brake signals of one execution's recorded steps: ``(speed (T,), waypoints (T, 10, 2),
#: friction ())``.
brake_signals = jax.jit(jax.vmap(brake_signal, in_axes=(0, 0, None)))


def step_start_speeds(v0: float, speed_end: np.ndarray) -> np.ndarray:
    """(T,) m/s, the ego's speed at the start of every recorded tick: ``v0`` at the first, then
    the previous tick's end speed.

    Args:
        v0: m/s, the speed at ``t = 0``.
        speed_end: (T,) m/s, the speed at the end of every tick.
    """
    speed_end = np.asarray(speed_end, np.float64)
    return np.concatenate([[float(v0)], speed_end[:-1]])


def response_time(t_end: np.ndarray, brake: np.ndarray, live: np.ndarray, t_from: float) -> float:
    """s, the start of the first of ``RESPONSE_STEPS`` consecutive live control steps with
    ``brake >= RESPONSE_BRAKE`` that start at or after ``t_from``; NaN when there is none.

    Args:
        t_end: (T,) s, time at the end of every tick (a step starts ``DT`` earlier).
        brake: (T,) brake signal of every step (:func:`brake_signal`).
        live: (T,) bool, the execution had not ended before the step.
        t_from: s, where the search starts (NaN: nothing is searched).
    """
    if not np.isfinite(t_from):
        return float("nan")
    start = np.asarray(t_end, np.float64) - DT
    on = (np.asarray(brake) >= RESPONSE_BRAKE) & np.asarray(live, bool)
    on &= start >= t_from - 1e-6
    run = 0
    for i, b in enumerate(on):
        run = run + 1 if b else 0
        if run == RESPONSE_STEPS:
            return float(start[i - RESPONSE_STEPS + 1])
    return float("nan")


def pre_event_speed_drop(
    t_end: np.ndarray, speed_end: np.ndarray, live: np.ndarray, v0: float, t_on: float,
    t_event: float,
) -> float:  # fmt: skip
    """m/s, the speed at ``t_on`` minus the lowest speed from ``t_on`` until ``t_event`` (the
    rest of the execution when the event never came); NaN when ``t_on`` is NaN.

    Args:
        t_end: (T,) s, time at the end of every tick.
        speed_end: (T,) m/s, the ego's speed then.
        live: (T,) bool, the tick was simulated.
        v0: m/s, the speed at ``t = 0``.
        t_on: s, the onset (warning onset, or the warning point).
        t_event: s, event onset (NaN: never).
    """
    if not np.isfinite(t_on):
        return float("nan")
    t = np.concatenate([[0.0], np.asarray(t_end, np.float64)])
    v = np.concatenate([[float(v0)], np.asarray(speed_end, np.float64)])
    ok = np.concatenate([[True], np.asarray(live, bool)])
    v_on = float(np.interp(t_on, t[ok], v[ok]))
    end = t_event if np.isfinite(t_event) else np.inf
    window = ok & (t >= t_on) & (t <= end)
    lowest = min(v_on, float(np.min(v[window]))) if np.any(window) else v_on
    return v_on - lowest
