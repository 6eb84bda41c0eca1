"""The policy observation (:class:`~lantern_jax.observation.Observation`) of one scenario.

Built from the static :class:`~lantern_jax.world.Scenario` and the dynamic
:class:`~lantern_jax.sim.state.State` at the start of a tick: the route ahead in the ego frame,
the actors in the ego frame (with the camera's visibility mask), the range image, the ego's
light and stop line, and the cooperative warning (active flag, text id, token ids, grounded
position and whether the text states one).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax import geometry, polyline
from lantern_jax.constants import BIG, OVERRIDE_FRAME_EGO
from lantern_jax.dynamics.lights import ego_light_state
from lantern_jax.observation import NUM_ROUTE_POINTS, ROUTE_STEP, Observation
from lantern_jax.scenarios import protocol, warnings
from lantern_jax.sim.state import State
from lantern_jax.world import Scenario, present

Array = jax.Array

NAV_TARGETS_M = (10.0, 30.0)  # m ahead on the route: the two navigation target points


def grounded_position(scenario: Scenario, state: State) -> Array:
    """(2,) m, the warning's <FRONT_CAR_POS>: hazard position in the ego frame (x fwd, y right).

    With the position-noise ablation, Gaussian noise of ``pos_noise_sigma`` (independent per
    tick, seeded by ``noise_seed``) is added.
    """
    cfg = scenario.config
    h = state.actors.xy[cfg.hazard_index]
    pos = geometry.world_to_ego(h, state.ego.xy, state.ego.yaw)
    key = jax.random.fold_in(jax.random.PRNGKey(cfg.noise_seed), state.tick)
    noise = jax.random.normal(key, (2,), jnp.float32) * cfg.pos_noise_sigma
    return pos + noise


def warning_fields(scenario: Scenario, state: State) -> dict[str, Array]:
    """The warning fields of the observation: what is delivered (protocol or override), its
    tokens (one lookup in the text table built outside ``jit``) and its position.

    The override position is exact (no position-noise ablation): world-frame positions are
    grounded into the current ego frame, ego-frame positions are delivered as they are.
    """
    cfg, ego = scenario.config, state.ego
    active, text_id, overridden = protocol.delivered_warning(state.protocol, cfg, state.t)
    tokens, has_position = warnings.text_language(text_id, active)
    fixed = jnp.stack([cfg.override_x, cfg.override_y])
    override_pos = jnp.where(
        cfg.override_frame == OVERRIDE_FRAME_EGO,
        fixed,
        geometry.world_to_ego(fixed, ego.xy, ego.yaw),
    )
    pos = jnp.where(overridden, override_pos, grounded_position(scenario, state))
    return dict(
        warning_active=active,
        warning_text_id=text_id,
        warning_pos=jnp.where(has_position, pos, 0.0),
        warning_has_position=has_position,
        warning_tokens=tokens,
    )


def observe(scenario: Scenario, state: State) -> Observation:
    """Build the policy observation of the current tick.

    Args:
        scenario: the execution's static scenario.
        state: the simulator state at time ``state.t`` (its percept is that of the same tick).
    """
    ego, a, r, cfg = state.ego, state.actors, scenario.route, scenario.config
    percept = state.percept
    arcs = percept.route_arc + ROUTE_STEP * jnp.arange(NUM_ROUTE_POINTS, dtype=jnp.float32)
    pts = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(arcs)
    route = geometry.world_to_ego(pts, ego.xy, ego.yaw)
    targets = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(
        percept.route_arc + jnp.asarray(NAV_TARGETS_M)
    )
    heading = jnp.stack([jnp.cos(a.yaw), jnp.sin(a.yaw)], -1)
    vel_w = heading * a.speed[:, None]
    on = present(scenario.actors, a)
    dist_to_stop = jnp.where(cfg.ego_stop_s < BIG * 0.5, cfg.ego_stop_s - percept.route_arc, BIG)
    return Observation(
        ego_speed=ego.speed,
        ego_accel=ego.accel,
        ego_steer=ego.steer,
        v_ref=cfg.v_ref,
        route=route,
        target_points=geometry.world_to_ego(targets, ego.xy, ego.yaw),
        dist_to_route_end=r.length - percept.route_arc,
        actor_xy=jnp.where(on[:, None], geometry.world_to_ego(a.xy, ego.xy, ego.yaw), BIG),
        actor_vel=jnp.where(on[:, None], geometry.world_to_ego_vec(vel_w, ego.yaw), 0.0),
        actor_dir=geometry.world_to_ego_vec(heading, ego.yaw),
        actor_extent=scenario.actors.extent,
        actor_kind=scenario.actors.kind,
        visible=percept.visible & on,
        present=on,
        range_image=percept.ranges,
        light_state=ego_light_state(scenario.lights, cfg.ego_light, state.t),
        dist_to_stop=dist_to_stop,
        **warning_fields(scenario, state),
    )
