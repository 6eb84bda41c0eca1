"""The readings of the observation-level sensors, for one scenario at one tick: the warning as
its delivered text, the ground truth with its forecasts, the six-camera rig, and the actors as
the declared cameras show them (the zero sentinel elsewhere).

Each function reads the static :class:`~lantern_jax.types.world.Scenario` and the simulator's state
at the start of a tick (:class:`lantern_jax.sim.state.State`; named ``state`` here, since the
state type is the simulator's, a layer above).  The sensor table
(:mod:`lantern_jax.sensors.registry`) joins them to the observation;
:func:`lantern_jax.sim.observe.observe` builds it.

The simulator's own decisions (protocol, measurement) never read an observation: they use the
ground truth (:func:`actors_in_ego_frame`, :func:`delivered_warning`).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import OVERRIDE_FRAME_EGO, SURROUND_FOV
from lantern_jax.dynamics.forecast import earliest_event_time, forecast_actors
from lantern_jax.maths import geometry
from lantern_jax.scenarios import warnings
from lantern_jax.sensors import warning_delivery
from lantern_jax.sensors.cameras import SURROUND_RAYS, camera_view
from lantern_jax.types.language import MAX_TOKENS, PAD_ID
from lantern_jax.types.observation import FORECAST_DT, FORECAST_STEPS, PrivilegedView, SurroundView
from lantern_jax.types.world import Scenario, present

Array = jax.Array
State = Any  # the simulator's state (lantern_jax.sim.state.State)


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
    active, text_id, overridden = warning_delivery.delivered_warning(state.protocol, cfg, state.t)
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
    """The six-camera rig now (:func:`~lantern_jax.sensors.cameras.camera_view` at 360 deg)."""
    v = camera_view(scenario, state.ego, state.actors, SURROUND_FOV, SURROUND_RAYS)
    on = present(scenario.actors, state.actors)
    return SurroundView(visible=v.visible & on, ranges=v.ranges, hit_class=v.hit_class)
