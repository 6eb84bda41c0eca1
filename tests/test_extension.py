"""Extending the benchmark from outside the package, as a user does: nothing under
``lantern_jax/`` is edited.

* a **sensor**: a rear-facing range sensor, registered from this file, declared by a policy
  that reads it (the user code is the ``# --- user code`` block below);
* a **metric**: the hardest braking of every execution and the route completion measured
  again from the ticks, as route-table columns described in the schema;
* a **family**: ``tests/family_example.py (the JWK family; its registration, suite file and
  evaluation through the API and the command line are tested in ``tests/test_unseen.py`` and
  ``tests/test_family_registry.py``).
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax import Settings, evaluate, write_outputs
from lantern_jax.core.constants import EGO_HALF_LENGTH
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios.suite import build_suite_scenarios, load_suite
from lantern_jax.scoring.table import metric_columns, read_route_table
from lantern_jax.scoring.thresholds import ScoringSettings
from lantern_jax.scoring.user_metrics import Metric
from lantern_jax.sensors.registry import (
    SENSOR_REGISTRY,
    normalize_sensors,
    register_sensor,
    view_sensor,
)
from lantern_jax.sensors.visibility import range_image
from lantern_jax.sim.engine import choose_path
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import rollout
from lantern_jax.sim.state import init_state
from lantern_jax.types.world import present

# --- user code: a rear range sensor and a policy that reads it ----------------------------------
REAR_RAYS = 8  # rays over the rear 60 degrees
REAR_FOV_DEG = 60.0


def rear_ranges(scenario, state):
    """(REAR_RAYS,) float32, m: distance to the first actor box or occluder behind the ego,
    from its rear bumper, capped at the scene's sensing range."""
    ego, actors, boxes = state.ego, state.actors, scenario.actors
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    rear = ego.xy - EGO_HALF_LENGTH * heading
    ranges, _ = range_image(
        rear, ego.yaw + jnp.pi, actors.xy, actors.yaw, boxes.extent, present(boxes, actors),
        REAR_FOV_DEG, REAR_RAYS, scenario.config.sensing_range, scenario.occluders,
    )  # fmt: skip
    return ranges


REAR_RANGE = view_sensor("rear_range", rear_ranges, description="rear range, 8 rays, 60 deg")


def act(params, carry, obs):
    """Follow the route; remember the closest thing ever seen behind."""
    closest = jnp.minimum(carry, jnp.min(obs.views["rear_range"]))
    return obs.route[:10], closest


def make_policy() -> Policy:
    return Policy("rear-aware", lambda key: {}, act, sensors=("rear_range",),
                  init_carry=lambda params: jnp.float32(jnp.inf))  # fmt: skip


# --- end of user code ---------------------------------------------------------------------------


@pytest.fixture
def registered():
    """The rear sensor registered for one test, then forgotten."""
    state = SENSOR_REGISTRY.snapshot()
    register_sensor(REAR_RANGE)
    yield
    SENSOR_REGISTRY.restore(state)


@pytest.fixture(scope="module")
def scene():
    return build_suite_scenarios(load_suite().select(["vc_0001"]))[0][0]


def test_a_registered_sensor_is_declared_and_observed(registered, scene):
    policy = make_policy()
    assert policy.sensors == ("front_camera", "rear_range")
    assert policy.user_sensors == (REAR_RANGE,) and not policy.privileged
    state = init_state(scene)
    obs = jax.jit(lambda s: observe(scene, s, policy.sensors))(state)
    np.testing.assert_array_equal(np.asarray(obs.views["rear_range"]),
                                  np.asarray(jax.jit(rear_ranges)(scene, state)))  # fmt: skip
    # a policy that does not declare it reads nothing of it
    assert jax.jit(lambda s: observe(scene, s))(state).views is None


def test_a_policy_reading_a_registered_sensor_drives_in_the_fused_program(registered, scene):
    policy = make_policy()
    choice = choose_path(policy, 360)
    assert choice.path == "fused" and "rear_range" in choice.reason
    final, _ = jax.jit(lambda: rollout(scene, policy, {}, 40))()
    closest = float(final.policy_carry)
    first = float(jnp.min(jax.jit(rear_ranges)(scene, init_state(scene))))  # the first tick's
    assert 0.0 < closest <= first <= float(scene.config.sensing_range)


def test_sensor_registration_rules(registered):
    assert register_sensor(REAR_RANGE) is REAR_RANGE  # the same sensor again: nothing new
    with pytest.raises(ValueError, match="already registered as another sensor"):
        register_sensor(view_sensor("rear_range", lambda sc, st: jnp.zeros(2)))
    with pytest.raises(ValueError, match="a built-in sensor"):
        register_sensor(view_sensor("warning", rear_ranges))
    with pytest.raises(TypeError, match="expected a Sensor"):
        register_sensor("rear_range")


def test_an_undeclared_or_forgotten_sensor_is_refused_naming_it():
    assert "rear_range" not in SENSOR_REGISTRY
    with pytest.raises(ValueError, match="unknown rear_range; known: front_camera"):
        normalize_sensors(("rear_range",))
    with pytest.raises(ValueError, match="rear_range"):
        make_policy()


# --- user code: two metrics ---------------------------------------------------------------------
HARDEST_BRAKE = Metric(
    name="hardest_brake_mps2",
    init=lambda settings: jnp.float32(jnp.inf),
    update=lambda low, sample, tick, settings: jnp.minimum(low, sample.ego_accel),
    value=lambda low, ctx, settings: low,
    unit="m/s^2",
    description="the lowest longitudinal acceleration applied in the execution",
)


def _completion(state, ctx, settings):
    furthest, length = state
    span = length - settings.completion_tol_m
    return jnp.clip(jnp.where(span > 0, furthest / jnp.where(span > 0, span, 1.0), 0.0), 0, 1)


COMPLETION = Metric(
    name="completion_again",
    init=lambda settings: (jnp.float32(0.0), jnp.float32(0.0)),
    update=lambda st, sample, tick, settings: (jnp.maximum(st[0], sample.progress),
                                               sample.route_length),
    value=_completion,
    description="route completion, from the furthest progress of the folded ticks",
)  # fmt: skip
# --- end of user code ---------------------------------------------------------------------------


def test_a_users_metric_is_a_route_table_column_in_the_schema_and_the_manifest(tmp_path):
    settings = Settings(scoring=ScoringSettings(metrics=(HARDEST_BRAKE, COMPLETION)))
    suite = load_suite().select(["pe_0001", "vc_0002"])
    # the split path: a world program of these settings, ``ego``'s small program beside it
    result = evaluate(["ego"], suite=suite, settings=settings, progress=False, path="split")
    table = result.route_table
    names = ["hardest_brake_mps2", "B_hardest_brake_mps2", "completion_again",
             "B_completion_again"]  # fmt: skip
    assert list(table.columns[-4:]) == names
    # the metric measured again what the benchmark measures: same rows, same routes
    np.testing.assert_allclose(table["completion_again"], table["A_progress"], atol=1e-6)
    np.testing.assert_allclose(table["B_completion_again"], table["B_progress"], atol=1e-6)
    assert (table["hardest_brake_mps2"] <= 0.0).all() and np.isfinite(table[names]).all().all()
    files = write_outputs(result, tmp_path / "out")
    schema = json.loads(files["route_level_results.schema.json"].read_text())
    described = {c["name"]: c for c in schema["columns"]}
    assert [c["name"] for c in schema["columns"][-4:]] == names
    assert described["hardest_brake_mps2"]["unit"] == "m/s^2"
    manifest = json.loads(files["reproducibility_manifest.json"].read_text())
    assert [m["name"] for m in manifest["settings"]["metrics"]] == names[::2]
    again = read_route_table(files["route_level_results.csv"])
    np.testing.assert_allclose(again[names].to_numpy(), table[names].to_numpy(), rtol=1e-12)


def _like(name: str) -> Metric:
    return Metric(name, HARDEST_BRAKE.init, HARDEST_BRAKE.update, HARDEST_BRAKE.value)


@pytest.mark.parametrize(
    ("metrics", "match"),
    [
        (("brake",), r"\[0\]: expected a Metric, got str"),
        ((HARDEST_BRAKE, HARDEST_BRAKE), r"\[1\]: hardest_brake_mps2: .* already exist"),
        ((_like("Hard Brake"),), r"\[0\]: name 'Hard Brake': 1-48 lower-case letters"),
        ((Metric("m", None, HARDEST_BRAKE.update, HARDEST_BRAKE.value),),
         r"\[0\]: m: init must be callable"),
    ],
)  # fmt: skip
def test_bad_metrics_are_refused_naming_the_setting(metrics, match):
    with pytest.raises(ValueError, match=r"ScoringSettings.metrics" + match):
        ScoringSettings(metrics=metrics).validate()


def test_a_metric_named_like_a_schema_column_is_refused():
    with pytest.raises(ValueError, match=r"\['ttc_min_s'\] are schema columns"):
        metric_columns(None, None, (_like("ttc_min_s"),))
