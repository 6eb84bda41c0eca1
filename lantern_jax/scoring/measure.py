"""Per-tick measurement of one execution: what the scorer needs to know about a tick.

The simulator calls :func:`measure` once per tick, after the world has been stepped, and folds
the resulting :class:`~lantern_jax.scoring.sample.TickSample` into the telemetry; it calls
:func:`execution_ended` to know when the execution is over.  Everything a gate or a component
looks at is decided here, with thresholds from :mod:`lantern_jax.scoring.thresholds`:

* collision: the ego box overlaps a present actor or a static occluder of the map (building,
  wall, parked vehicle) while the ego moves at >= 0.1 m/s (the leaderboard ignores contacts at
  standstill);
* outside the lanes: the ego centre is in no lane (half width + 0.5 m) or drives its lane the
  wrong way (more than 120 deg from the lane direction);
* red-light violation: the ego crossed its stop line during the tick while its light was red;
* justified stop (the Route B false-brake excuse): a red/yellow light holds the ego, an actor's
  box reaches into the ego's path (within the ego half width + 0.5 m of the route centre line,
  measured across the route) within 15 m ahead, or the route end is within 10 m; a vehicle
  parked beside the lane is no excuse, and neither is a warning;
* slow driving with nothing to justify it (the efficiency diagnostic beside the CUS,
  :mod:`lantern_jax.scoring.components.efficiency`): the ego below ``SLOW_SPEED_FRACTION`` of
  the route's reference speed while :func:`justified_stop` finds no excuse;
* whether the ego's progress lies in the Route B false-brake stretch
  (:func:`lantern_jax.scoring.components.false_brake.matched_window`);
* the controlled hazard's relative position and velocity and box distance (TTC, clearance).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import EGO_HALF_LENGTH, EGO_HALF_WIDTH, LIGHT_RED
from lantern_jax.maths import geometry, polyline
from lantern_jax.scoring.components.false_brake import matched_window
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import ScoringSettings
from lantern_jax.types.world import ActorState, EgoState, Lanes, ProtocolState, Scenario

Array = jax.Array

EGO_EXTENT = (EGO_HALF_LENGTH, EGO_HALF_WIDTH)  # m, half length and half width of the ego box


def outside_lanes(lanes: Lanes, ego: EgoState, settings: ScoringSettings) -> Array:
    """() bool: the ego centre is in no lane (half width + 0.5 m), or drives its lane the wrong way.

    Wrong way = heading more than 120 deg from the lane's direction (the leaderboard's junction
    threshold, used everywhere here; ``settings.wrong_way_rad``).
    """
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])

    def one(center, pv, width):
        dist, direction = polyline.nearest_segment(center, pv, ego.xy)
        norm = jnp.sqrt(jnp.maximum(jnp.sum(direction * direction), 1e-12))
        wrong = jnp.sum(direction * heading) < jnp.cos(settings.wrong_way_rad) * norm
        return (dist <= 0.5 * width + settings.lane_margin_m) & ~wrong

    inside = jax.vmap(one)(lanes.center, lanes.point_valid, lanes.width)
    return ~jnp.any(inside & lanes.valid)


def justified_stop(
    light_holds: Array,
    gap: Array,
    lateral: Array,
    present: Array,
    dist_to_end: Array,
    settings: ScoringSettings,
) -> Array:
    """() bool: standing still now would be justified (light, lead actor, route end).

    Args:
        light_holds: () bool, a red/yellow light holds the ego at its stop line.
        gap: (A,) float32, m, route gap from the ego front to each actor.
        lateral: (A,) float32, m, each actor's distance from the route minus its half size.
        present: (A,) bool, actors in the world.
        dist_to_end: () float32, m, route length minus the ego's route arc.
        settings: the distances that justify a stop (``justify_*``).
    """
    in_corr = present & (lateral < EGO_HALF_WIDTH + settings.justify_lateral_margin_m)
    lead = jnp.any(
        in_corr & (gap > settings.justify_lead_behind_m) & (gap < settings.justify_lead_dist_m)
    )
    return light_holds | lead | (dist_to_end < settings.justify_route_end_m)


@struct.dataclass
class TickEnd:
    """The world at the end of one tick of one execution, as :func:`measure` reads it (built
    by keyword in :func:`lantern_jax.sim.step.transition`, so no two fields can be swapped)."""

    ego: EgoState  # the ego at the end of the tick
    actors: ActorState  # the actors at the end of the tick
    present: Array  # (A,) bool, actors in the world at the end of the tick
    protocol: ProtocolState  # protocol times after the tick
    t: Array  # () float32, s, time at the end of the tick
    progress: Array  # () float32, m, furthest route arc reached
    dist_to_route: Array  # () float32, m, ego centre distance from the route
    arc_before: Array  # () float32, m, the ego's route arc at the start of the tick
    arc_now: Array  # () float32, m, the ego's route arc at the end of the tick
    light: Array  # () int32, LIGHT_* state of the ego's light at ``t``
    justified: Array  # () bool, from :func:`justified_stop`
    fault: Array  # () bool, controller fault this tick


def measure(scenario: Scenario, end: TickEnd, settings: ScoringSettings) -> TickSample:
    """The tick's :class:`TickSample` (one execution, after the world was stepped).

    Args:
        scenario: the execution's static scenario.
        end: the world at the end of the tick (:class:`TickEnd`).
        settings: scoring thresholds.
    """
    ego, actors, present, protocol = end.ego, end.actors, end.present, end.protocol
    t, progress, dist_to_route, light = end.t, end.progress, end.dist_to_route, end.light
    arc_before, arc_now, justified, fault = end.arc_before, end.arc_now, end.justified, end.fault
    cfg = scenario.config
    h = cfg.hazard_index
    ext = scenario.actors.extent
    ego_ext = jnp.asarray(EGO_EXTENT, jnp.float32)
    overlap = geometry.overlap_with_boxes(ego.xy, ego.yaw, ego_ext, actors.xy, actors.yaw, ext)
    occ = scenario.occluders
    hit_occ = geometry.overlap_with_boxes(ego.xy, ego.yaw, ego_ext, occ.center, occ.yaw, occ.extent)
    contact = jnp.any(overlap & present) | jnp.any(hit_occ & occ.valid)
    collision = contact & (ego.speed >= settings.collision_min_speed_mps)
    # only the hazard's box distance is scored (TTC, clearance): one box pair, not A
    hazard_dist = geometry.box_distance(
        ego.xy, ego.yaw, ego_ext, actors.xy[h], actors.yaw[h], ext[h]
    )
    ego_vel = ego.speed * jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    hz_vel = actors.speed[h] * jnp.stack([jnp.cos(actors.yaw[h]), jnp.sin(actors.yaw[h])])
    crossed_stop = (arc_before < cfg.ego_stop_s) & (arc_now >= cfg.ego_stop_s)
    fb_lo, fb_hi = matched_window(cfg.s_warn, cfg.s_event, cfg.s_conflict, settings)
    return TickSample(
        t=t,
        ego_speed=ego.speed,
        ego_accel=ego.accel,
        progress=progress,
        route_length=scenario.route.length,
        dist_to_route=dist_to_route,
        outside_lanes=outside_lanes(scenario.lanes, ego, settings),
        red_light_violation=crossed_stop & (light == LIGHT_RED),
        collision=collision,
        hazard_present=present[h] & cfg.is_route_a,
        hazard_rel=actors.xy[h] - ego.xy,
        hazard_rel_vel=hz_vel - ego_vel,
        hazard_box_dist=hazard_dist,
        justified_stop=justified,
        slow_unjustified=(ego.speed < settings.slow_speed_fraction * cfg.v_ref) & ~justified,
        fb_window=(progress >= fb_lo) & (progress <= fb_hi),
        controller_fault=fault,
        t_warn_point=protocol.t_warn_point,
        t_event=protocol.t_event,
        t_warn_off=protocol.t_warn_off,
        t_clear=protocol.t_clear,
        is_route_a=cfg.is_route_a,
        coincident_onset=cfg.s_event <= cfg.s_warn,
    )


def execution_ended(
    scenario: Scenario,
    t: Array,
    progress: Array,
    dist_to_route: Array,
    still_time: Array,
    settings: ScoringSettings,
) -> Array:
    """() bool: the execution is over — route completed, timed out, deviated 30 m or blocked 20 s.

    Args:
        scenario: the execution's static scenario.
        t: () float32, s, time at the end of the tick.
        progress: () float32, m, furthest route arc reached.
        dist_to_route: () float32, m.
        still_time: () float32, s, continuous time the ego has been still.
        settings: the route's end zone, the deviation and standstill limits.
    """
    return (
        (progress >= settings.completion_length(scenario.route.length))
        | (t >= scenario.config.timeout_s)
        | (dist_to_route >= settings.route_deviation_m)
        | (still_time >= settings.block_still_s)
    )
