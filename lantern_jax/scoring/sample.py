"""The per-tick measurement the rollout hands to the telemetry accumulators.

The rollout computes one :class:`TickSample` per 20 Hz tick for one execution (after the world
has been stepped); :mod:`lantern_jax.scoring.telemetry` folds it into running accumulators, so
scoring never needs a stored trajectory.
"""

from __future__ import annotations

import jax
from flax import struct

Array = jax.Array


@struct.dataclass
class TickSample:
    """What the scorer needs to know about one tick of one execution (all float32 unless noted)."""

    t: Array  # () s, time at the end of the tick
    ego_speed: Array  # () m/s
    ego_accel: Array  # () m/s^2, longitudinal acceleration applied during the tick
    progress: Array  # () m, furthest route arc reached so far (monotone)
    route_length: Array  # () m
    dist_to_route: Array  # () m, distance of the ego centre from the route polyline
    outside_lanes: Array  # () bool, ego centre outside every driving lane (or wrong way)
    red_light_violation: Array  # () bool, ego crossed its stop line on red during this tick
    collision: Array  # () bool, ego box overlaps a present actor (ego speed >= 0.1 m/s)
    hazard_present: Array  # () bool, the controlled hazard actor exists right now
    hazard_rel: Array  # (2,) m, hazard centre minus ego centre, world frame
    hazard_rel_vel: Array  # (2,) m/s, hazard velocity minus ego velocity, world frame
    hazard_box_dist: Array  # () m, box-surface distance ego-hazard (0 when overlapping)
    justified_stop: Array  # () bool, a light, lead vehicle, obstacle, conflict or route end
    #                         justifies standing still (Route B false-brake excuse)
    slow_unjustified: Array  # () bool, ego speed below SLOW_SPEED_FRACTION of the route reference
    #                          speed while nothing justifies it (the efficiency diagnostic)
    fb_window: Array  # () bool, the ego's route progress lies in the stretch matched to Route A's
    #                    warning-to-event approach (Route B false brake)
    controller_fault: Array  # () bool, the policy's plan was unusable (NaN/inf, or over
    #                          MAX_PLAN_SPEED) this tick
    t_warn_point: Array  # () s, protocol: ego reached the warning point (t_ref); NEVER if not
    t_event: Array  # () s, protocol: physical-event onset; NEVER if not yet
    t_warn_off: Array  # () s, protocol: warning termination; NEVER if not yet
    t_clear: Array  # () s, protocol: hazard clearance; NEVER if not yet
    is_route_a: Array  # () bool
    coincident_onset: Array  # () bool, warning and event points coincide (Right-Turn Yield)
