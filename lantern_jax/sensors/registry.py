"""The sensor table: every sensor a policy may declare, the four built-in ones and those
registered from user code, as one :class:`Sensor` entry each.

A sensor is a name, what its reading is (the type of its view), and how that reading is joined
to one execution's observation at one tick (:attr:`Sensor.add`).  The simulator builds the
observation of every tick from the front camera (every policy's) and then, for each sensor the
policy declares, calls that sensor's ``add`` (:func:`lantern_jax.sim.observe.observe`, and each
branch of a policy switch, :meth:`lantern_jax.sim.switch.PolicySwitch.choose`); a policy reads
only what its declared sensors added.  :func:`normalize_sensors` checks a declaration against
this table, and a policy's sensor flags (``Policy.privileged``, ...) are read from it.

Built-in sensors (their readings: :mod:`lantern_jax.sensors.views`):

* ``"front_camera"`` — every policy's: the base observation (the route ahead, the ego state,
  its light and stop line, the actors the camera sees now, its range image);
* ``"warning"`` — the delivered warning, as its text (``warning_tokens``, ``warning_values``);
* ``"surround_rig"`` — the six-camera rig (``Observation.surround``); what it sees joins the
  actors;
* ``"privileged"`` — ground truth and forecasts (``Observation.privileged``); reference
  experts only (:attr:`Sensor.reference_only`).

A sensor of your own (a rear range sensor, a lidar, a V2X track list) is one
:func:`view_sensor` call: a name and a function ``(scenario, state) -> view`` (a pytree of
arrays for one execution), registered with :func:`register_sensor`; a policy that declares the
name reads the view as ``obs.views[name]``.  Such a sensor is observed in the fused rollout
program (the split path's world program observes the built-in sensors only, and a policy
declaring a registered sensor takes the fused path).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from lantern_jax.core.named_registry import NamedRegistry
from lantern_jax.sensors import views
from lantern_jax.types.observation import (
    FRONT_CAMERA,
    PRIVILEGED,
    SURROUND_RIG,
    WARNING,
    Observation,
    PrivilegedView,
    SurroundView,
)
from lantern_jax.types.world import Scenario

#: ``add(obs, scenario, state, bank) -> obs``: the observation of one execution with the
#: sensor's reading joined (``state``: the simulator's state at the start of the tick; ``bank``:
#: the warning texts, ``Settings.bank``, traced in a compiled program).
AddFn = Callable[[Observation, Scenario, Any, Any], Observation]


@dataclass(frozen=True)
class Sensor:
    """One sensor a policy may declare.

    Attributes:
        name: what a policy writes in ``Policy.sensors``.
        add: how its reading joins one execution's observation (:data:`AddFn`).
        view: the type of its reading (None: it fills the observation's own fields).
        description: one line for listings and errors.
        reference_only: it reads ground truth: a policy declaring it is an upper reference,
            never a submission (the ``"privileged"`` sensor).
        builtin: one of the four built-in sensors.
    """

    name: str
    add: AddFn
    view: Any = None
    description: str = ""
    reference_only: bool = False
    builtin: bool = False


class SensorRegistry(NamedRegistry[Sensor]):
    """The ordered table of :class:`Sensor` entries (the built-in four first)."""

    kind = "sensor"
    entry_type = Sensor

    def key_of(self, sensor: Sensor) -> str:
        return sensor.name

    def check(self, sensor: Sensor) -> None:
        """Refuse an empty name or an ``add`` that is not callable."""
        if not isinstance(sensor.name, str) or not sensor.name.strip():
            raise ValueError(f"sensor name: expected a non-empty string, got {sensor.name!r}")
        if not callable(sensor.add):
            raise ValueError(f"sensor {sensor.name!r}: add must be callable")

    def get(self, name: str) -> Sensor:
        """The entry of a sensor name.

        Raises:
            ValueError: naming the known sensors.
        """
        found = self.held(name)
        if found is None:
            raise ValueError(f"sensors: unknown {name}; known: {', '.join(self.keys())}")
        return found

    def names(self) -> tuple[str, ...]:
        """Every sensor name, in registration order (the built-in four first)."""
        return self.keys()


#: The table of every sensor the process knows.
SENSOR_REGISTRY = SensorRegistry()


def register_sensor(sensor: Sensor) -> Sensor:
    """Register a sensor of your own (see the module docstring and :func:`view_sensor`).

    Raises:
        ValueError: for a built-in name, or a name held by another sensor.
    """
    name = getattr(sensor, "name", None)
    if name in SENSOR_REGISTRY and SENSOR_REGISTRY.get(name).builtin:
        raise ValueError(f"sensor {name!r}: a built-in sensor")
    if getattr(sensor, "builtin", False):
        raise ValueError(f"sensor {name!r}: a registered sensor is not built in (builtin=False)")
    return SENSOR_REGISTRY.register(sensor)


def view_sensor(name: str, build: Callable[[Scenario, Any], Any], view: Any = None,
                description: str = "") -> Sensor:  # fmt: skip
    """A sensor whose reading is one view, delivered as ``obs.views[name]``.

    Args:
        name: the sensor's name.
        build: ``(scenario, state) -> view``, a pytree of arrays for one execution at the start
            of a tick (``state``: :class:`lantern_jax.sim.state.State`; ``state.ego``,
            ``state.actors``, ``state.t``); written for one scenario, ``vmap``-ed by the
            simulator, traced inside its compiled rollout.
        view: the type of the view, for listings (optional).
        description: one line for listings.
    """

    def add(obs: Observation, scenario: Scenario, state: Any, bank: Any) -> Observation:
        return obs.replace(views={**(obs.views or {}), name: build(scenario, state)})

    add.__qualname__ = f"view_sensor({name!r}).add"
    return Sensor(name, add, view, description)


def declared(sensors: Iterable[str]) -> tuple[Sensor, ...]:
    """The entries of a (normalised) sensor declaration."""
    return tuple(SENSOR_REGISTRY.get(n) for n in sensors)


def normalize_sensors(sensors: Any) -> tuple[str, ...]:
    """The canonical form of a sensor declaration: a sorted tuple of registered sensor names,
    always including :data:`~lantern_jax.types.observation.FRONT_CAMERA`.

    Raises:
        ValueError: naming an unknown sensor, or for a bare string (write ``("warning",)``).
    """
    known = SENSOR_REGISTRY.names()
    if isinstance(sensors, str):
        raise ValueError(
            f"sensors: expected a collection of sensor names, got the string {sensors!r} "
            f"(write ({sensors!r},)); known: {', '.join(known)}"
        )
    names = set(sensors) | {FRONT_CAMERA}
    unknown = sorted(str(n) for n in names if n not in SENSOR_REGISTRY)
    if unknown:
        raise ValueError(f"sensors: unknown {', '.join(unknown)}; known: {', '.join(known)}")
    return tuple(sorted(names))


# ------------------------------------------------------------------------------------------------
# the four built-in sensors
# ------------------------------------------------------------------------------------------------
def _front_camera(obs: Observation, scenario: Scenario, state: Any, bank: Any) -> Observation:
    """Every policy's camera: the base observation already is its reading."""
    return obs


def _warning(obs: Observation, scenario: Scenario, state: Any, bank: Any) -> Observation:
    """The delivered warning's text (:func:`~lantern_jax.sensors.views.warning_fields`)."""
    return obs.replace(**views.warning_fields(scenario, state, bank))


def _surround_rig(obs: Observation, scenario: Scenario, state: Any, bank: Any) -> Observation:
    """The six-camera rig's view; the actors it sees join those the front camera sees."""
    rig = views.surround_view(scenario, state)
    truth = views.actors_in_ego_frame(scenario, state)
    seen = obs.visible | rig.visible
    fields = {k: v for k, v in truth.items() if k != "present"}
    return obs.replace(surround=rig, visible=seen, **views.mask_actors(fields, seen))


def _privileged(obs: Observation, scenario: Scenario, state: Any, bank: Any) -> Observation:
    """Ground truth and forecasts (:func:`~lantern_jax.sensors.views.privileged_view`)."""
    return obs.replace(privileged=views.privileged_view(scenario, state))


BUILTIN_SENSORS = (
    Sensor(FRONT_CAMERA, _front_camera, None, "the 110 deg front camera (every policy's)",
           builtin=True),
    Sensor(SURROUND_RIG, _surround_rig, SurroundView, "the six-camera 360 deg rig",
           builtin=True),
    Sensor(WARNING, _warning, None, "the delivered warning, as its text", builtin=True),
    Sensor(PRIVILEGED, _privileged, PrivilegedView, "ground truth and 2-s forecasts "
           "(reference experts only)", reference_only=True, builtin=True),
)  # fmt: skip
for _sensor in BUILTIN_SENSORS:
    SENSOR_REGISTRY.register(_sensor)
