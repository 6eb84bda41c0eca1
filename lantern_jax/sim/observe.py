"""The policy observation (:class:`~lantern_jax.observation.Observation`) of one scenario,
built from the sensors the policy declares and from nothing else.

Built from the static :class:`~lantern_jax.world.Scenario` and the dynamic
:class:`~lantern_jax.sim.state.State` at the start of a tick: the route ahead in the ego frame,
the actors the declared cameras see now (every other slot holds the zero sentinel), the front
camera's range image, the ego's light and stop line, and — with the ``"warning"`` sensor — the
delivered warning as token ids and the value channel of the numbers it writes.

With the ``"privileged"`` sensor (a static switch) it also fills ``Observation.privileged``:
every actor's ground truth and its forecast over the next 2 s from its own script or motion
model (:mod:`lantern_jax.dynamics.forecast`).  With ``"surround_rig"`` it fills
``Observation.surround`` and adds what the rig sees to the actors.  Ordinary policies get
``None`` there and pay nothing for them.

The simulator's own decisions (protocol, measurement) never read an observation: they use the
ground truth (:func:`actors_in_ego_frame`, :func:`delivered_warning`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax import geometry, polyline
from lantern_jax.constants import BIG, OVERRIDE_FRAME_EGO, SURROUND_FOV
from lantern_jax.dynamics.forecast import earliest_event_time, forecast_actors
from lantern_jax.dynamics.lights import ego_light_state
from lantern_jax.language import MAX_TOKENS, PAD_ID
from lantern_jax.observation import (
    FORECAST_DT,
    FORECAST_STEPS,
    FRONT_CAMERA,
    NUM_ROUTE_POINTS,
    PRIVILEGED,
    ROUTE_STEP,
    SURROUND_RIG,
    WARNING,
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
DEFAULT_SENSORS = (FRONT_CAMERA,)


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


def delivered_warning(
    scenario: Scenario, state: State, bank: warnings.TextBank | None = None
) -> tuple[Array, Array, Array]:
    """What is delivered now: the protocol's warning or the override (ground truth, not a
    policy input).

    The override position is exact (no position-noise ablation): world-frame positions are
    grounded into the current ego frame, ego-frame positions are delivered as they are.

    Returns:
        active: () bool, a warning is delivered.
        text_id: () int32, its text-bank id (-1 when none).
        position: (2,) float32, m, ego frame, the position its text grounds (zeros when none or
            when the text states no position).
    """
    cfg, ego = scenario.config, state.ego
    active, text_id, overridden = protocol.delivered_warning(state.protocol, cfg, state.t)
    fixed = jnp.stack([cfg.override_x, cfg.override_y])
    override_pos = jnp.where(
        cfg.override_frame == OVERRIDE_FRAME_EGO,
        fixed,
        geometry.world_to_ego(fixed, ego.xy, ego.yaw),
    )
    pos = jnp.where(overridden, override_pos, grounded_position(scenario, state))
    has_position = warnings.text_tables(bank).has_position
    n = has_position.shape[0]
    states_position = jnp.asarray(has_position)[jnp.clip(text_id, 0, n - 1)]
    stated = active & (text_id >= 0) & (text_id < n) & states_position
    return active, text_id, jnp.where(stated, pos, 0.0)


def route_ahead(scenario: Scenario, state: State) -> tuple[Array, Array]:
    """The route ahead in the ego frame.

    Returns:
        route: (NUM_ROUTE_POINTS, 2) float32, m, ``ROUTE_STEP`` apart from the ego's projection.
        targets: (2, 2) float32, m, the navigation targets ``NAV_TARGETS_M`` ahead.
    """
    ego, r = state.ego, scenario.route
    at = state.percept.route_arc
    arcs = at + ROUTE_STEP * jnp.arange(NUM_ROUTE_POINTS, dtype=jnp.float32)
    pts = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(arcs)
    targets = jax.vmap(lambda s: polyline.interpolate(r.xy, r.s, r.valid, s)[0])(
        at + jnp.asarray(NAV_TARGETS_M)
    )
    return (
        geometry.world_to_ego(pts, ego.xy, ego.yaw),
        geometry.world_to_ego(targets, ego.xy, ego.yaw),
    )


def actors_in_ego_frame(scenario: Scenario, state: State) -> dict[str, Array]:
    """Ground truth of every actor slot in the ego frame (the simulator's, never a policy's
    input unless it is privileged).

    Returns:
        ``present`` (A,) bool and ``actor_xy``, ``actor_vel``, ``actor_dir``, ``actor_extent``
        (A, 2) float32 and ``actor_kind`` (A,) int32, zero where no actor is present.
    """
    ego, a = state.ego, state.actors
    on = present(scenario.actors, a)
    heading = jnp.stack([jnp.cos(a.yaw), jnp.sin(a.yaw)], -1)
    fields = dict(
        actor_xy=geometry.world_to_ego(a.xy, ego.xy, ego.yaw),
        actor_vel=geometry.world_to_ego_vec(heading * a.speed[:, None], ego.yaw),
        actor_dir=geometry.world_to_ego_vec(heading, ego.yaw),
        actor_extent=scenario.actors.extent,
        actor_kind=scenario.actors.kind,
    )
    return dict(present=on, **mask_actors(fields, on))


def mask_actors(fields: dict[str, Array], seen: Array) -> dict[str, Array]:
    """Per-actor fields with every slot outside ``seen`` ((A,) bool) set to the zero sentinel."""
    return {
        k: jnp.where(seen.reshape(seen.shape + (1,) * (v.ndim - 1)), v, jnp.zeros_like(v))
        for k, v in fields.items()
    }


def warning_fields(
    scenario: Scenario, state: State, bank: warnings.TextBank | None = None
) -> dict[str, Array]:
    """The warning as a policy with the ``"warning"`` sensor reads it: the delivered text's
    token ids and value channel (:func:`~lantern_jax.scenarios.warnings.warning_language`)."""
    active, text_id, pos = delivered_warning(scenario, state, bank)
    tokens, values = warnings.warning_language(text_id, active, pos, bank)
    return dict(warning_tokens=tokens, warning_values=values)


def no_warning_fields() -> dict[str, Array]:
    """The warning fields of a policy without the ``"warning"`` sensor: always no text."""
    return dict(
        warning_tokens=jnp.full((MAX_TOKENS,), PAD_ID, jnp.int32),
        warning_values=jnp.zeros((MAX_TOKENS,), jnp.float32),
    )


def forecast_view(scenario: Scenario, state: State, truth: dict[str, Array]) -> PrivilegedView:
    """Ground truth ``truth`` (:func:`actors_in_ego_frame`) and every actor's 2-s forecast
    (:func:`~lantern_jax.dynamics.forecast.forecast_actors`) in the ego frame; a pending event
    may begin once the ego reaches the warning point."""
    ego, a, proto = state.ego, state.actors, state.protocol
    t_early = earliest_event_time(
        state.t, proto.t_warn_point, proto.t_event, scenario.config.force_event
    )
    fc = forecast_actors(
        scenario.actors, a, truth["present"], state.t, proto.t_event, t_early, FORECAST_STEPS,
        FORECAST_DT,
    )  # fmt: skip
    # world -> ego frame (x forward, y right), component-wise (see geometry.world_to_ego_vec)
    c, s = jnp.cos(ego.yaw), jnp.sin(ego.yaw)
    dx, dy = fc.x - ego.xy[0], fc.y - ego.xy[1]
    view = PrivilegedView(
        **truth,
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


def privileged_view(scenario: Scenario, state: State) -> PrivilegedView:
    """The ``"privileged"`` sensor: ground truth and forecasts (:func:`forecast_view`)."""
    return forecast_view(scenario, state, actors_in_ego_frame(scenario, state))


def surround_view(scenario: Scenario, state: State) -> SurroundView:
    """The six-camera rig now (:func:`~lantern_jax.sim.sense.camera_view` at 360 deg)."""
    v = camera_view(scenario, state.ego, state.actors, SURROUND_FOV, SURROUND_RAYS)
    on = present(scenario.actors, state.actors)
    return SurroundView(visible=v.visible & on, ranges=v.ranges, hit_class=v.hit_class)


def observe(
    scenario: Scenario,
    state: State,
    sensors: tuple[str, ...] = DEFAULT_SENSORS,
    bank: warnings.TextBank | None = None,
) -> Observation:
    """Build the observation of the current tick from the declared sensors only.

    Args:
        scenario: the execution's static scenario.
        state: the simulator state at time ``state.t`` (its percept is that of the same tick).
        sensors: static; the policy's sensor names
            (:func:`~lantern_jax.observation.normalize_sensors`; ``Policy.sensors``).
        bank: static; the warning texts (``Settings.bank``).
    """
    r, cfg, percept = scenario.route, scenario.config, state.percept
    route, targets = route_ahead(scenario, state)
    truth = actors_in_ego_frame(scenario, state)
    seen = percept.visible & truth["present"]
    surround = surround_view(scenario, state) if SURROUND_RIG in sensors else None
    if surround is not None:
        seen = seen | surround.visible
    actor_fields = {k: v for k, v in truth.items() if k != "present"}
    dist_to_stop = jnp.where(cfg.ego_stop_s < BIG * 0.5, cfg.ego_stop_s - percept.route_arc, BIG)
    return Observation(
        ego_speed=state.ego.speed,
        ego_accel=state.ego.accel,
        ego_steer=state.ego.steer,
        v_ref=cfg.v_ref,
        route=route,
        target_points=targets,
        dist_to_route_end=r.length - percept.route_arc,
        **mask_actors(actor_fields, seen),
        visible=seen,
        range_image=percept.ranges,
        range_class=percept.range_class,
        light_state=ego_light_state(scenario.lights, cfg.ego_light, state.t),
        dist_to_stop=dist_to_stop,
        **(warning_fields(scenario, state, bank) if WARNING in sensors else no_warning_fields()),
        privileged=forecast_view(scenario, state, truth) if PRIVILEGED in sensors else None,
        surround=surround,
    )


def _when(on: Array, view: Callable[[], Any]) -> Any:
    """``view()`` when ``on`` (a traced, unbatched bool), else zeros of its shapes: a real
    branch (``lax.cond``), so the view costs nothing when off."""
    shapes = jax.eval_shape(view)
    return jax.lax.cond(
        on, view, lambda: jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
    )


def observe_every_sensor(
    scenario: Scenario,
    state: State,
    privileged: Array,
    surround: Array,
    bank: warnings.TextBank | None = None,
    privileged_as: Callable[[PrivilegedView], Any] = lambda view: view,
) -> tuple[Observation, Any]:
    """The observation of a policy whose heavy sensors are chosen at run time: the front
    camera and the warning always, the six-camera rig (``surround``) and the ground truth
    (``privileged``) when the traced bools say so (zeros otherwise, never computed).

    One program for every sensor declaration: :func:`observe` with the same sensors equals it
    field by field once the undeclared views are dropped (``surround=None``, the ground truth
    left out, the warning fields blanked for a policy without the warning sensor).  The
    simulator's world program (:mod:`lantern_jax.sim.split`) builds this; the policy's own
    program drops what its policy did not declare, so the boundary holds.

    Args:
        scenario, state: as :func:`observe`.
        privileged: () bool, compute the ground truth and forecasts.
        surround: () bool, fill ``Observation.surround`` and add what the rig sees.
        bank: static; the warning texts.
        privileged_as: applied to the ground-truth view inside its branch (e.g. packing it,
            so that the branch that is off writes zeros of the packed shape only).

    Returns:
        (the observation with ``privileged=None``, ``privileged_as`` of the
        :class:`~lantern_jax.observation.PrivilegedView` or zeros of its shapes).
    """
    obs = observe(scenario, state, (FRONT_CAMERA, WARNING), bank)
    truth = actors_in_ego_frame(scenario, state)
    rig = _when(surround, lambda: surround_view(scenario, state))
    seen = obs.visible | rig.visible
    fields = {k: v for k, v in truth.items() if k != "present"}
    obs = obs.replace(visible=seen, **mask_actors(fields, seen), surround=rig)
    view = _when(privileged, lambda: privileged_as(forecast_view(scenario, state, truth)))
    return obs, view
