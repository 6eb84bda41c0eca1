"""The policy observation (:class:`~lantern_jax.observation.Observation`) of one scenario.

Built from the static :class:`~lantern_jax.world.Scenario` and the dynamic
:class:`~lantern_jax.sim.state.State` at the start of a tick: the route ahead in the ego frame,
the actors in the ego frame (with the camera's visibility mask), the range image, the ego's
light and stop line, and the cooperative warning (active flag, text id, token ids, grounded
position and whether the text states one).

With ``privileged=True`` (a static switch, set for policies whose ``Policy.privileged`` flag is
on) it also fills ``Observation.privileged``: every actor's forecast over the next 2 s from its
own script or motion model (:mod:`lantern_jax.dynamics.forecast`), in the ego frame.  Ordinary
policies get ``None`` there and the forecast is never computed for them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax import geometry, polyline
from lantern_jax.constants import BIG, OVERRIDE_FRAME_EGO, SURROUND_FOV
from lantern_jax.dynamics.forecast import earliest_event_time, forecast_actors
from lantern_jax.dynamics.lights import ego_light_state
from lantern_jax.observation import (
    FORECAST_DT,
    FORECAST_STEPS,
    NUM_ROUTE_POINTS,
    ROUTE_STEP,
    Observation,
    PrivilegedView,
    SurroundView,
)
from lantern_jax.scenarios import protocol, warnings
from lantern_jax.sim.sense import SURROUND_RAYS, camera_view
from lantern_jax.sim.state import State
from lantern_jax.world import Scenario, present

Array = jax.Array

NAV_TARGETS_M = (10.0, 30.0)  # m ahead on the route: the two navigation target points


def position_offset(scenario: Scenario) -> Array:
    """(2,) m, world frame: the noisy-position ablation's displacement of the reported position.

    One displacement per execution (not redrawn per tick): length ``pos_noise_m`` exactly, in a
    direction drawn uniformly on the circle from the execution's ``noise_seed``.  It stands for
    a fixed localisation error of the warning's source; zero without the ablation.
    """
    cfg = scenario.config
    angle = jax.random.uniform(
        jax.random.PRNGKey(cfg.noise_seed), (), jnp.float32, 0.0, 2.0 * jnp.pi
    )
    return cfg.pos_noise_m * jnp.stack([jnp.cos(angle), jnp.sin(angle)])


def grounded_position(scenario: Scenario, state: State) -> Array:
    """(2,) m, the warning's <FRONT_CAR_POS>: hazard position in the ego frame (x fwd, y right).

    With the noisy-position ablation the reported hazard position is displaced by
    :func:`position_offset` (in the world frame, so the reported point is off by exactly
    ``pos_noise_m`` in the ego frame too).
    """
    h = state.actors.xy[scenario.config.hazard_index] + position_offset(scenario)
    return geometry.world_to_ego(h, state.ego.xy, state.ego.yaw)


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


def privileged_view(scenario: Scenario, state: State) -> PrivilegedView:
    """Every actor's 2-s forecast (:func:`~lantern_jax.dynamics.forecast.forecast_actors`) in
    the ego frame; a pending event may begin once the ego reaches the warning point."""
    ego, a, proto = state.ego, state.actors, state.protocol
    t_early = earliest_event_time(
        state.t, proto.t_warn_point, proto.t_event, scenario.config.force_event
    )
    on = present(scenario.actors, a)
    fc = forecast_actors(
        scenario.actors, a, on, state.t, proto.t_event, t_early, FORECAST_STEPS, FORECAST_DT
    )
    # world -> ego frame (x forward, y right), component-wise (see geometry.world_to_ego_vec)
    c, s = jnp.cos(ego.yaw), jnp.sin(ego.yaw)
    dx, dy = fc.x - ego.xy[0], fc.y - ego.xy[1]
    view = PrivilegedView(
        forecast_x=c * dx + s * dy,
        forecast_y=s * dx - c * dy,
        forecast_ux=c * fc.ux + s * fc.uy,
        forecast_uy=s * fc.ux - c * fc.uy,
        forecast_half_length=fc.half_length,
        forecast_half_width=fc.half_width,
        forecast_speed=fc.speed,
        forecast_valid=fc.valid,
    )
    # The barrier shields the forecast from the algebraic simplifier only: on CPU it is
    # expanded before the fusion passes, and the policy's box tests still re-derive the
    # forecast (benchmarks/profile_kernels.py --policy expert shows it; see split_map).
    return jax.lax.optimization_barrier(view)


def observe(
    scenario: Scenario, state: State, privileged: bool = False, surround: bool = False
) -> Observation:
    """Build the policy observation of the current tick.

    Args:
        scenario: the execution's static scenario.
        state: the simulator state at time ``state.t`` (its percept is that of the same tick).
        privileged: static; also fill ``Observation.privileged`` (:func:`privileged_view`).
        surround: static; also fill ``Observation.surround`` (:func:`surround_view`).
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
        range_class=percept.range_class,
        light_state=ego_light_state(scenario.lights, cfg.ego_light, state.t),
        dist_to_stop=dist_to_stop,
        **warning_fields(scenario, state),
        privileged=privileged_view(scenario, state) if privileged else None,
        surround=surround_view(scenario, state) if surround else None,
    )


def surround_view(scenario: Scenario, state: State) -> SurroundView:
    """The six-camera rig now (:func:`~lantern_jax.sim.sense.camera_view` at 360 deg)."""
    v = camera_view(scenario, state.ego, state.actors, SURROUND_FOV, SURROUND_RAYS)
    return SurroundView(visible=v.visible, ranges=v.ranges, hit_class=v.hit_class)
