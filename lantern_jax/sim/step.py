"""One 20 Hz tick of one scenario execution: policy -> controller -> dynamics -> protocol.

Order inside a tick (time ``t`` -> ``t + DT``):

1. the policy reads the observation of ``t`` and returns 10 waypoints; non-finite waypoints are
   a controller fault (full braking, recorded), never propagated into the state;
2. the waypoint controller and the ego bicycle advance the ego;
3. the protocol records the warning point, runs the anti-deadlock countdown and starts the
   event (sub-tick times);
4. scripted actors (closed form, triggered by the event) and IDM traffic advance;
5. the camera senses the new world; the protocol records warning termination and clearance,
   and a cleared hazard is removed;
6. a :class:`~lantern_jax.scoring.sample.TickSample` is folded into the telemetry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax import geometry, polyline
from lantern_jax.constants import (
    BIG,
    DT,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    LIGHT_GREEN,
    LIGHT_RED,
    ROLE_BACKGROUND,
)
from lantern_jax.dynamics.actors import step_actors
from lantern_jax.dynamics.bicycle import bicycle_step, sanitize_controls
from lantern_jax.dynamics.controller import track_waypoints
from lantern_jax.dynamics.lights import light_states
from lantern_jax.policies.planner import project_points_on_route
from lantern_jax.scenarios import protocol
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.telemetry import Telemetry, init_telemetry, update_telemetry
from lantern_jax.sim.observe import Percept, ego_light, observe, sense
from lantern_jax.world import World

Array = jax.Array

HOLD_LIGHT_DIST = 30.0  # m, a red light this close ahead holds the ego (pauses the countdown)
QUEUE_DIST = 12.0  # m, a slow background vehicle this close ahead in the corridor is a queue
JUSTIFY_LEAD_DIST = 15.0  # m, an actor this close ahead in the corridor justifies a stop
ROUTE_END_DIST = 10.0  # m, standing this close to the route end is justified
LANE_MARGIN = 0.5  # m, outside_route_lanes tolerance beyond half a lane width
WRONG_WAY = 2.0 * jnp.pi / 3.0  # rad, heading difference that counts as driving a lane backwards
SEVERE_DEVIATION = 30.0  # m, route deviation that ends the route
STALL_END = 20.0  # s, standing still this long ends the execution (blocked)


@struct.dataclass
class SimState:
    """The scan carry of one execution."""

    world: World
    percept: Percept
    telemetry: Telemetry
    done: Array  # () bool, the execution has ended (state frozen)
    fault: Array  # () bool, a controller fault happened at some tick


@struct.dataclass
class TickRecord:
    """What is kept per tick when full trajectories are recorded (for plots).

    State fields (``t``, ego, actors, visibility) are those at the END of the tick; the policy
    fields (``warning_active``, ``warning_pos``, ``waypoints``) are what the policy saw and
    returned at the START of it.  After an execution has ended, records repeat its final state
    (``done`` True) with the policy fields zeroed.
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
    warning_pos: Array  # (2,) m, ego frame
    waypoints: Array  # (10, 2) m, ego frame
    light: Array  # () int32
    done: Array  # () bool


@struct.dataclass
class Carry:
    """The part of :class:`SimState` that changes over time (the scan carry).

    Static scenario data (map, route, lights, actor scripts, parameters) is closed over rather
    than carried, so that freezing finished executions and the scan's loop state never copy it.
    """

    t: Array  # () s
    tick: Array  # () int32
    ego: Any  # EgoState
    actors: Any  # Actors
    protocol: Any  # ProtocolState
    percept: Percept
    telemetry: Telemetry
    done: Array  # () bool
    fault: Array  # () bool


def to_carry(state: SimState) -> Carry:
    """The dynamic part of a :class:`SimState`."""
    w = state.world
    return Carry(w.t, w.tick, w.ego, w.actors, w.protocol, state.percept, state.telemetry,
                 state.done, state.fault)  # fmt: skip


def from_carry(static: World, c: Carry) -> SimState:
    """Re-attach the static world to a carry."""
    world = static.replace(t=c.t, tick=c.tick, ego=c.ego, actors=c.actors, protocol=c.protocol)
    return SimState(world=world, percept=c.percept, telemetry=c.telemetry, done=c.done,
                    fault=c.fault)  # fmt: skip


def init_state(world: World) -> SimState:
    """Initial carry: sense the start state, empty telemetry."""
    percept = sense(world, jnp.asarray(0.0, jnp.float32))
    return SimState(
        world=world,
        percept=percept,
        telemetry=init_telemetry(),
        done=jnp.asarray(False),
        fault=jnp.asarray(False),
    )


def corridor_gaps(obs) -> tuple[Array, Array]:
    """Route gap ahead of the ego and lateral distance from the route of every actor.

    Uses the observation of the tick (its route points ahead of the ego and the actors in the
    ego frame), so the projection runs on the 24 observed route points rather than the whole
    route.

    Returns:
        gap: (A,) m, route distance from the ego front to the actor's nearest point.
        lateral: (A,) m, distance of the actor centre from the route minus its half size.
    """
    arc, dist = project_points_on_route(obs.route, obs.actor_xy)
    half = jnp.max(obs.actor_extent, axis=-1)
    return arc - EGO_HALF_LENGTH - half, dist - half


def outside_lanes(world: World) -> Array:
    """() bool: the ego centre is in no lane (half width + 0.5 m), or drives its lane the wrong way.

    Wrong way = heading more than 120 deg from the lane's direction (the leaderboard's junction
    threshold, used everywhere here).
    """
    ln, ego = world.lanes, world.ego
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])

    def one(center, pv, width):
        dist, direction = polyline.nearest_segment(center, pv, ego.xy)
        norm = jnp.sqrt(jnp.maximum(jnp.sum(direction * direction), 1e-12))
        wrong = jnp.sum(direction * heading) < jnp.cos(WRONG_WAY) * norm
        return (dist <= 0.5 * width + LANE_MARGIN) & ~wrong

    inside = jax.vmap(one)(ln.center, ln.point_valid, ln.width)
    return ~jnp.any(inside & ln.valid)


def tick(
    act: Callable[[Any, Any], Array], params: Any, state: SimState, temperature: Array
) -> tuple[SimState, TickRecord]:
    """Advance one execution by one tick (a :class:`SimState` wrapper of :func:`tick_carry`)."""
    carry, rec = tick_carry(act, params, state.world, to_carry(state), temperature)
    return from_carry(state.world, carry), rec


def tick_carry(
    act: Callable[[Any, Any], Array],
    params: Any,
    static: World,
    carry: Carry,
    temperature: Array,
) -> tuple[Carry, TickRecord]:
    """Advance one execution by one tick (see the module docstring for the order).

    Args:
        act: the policy's ``act(params, obs) -> (10, 2)`` waypoints.
        params: the policy parameters.
        static: the execution's world (its static fields are used; the dynamic ones come from
            ``carry``).
        carry: the dynamic state.
        temperature: () soft-score temperature for the telemetry's smooth accumulators.

    Returns:
        (new carry — identical to ``carry`` when the execution had already ended, record).
    """
    state = carry
    world = static.replace(
        t=carry.t, tick=carry.tick, ego=carry.ego, actors=carry.actors, protocol=carry.protocol
    )
    percept = carry.percept
    p = world.params
    obs = observe(world, percept)
    wps = act(params, obs)
    wp_fault = ~jnp.all(jnp.isfinite(wps))
    wps_safe = jnp.where(wp_fault, 0.0, wps)
    steer_cmd, accel_cmd = track_waypoints(world.ego, wps_safe, p.friction)
    steer_cmd, accel_cmd, ctl_fault = sanitize_controls(steer_cmd, accel_cmd)
    fault = wp_fault | ctl_fault
    accel_cmd = jnp.where(fault, -BIG, accel_cmd)  # full (friction-limited) braking
    steer_cmd = jnp.where(fault, world.ego.steer, steer_cmd)
    ego = bicycle_step(world.ego, steer_cmd, accel_cmd, p.friction)
    t_next = world.t + DT
    world = world.replace(ego=ego, t=t_next, tick=world.tick + 1)

    # Route progress and what holds the ego (for the anti-deadlock pause).
    r = world.route
    arc_now, _, _, dist_now = polyline.project(r.xy, r.s, r.valid, ego.xy)
    progress = jnp.maximum(percept.progress, jnp.clip(arc_now, 0.0, world.route.length))
    light = ego_light(world, t_next)
    to_stop = p.ego_stop_s - arc_now
    held_light = (light != LIGHT_GREEN) & (to_stop > -1.0) & (to_stop < HOLD_LIGHT_DIST)
    gap, lateral = corridor_gaps(obs)
    present = world.actors.present
    queue = (
        present
        & (lateral < EGO_HALF_WIDTH + 0.5)
        & (world.actors.role == ROLE_BACKGROUND)
        & (gap > -1.0)
        & (gap < QUEUE_DIST)
        & (world.actors.speed < 1.0)
    )
    held = held_light | jnp.any(queue)
    proto = protocol.advance_markers(world.protocol, p, t_next, percept.progress, progress, held)

    # Actors.
    lights_now = light_states(world.lights, t_next)
    actors = step_actors(
        world.actors, world.script, t_next, proto.t_event, lights_now, ego.xy, ego.yaw, ego.speed
    )
    h = p.hazard_index
    despawn = protocol.happened(proto.t_clear) & p.despawn_on_clear
    actors = actors.replace(active=actors.active.at[h].set(actors.active[h] & ~despawn))
    world = world.replace(actors=actors, protocol=proto)

    new_percept = sense(world, percept.progress, (arc_now, dist_now))
    hazard_visible = new_percept.visible[h] & actors.present[h]
    proto = protocol.advance_hazard(proto, p, t_next, hazard_visible, actors.s[h], ego.speed)
    first_warn = protocol.happened(proto.t_warn_point) & ~protocol.happened(
        carry.protocol.t_warn_point
    )
    proto = proto.replace(
        t_warn_on=protocol.warning_onset(proto, p),
        hazard_visible_at_warn=jnp.where(first_warn, hazard_visible, proto.hazard_visible_at_warn),
    )
    cleared_now = protocol.happened(proto.t_clear) & p.despawn_on_clear
    actors = actors.replace(active=actors.active.at[h].set(actors.active[h] & ~cleared_now))
    world = world.replace(actors=actors, protocol=proto)

    # Telemetry sample.
    a = world.actors
    ego_ext = jnp.asarray([EGO_HALF_LENGTH, EGO_HALF_WIDTH], jnp.float32)
    overlap = geometry.overlap_with_boxes(ego.xy, ego.yaw, ego_ext, a.xy, a.yaw, a.extent)
    collision = jnp.any(overlap & a.present) & (ego.speed >= 0.1)
    dists = geometry.distance_to_boxes(ego.xy, ego.yaw, ego_ext, a.xy, a.yaw, a.extent)
    ego_vel = ego.speed * jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    hz_vel = a.speed[h] * jnp.stack([jnp.cos(a.yaw[h]), jnp.sin(a.yaw[h])])
    crossed_stop = (percept.route_arc < p.ego_stop_s) & (arc_now >= p.ego_stop_s)
    red_violation = crossed_stop & (light == LIGHT_RED)
    in_corr = present & (lateral < EGO_HALF_WIDTH + 1.0)
    lead = jnp.any(in_corr & (gap > -2.0) & (gap < JUSTIFY_LEAD_DIST))
    justified = held_light | lead | (world.route.length - arc_now < ROUTE_END_DIST)
    sample = TickSample(
        t=t_next,
        ego_speed=ego.speed,
        ego_accel=ego.accel,
        progress=new_percept.progress,
        route_length=world.route.length,
        dist_to_route=new_percept.dist_to_route,
        outside_lanes=outside_lanes(world),
        red_light_violation=red_violation,
        collision=collision,
        hazard_present=a.present[h] & p.is_route_a,
        hazard_rel=a.xy[h] - ego.xy,
        hazard_rel_vel=hz_vel - ego_vel,
        hazard_box_dist=dists[h],
        justified_stop=justified,
        controller_fault=fault,
        t_warn_point=proto.t_warn_point,
        t_event=proto.t_event,
        t_warn_off=proto.t_warn_off,
        t_clear=proto.t_clear,
        is_route_a=p.is_route_a,
        coincident_onset=p.s_event <= p.s_warn,
    )
    tel = update_telemetry(state.telemetry, sample, temperature)

    completed = new_percept.progress >= world.route.length - 2.0
    ended = (
        completed
        | (t_next >= p.timeout_s)
        | (new_percept.dist_to_route >= SEVERE_DEVIATION)
        | (proto.ego_still_time >= STALL_END)
    )
    new = Carry(
        t=world.t,
        tick=world.tick,
        ego=world.ego,
        actors=world.actors,
        protocol=world.protocol,
        percept=new_percept,
        telemetry=tel,
        done=ended,
        fault=state.fault | fault,
    )
    new = jax.tree.map(lambda n, o: jnp.where(state.done, o, n), new, state)
    # Records of ticks after the end repeat the frozen state (the run's last real tick).
    live = ~state.done
    rec = TickRecord(
        t=new.t,
        ego_xy=new.ego.xy,
        ego_yaw=new.ego.yaw,
        ego_speed=new.ego.speed,
        ego_accel=new.ego.accel,
        actor_xy=new.actors.xy,
        actor_yaw=new.actors.yaw,
        actor_present=new.actors.present,
        visible=new.percept.visible & new.actors.present,
        warning_active=obs.warning_active & live,
        warning_pos=jnp.where(live, obs.warning_pos, 0.0),
        waypoints=jnp.where(live, wps_safe, 0.0),
        light=light,
        done=new.done,
    )
    return new, rec
