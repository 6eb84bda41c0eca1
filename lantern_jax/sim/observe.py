"""Perception and observation of one scenario: visibility, range image, route, warning."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax import geometry, polyline
from lantern_jax.constants import BIG, FRONT_CAMERA_FOV, LIGHT_GREEN
from lantern_jax.dynamics.lights import light_states
from lantern_jax.policies.observation import (
    NUM_RANGE_RAYS,
    NUM_ROUTE_POINTS,
    ROUTE_STEP,
    Observation,
)
from lantern_jax.scenarios import protocol
from lantern_jax.sensors.visibility import camera_pose, range_image, visible_actors
from lantern_jax.world import World

Array = jax.Array


@struct.dataclass
class Percept:
    """Sensor results computed once per tick (after the world has been stepped)."""

    visible: Array  # (A,) bool, front-camera visibility of each actor
    ranges: Array  # (NUM_RANGE_RAYS,) float32, m, front-camera range image
    route_arc: Array  # () float32, m, ego projection onto the route (may be < 0 or > length)
    dist_to_route: Array  # () float32, m, ego centre distance from the route polyline
    progress: Array  # () float32, m, furthest route arc reached (monotone, clipped to length)


def sense(
    world: World, progress_prev: Array, route_proj: tuple[Array, Array] | None = None
) -> Percept:
    """Compute the percept of the current world (camera visibility, range image, route).

    Args:
        world: the scenario at the current tick.
        progress_prev: () m, progress before this tick (progress is monotone).
        route_proj: the ego's (route arc, distance from the route) when already computed.
    """
    a = world.actors
    cam_xy, cam_yaw = camera_pose(world.ego.xy, world.ego.yaw)
    rng = world.params.sensing_range
    vis = visible_actors(cam_xy, cam_yaw, a.xy, a.yaw, a.extent, a.present, FRONT_CAMERA_FOV, rng)
    ranges, _ = range_image(
        cam_xy, cam_yaw, a.xy, a.yaw, a.extent, a.present, FRONT_CAMERA_FOV, NUM_RANGE_RAYS, rng
    )
    r = world.route
    if route_proj is None:
        arc, _, _, dist = polyline.project(r.xy, r.s, r.valid, world.ego.xy)
    else:
        arc, dist = route_proj
    progress = jnp.maximum(progress_prev, jnp.clip(arc, 0.0, r.length))
    return Percept(visible=vis, ranges=ranges, route_arc=arc, dist_to_route=dist, progress=progress)


def ego_light(world: World, t: Array) -> Array:
    """() int32 LIGHT_* state of the ego's traffic light at ``t`` (GREEN when it has none)."""
    states = light_states(world.lights, t)
    idx = jnp.clip(world.params.ego_light, 0, states.shape[0] - 1)
    return jnp.where(world.params.ego_light >= 0, states[idx], LIGHT_GREEN).astype(jnp.int32)


def grounded_position(world: World) -> Array:
    """(2,) m, the warning's <FRONT_CAR_POS>: hazard position in the ego frame (x fwd, y right).

    With the position-noise ablation, Gaussian noise of ``pos_noise_sigma`` (independent per
    tick, seeded by ``noise_seed``) is added.
    """
    h = world.actors.xy[world.params.hazard_index]
    pos = geometry.world_to_ego(h, world.ego.xy, world.ego.yaw)
    key = jax.random.fold_in(jax.random.PRNGKey(world.params.noise_seed), world.tick)
    noise = jax.random.normal(key, (2,), jnp.float32) * world.params.pos_noise_sigma
    return pos + noise


def observe(world: World, percept: Percept) -> Observation:
    """Build the policy observation of the current tick.

    Args:
        world: the scenario at time ``world.t``.
        percept: the sensing results of the same tick (:func:`sense`).
    """
    ego, a, r = world.ego, world.actors, world.route
    arcs = percept.route_arc + ROUTE_STEP * jnp.arange(NUM_ROUTE_POINTS, dtype=jnp.float32)
    pts = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(arcs)
    route = geometry.world_to_ego(pts, ego.xy, ego.yaw)
    targets = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(
        percept.route_arc + jnp.asarray([10.0, 30.0])
    )
    heading = jnp.stack([jnp.cos(a.yaw), jnp.sin(a.yaw)], -1)
    vel_w = heading * a.speed[:, None]
    present = a.present
    active = protocol.warning_active(world.protocol, world.params, world.t)
    p = world.params
    dist_to_stop = jnp.where(p.ego_stop_s < BIG * 0.5, p.ego_stop_s - percept.route_arc, BIG)
    return Observation(
        ego_speed=ego.speed,
        ego_accel=ego.accel,
        ego_steer=ego.steer,
        v_ref=p.v_ref,
        route=route,
        target_points=geometry.world_to_ego(targets, ego.xy, ego.yaw),
        dist_to_route_end=r.length - percept.route_arc,
        actor_xy=jnp.where(present[:, None], geometry.world_to_ego(a.xy, ego.xy, ego.yaw), BIG),
        actor_vel=jnp.where(present[:, None], geometry.world_to_ego_vec(vel_w, ego.yaw), 0.0),
        actor_dir=geometry.world_to_ego_vec(heading, ego.yaw),
        actor_extent=a.extent,
        actor_kind=a.kind,
        visible=percept.visible & present,
        present=present,
        range_image=percept.ranges,
        light_state=ego_light(world, world.t),
        dist_to_stop=dist_to_stop,
        warning_active=active,
        warning_text_id=jnp.where(active, p.text_id, -1).astype(jnp.int32),
        warning_pos=jnp.where(active, grounded_position(world), 0.0),
    )
