"""The policy observation (:class:`~lantern_jax.types.observation.Observation`) of one scenario,
built from the sensors the policy declares and from nothing else.

Built from the static :class:`~lantern_jax.types.world.Scenario` and the dynamic
:class:`~lantern_jax.sim.state.State` at the start of a tick.  The front camera's observation
comes first (every policy's): the route ahead in the ego frame, the ego's state, light and stop
line, the actors the camera sees now (every other slot holds the zero sentinel) and its range
image, with no warning text.  Then each declared sensor joins its reading, through its entry of
the sensor table (:mod:`lantern_jax.sensors.registry`): the warning text (``"warning"``), the
six-camera rig (``"surround_rig"``, whose actors join those seen), ground truth and forecasts
(``"privileged"``), or the view of a sensor registered from user code (``obs.views[name]``).
A policy that declares none of them gets ``None`` there and pays nothing for them.

The readings themselves are :mod:`lantern_jax.sensors.views` (their names are kept importable
from here).  The simulator's own decisions (protocol, measurement) never read an observation:
they use the ground truth (:func:`actors_in_ego_frame`, :func:`delivered_warning`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import BIG
from lantern_jax.dynamics.lights import ego_light_state
from lantern_jax.maths import geometry, polyline
from lantern_jax.scenarios import warnings
from lantern_jax.sensors.registry import SENSOR_REGISTRY

# the sensors' readings, kept importable from here
from lantern_jax.sensors.views import actors_in_ego_frame as actors_in_ego_frame
from lantern_jax.sensors.views import delivered_warning as delivered_warning
from lantern_jax.sensors.views import forecast_view as forecast_view
from lantern_jax.sensors.views import grounded_position as grounded_position
from lantern_jax.sensors.views import mask_actors as mask_actors
from lantern_jax.sensors.views import no_warning_fields as no_warning_fields
from lantern_jax.sensors.views import position_offset as position_offset
from lantern_jax.sensors.views import privileged_view as privileged_view
from lantern_jax.sensors.views import surround_view as surround_view
from lantern_jax.sensors.views import warning_fields as warning_fields
from lantern_jax.sim.state import State
from lantern_jax.types.observation import (
    FRONT_CAMERA,
    NUM_ROUTE_POINTS,
    ROUTE_STEP,
    WARNING,
    Observation,
    PrivilegedView,
)
from lantern_jax.types.world import Scenario

Array = jax.Array

NAV_TARGETS_M = (10.0, 30.0)  # m ahead on the route: the two navigation target points
DEFAULT_SENSORS = (FRONT_CAMERA,)


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


def front_camera_observation(scenario: Scenario, state: State) -> Observation:
    """The observation every policy gets (the front camera, the map and the ego's own state),
    before any other sensor joins its reading: no warning text, no rig, no ground truth."""
    r, cfg, percept = scenario.route, scenario.config, state.percept
    route, targets = route_ahead(scenario, state)
    truth = actors_in_ego_frame(scenario, state)
    seen = percept.visible & truth["present"]
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
        **no_warning_fields(),
    )


def observe(
    scenario: Scenario,
    state: State,
    sensors: tuple[str, ...] = DEFAULT_SENSORS,
    bank: warnings.TextBank | None = None,
) -> Observation:
    """Build the observation of the current tick from the declared sensors only: the front
    camera's (:func:`front_camera_observation`), then each declared sensor's reading joined by
    its entry of the sensor table (:attr:`~lantern_jax.sensors.registry.Sensor.add`).

    Args:
        scenario: the execution's static scenario.
        state: the simulator state at time ``state.t`` (its percept is that of the same tick).
        sensors: static; the policy's sensor names
            (:func:`~lantern_jax.sensors.registry.normalize_sensors`; ``Policy.sensors``).
        bank: the warning texts (``Settings.bank``; traced in a compiled program).

    Raises:
        ValueError: naming a sensor the table does not hold.
    """
    obs = front_camera_observation(scenario, state)
    for name in dict.fromkeys(sensors):
        obs = SENSOR_REGISTRY.get(name).add(obs, scenario, state, bank)
    return obs


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
    simulator's world program (:mod:`lantern_jax.sim.split`) builds this with the ground truth
    off (a privileged policy's own program computes that from the state); the policy's own
    program drops what its policy did not declare, so the boundary holds.  It observes the
    built-in sensors only: a policy that declares a sensor registered from user code is run by
    the fused program (:func:`lantern_jax.sim.engine.split_possible`).

    Args:
        scenario, state: as :func:`observe`.
        privileged: () bool, compute the ground truth and forecasts.
        surround: () bool, fill ``Observation.surround`` and add what the rig sees.
        bank: the warning texts (traced in a compiled program).
        privileged_as: applied to the ground-truth view inside its branch (e.g. packing it,
            so that the branch that is off writes zeros of the packed shape only).

    Returns:
        (the observation with ``privileged=None``, ``privileged_as`` of the
        :class:`~lantern_jax.types.observation.PrivilegedView` or zeros of its shapes).
    """
    obs = observe(scenario, state, (FRONT_CAMERA, WARNING), bank)
    truth = actors_in_ego_frame(scenario, state)
    rig = _when(surround, lambda: surround_view(scenario, state))
    seen = obs.visible | rig.visible
    fields = {k: v for k, v in truth.items() if k != "present"}
    obs = obs.replace(visible=seen, **mask_actors(fields, seen), surround=rig)
    view = _when(privileged, lambda: privileged_as(forecast_view(scenario, state, truth)))
    return obs, view
