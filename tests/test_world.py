"""Constructors and validate(): bad input is rejected with an error naming the field."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import KIND_PEDESTRIAN, OCC_WALL, ROLE_HAZARD, TRIGGER_EVENT
from lantern_jax.scenarios.assemble import execution_config
from lantern_jax.scenarios.handmade import ActorSpec, config_fields, pack_route, straight_scene
from lantern_jax.scenarios.road import OccluderSpec


def scenario_config(**overrides):
    return execution_config(config_fields(**overrides))


@pytest.fixture(scope="module")
def world():
    ped = ActorSpec(
        path=np.array([[50.0, -6.0], [50.0, 16.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
        role=ROLE_HAZARD, v_post=3.0, trigger=TRIGGER_EVENT,
    )  # fmt: skip
    return straight_scene([ped], s_warn=32.0, s_event=41.0, s_conflict=50.0)


def test_valid_world_passes(world):
    assert world.validate() is world


def _replace(obj, **kw):
    return dataclasses.replace(obj, **kw)


@pytest.mark.parametrize(
    "mutate, field",
    [
        (
            lambda w: w.replace(actors0=_replace(w.actors0, xy=w.actors0.xy[:, :1])),
            "ActorState.xy",
        ),
        (lambda w: w.replace(ego0=_replace(w.ego0, xy=jnp.zeros((3,)))), "EgoState.xy"),
        (lambda w: w.replace(route=_replace(w.route, s=w.route.s[:-1])), "Route.s"),
    ],
)
def test_wrong_shapes_name_the_field(world, mutate, field):
    with pytest.raises(ValueError, match=field.split(".")[0]):
        mutate(world).validate()


def test_nan_and_inf_are_rejected(world):
    bad = world.replace(ego0=_replace(world.ego0, speed=jnp.asarray(np.nan, jnp.float32)))
    with pytest.raises(ValueError, match=r"EgoState.speed: contains NaN or inf"):
        bad.validate()
    xy = world.actors0.xy.at[0, 1].set(jnp.inf)
    with pytest.raises(ValueError, match=r"ActorState.xy: contains NaN or inf"):
        world.replace(actors0=_replace(world.actors0, xy=xy)).validate()


def test_nan_in_padding_slots_is_allowed(world):
    # Slot 5 is padding (valid=False): its values never enter the simulation.
    xy = world.actors0.xy.at[5].set(jnp.nan)
    checked = world.replace(actors0=_replace(world.actors0, xy=xy)).validate()  # no raise
    assert bool(jnp.isnan(checked.actors0.xy[5]).all())  # accepted as it is, not repaired


def test_negative_extent_is_rejected(world):
    ext = world.actors.extent.at[0, 0].set(-1.0)
    with pytest.raises(ValueError, match=r"ActorScript.extent: must be non-negative"):
        world.replace(actors=_replace(world.actors, extent=ext)).validate()


def test_route_needs_two_points():
    with pytest.raises(ValueError, match=r"Route.xy: a route needs at least two points"):
        pack_route(np.array([[0.0, 0.0]]))


def test_marker_order_and_positive_params_are_checked():
    with pytest.raises(ValueError, match=r"ExecutionConfig.s_warn/s_event/s_conflict"):
        scenario_config(s_warn=40.0, s_event=30.0, s_conflict=50.0).validate()
    with pytest.raises(ValueError, match=r"ExecutionConfig.friction: must be > 0"):
        scenario_config(friction=0.0).validate()
    with pytest.raises(ValueError, match=r"unknown fields \['frction'\]"):
        scenario_config(frction=1.0)


def test_hazard_index_must_name_a_slot(world):
    bad = world.replace(config=world.config.replace(hazard_index=jnp.asarray(99, jnp.int32)))
    with pytest.raises(ValueError, match=r"ExecutionConfig.hazard_index: 99 outside"):
        bad.validate()


def test_script_lat_duration_must_be_positive(world):
    ld = world.actors.lat_duration.at[0].set(0.0)
    with pytest.raises(ValueError, match=r"ActorScript.lat_duration: must be > 0"):
        world.replace(actors=_replace(world.actors, lat_duration=ld)).validate()


def _family_scenario():
    from lantern_jax.scenarios.families import build_pair, sample_params

    return build_pair(sample_params("LWW", np.random.default_rng(5)))[0]


@pytest.mark.parametrize(
    "mutate, message",
    [
        # route length NaN, negative, or inconsistent with its arc lengths
        (lambda w: w.replace(route=_replace(w.route, length=jnp.float32(np.nan))),
         r"Route.length: contains NaN"),
        (lambda w: w.replace(route=_replace(w.route, length=jnp.float32(-5.0))),
         r"Route.length: -5.0 must equal the last valid arc length"),
        (lambda w: w.replace(route=_replace(w.route, length=w.route.length + 3.0)),
         r"Route.length: .* must equal the last valid arc length"),
        # family index out of range
        (lambda w: w.replace(config=w.config.replace(family=jnp.int32(99))),
         r"ExecutionConfig.family: 99 outside 0\.\.\d+"),  # 0..5, and registered families
        # an invalid light id for the ego and for an actor
        (lambda w: w.replace(config=w.config.replace(ego_light=jnp.int32(7))),
         r"ExecutionConfig.ego_light: 7 >= number of light slots"),
        (lambda w: w.replace(actors=_replace(w.actors, light_index=w.actors.light_index.at[0]
                                             .set(5))),
         r"ActorScript.light_index: must be -1 or < 2"),
        # decreasing path arc lengths
        (lambda w: w.replace(actors=_replace(w.actors, path_s=w.actors.path_s.at[0, 1].set(-1.0))),
         r"ActorScript.path_s: arc length must not decrease"),
    ],
)  # fmt: skip
def test_inconsistent_scenarios_are_rejected(world, mutate, message):
    with pytest.raises(ValueError, match=message):
        mutate(world).validate()


def test_light_with_an_empty_cycle_is_rejected():
    sc = _family_scenario()
    lights = sc.lights
    if not bool(lights.valid[0]):
        lights = _replace(lights, valid=lights.valid.at[0].set(True))
    zero = lights.green.at[0].set(0.0)
    bad = sc.replace(lights=_replace(lights, green=zero, yellow=zero * 0, red=zero * 0))
    with pytest.raises(ValueError, match=r"TrafficLights.green: light 0 has an empty cycle"):
        bad.validate()


def test_ego_light_must_be_a_valid_slot():
    sc = _family_scenario()
    lights = _replace(sc.lights, valid=jnp.zeros_like(sc.lights.valid))
    bad = sc.replace(lights=lights, config=sc.config.replace(ego_light=jnp.int32(0)))
    with pytest.raises(ValueError, match=r"ExecutionConfig.ego_light: light slot 0 is not valid"):
        bad.validate()


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda o: o.replace(extent=o.extent.at[0, 0].set(0.0)), "Occluders.extent"),
        (lambda o: o.replace(center=o.center.at[0, 1].set(jnp.nan)), "Occluders.center"),
        (lambda o: o.replace(kind=o.kind.at[0].set(7)), "Occluders.kind"),
        (lambda o: o.replace(yaw=o.yaw[:3]), "Occluders.yaw"),
    ],
)
def test_bad_occluders_name_the_field(mutate, field):
    wall = OccluderSpec(np.array([20.0, 8.0]), 0.0, (4.0, 0.3), OCC_WALL, "wall")
    sc = straight_scene([], occluders=[wall])
    assert bool(sc.occluders.valid[0]) and not bool(sc.occluders.valid[1])
    with pytest.raises(ValueError, match=field):
        sc.replace(occluders=mutate(sc.occluders)).validate()
    # NaN in a padding slot is allowed (only valid slots must be finite)
    pad_nan = sc.occluders.replace(center=sc.occluders.center.at[1, 0].set(jnp.nan))
    sc.replace(occluders=pad_nan).validate()
