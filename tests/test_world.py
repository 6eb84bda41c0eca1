"""Constructors and validate(): bad input is rejected with an error naming the field."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.constants import KIND_PEDESTRIAN, ROLE_HAZARD, TRIGGER_EVENT
from lantern_jax.scenarios.handmade import (
    ActorSpec,
    pack_route,
    scenario_params,
    straight_scene,
)


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
        (lambda w: w.replace(actors=_replace(w.actors, xy=w.actors.xy[:, :1])), "Actors.extent"),
        (lambda w: w.replace(ego=_replace(w.ego, xy=jnp.zeros((3,)))), "EgoState.xy"),
        (lambda w: w.replace(route=_replace(w.route, s=w.route.s[:-1])), "Route.s"),
    ],
)
def test_wrong_shapes_name_the_field(world, mutate, field):
    with pytest.raises(ValueError, match=field.split(".")[0]):
        mutate(world).validate()


def test_nan_and_inf_are_rejected(world):
    bad = world.replace(ego=_replace(world.ego, speed=jnp.asarray(np.nan, jnp.float32)))
    with pytest.raises(ValueError, match=r"EgoState.speed: contains NaN or inf"):
        bad.validate()
    xy = world.actors.xy.at[0, 1].set(jnp.inf)
    with pytest.raises(ValueError, match=r"Actors.xy: contains NaN or inf"):
        world.replace(actors=_replace(world.actors, xy=xy)).validate()


def test_nan_in_padding_slots_is_allowed(world):
    # Slot 5 is padding (valid=False): its values never enter the simulation.
    xy = world.actors.xy.at[5].set(jnp.nan)
    world.replace(actors=_replace(world.actors, xy=xy)).validate()


def test_negative_extent_is_rejected(world):
    ext = world.actors.extent.at[0, 0].set(-1.0)
    with pytest.raises(ValueError, match=r"Actors.extent: must be non-negative"):
        world.replace(actors=_replace(world.actors, extent=ext)).validate()


def test_route_needs_two_points():
    with pytest.raises(ValueError, match=r"Route.xy: a route needs at least two points"):
        pack_route(np.array([[0.0, 0.0]]))


def test_marker_order_and_positive_params_are_checked():
    with pytest.raises(ValueError, match=r"ScenarioParams.s_warn/s_event/s_conflict"):
        scenario_params(s_warn=40.0, s_event=30.0, s_conflict=50.0).validate()
    with pytest.raises(ValueError, match=r"ScenarioParams.friction: must be > 0"):
        scenario_params(friction=0.0).validate()
    with pytest.raises(ValueError, match=r"unknown fields \['frction'\]"):
        scenario_params(frction=1.0)


def test_hazard_index_must_name_a_slot(world):
    bad = world.replace(params=world.params.replace(hazard_index=jnp.asarray(99, jnp.int32)))
    with pytest.raises(ValueError, match=r"ScenarioParams.hazard_index: 99 outside"):
        bad.validate()


def test_script_lat_duration_must_be_positive(world):
    ld = world.script.lat_duration.at[0].set(0.0)
    with pytest.raises(ValueError, match=r"ActorScript.lat_duration: must be > 0"):
        world.replace(script=_replace(world.script, lat_duration=ld)).validate()
