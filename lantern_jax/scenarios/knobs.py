"""Scenario knobs: named, differentiable handles on the float leaves of a built scenario.

A knob is a continuous quantity a user may sweep or differentiate — the hazard's speed, its
trigger delay, where it starts along its path, the size of its lateral manoeuvre, the scene
actor's speed and reveal deadline, the warning and event leads.  Scene geometry (road
curvature, junction shape, occluder set-back and size) is not a knob: it is built in NumPy
before the rollout and does not map onto a single leaf of the scenario.  Each knob reads and
writes leaves of the :class:`~lantern_jax.types.world.Scenario` pytree itself (its actor scripts and
execution config), so there is one source for every value, no parallel copy to keep in sync,
and a gradient with respect to a knob is an ordinary JAX gradient::

    def objective(speed):
        sc = set_knobs(scenario, hazard_speed=speed)
        final, _ = rollout(sc, policy, policy_params, num_ticks)
        return final.telemetry...

    jax.grad(objective)(jnp.float32(3.0))

Setting a knob that changes how an actor moves also refreshes that actor's state at ``t = 0``
from its script (:func:`lantern_jax.dynamics.actors.start_state`, float32), so the initial
conditions stay consistent with the script.  Knobs are pure functions (jittable, vmappable).

Which knobs a family exposes, and their ranges, belong to the family (scenario stress testing);
this module only defines what each knob means on any scenario.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from lantern_jax.dynamics.actors import start_state
from lantern_jax.scenarios.families_common import SCENE_SLOT
from lantern_jax.types.world import Scenario

Array = jax.Array


@dataclass(frozen=True)
class Knob:
    """A named continuous scenario quantity: how to read it and how to write it."""

    name: str
    unit: str
    doc: str
    get: Callable[[Scenario], Array]  # () float32
    set: Callable[[Scenario, Array], Scenario]
    shared: bool = False  # part of the scene both routes share (Route B gets it too)


def _slot_of(scenario: Scenario, slot: int | None) -> Array:
    return scenario.config.hazard_index if slot is None else jnp.asarray(slot, jnp.int32)


def _with_script(scenario: Scenario, slot: Array, **fields: Array) -> Scenario:
    """Write script fields of one slot and refresh that slot's initial state."""
    script = scenario.actors
    new = script.replace(
        **{k: getattr(script, k).at[slot].set(jnp.asarray(v, jnp.float32)) for k, v in
           fields.items()}
    )  # fmt: skip
    start = start_state(new)
    mask = jnp.arange(script.valid.shape[0]) == slot

    def keep_others(fresh, old):
        return jnp.where(mask.reshape(mask.shape + (1,) * (old.ndim - 1)), fresh, old)

    actors0 = jax.tree.map(keep_others, start, scenario.actors0)
    return scenario.replace(actors=new, actors0=actors0)


def _script_knob(name: str, field: str, unit: str, doc: str, slot: int | None = None) -> Knob:
    def get(sc: Scenario) -> Array:
        return getattr(sc.actors, field)[_slot_of(sc, slot)]

    def set_(sc: Scenario, value: Array) -> Scenario:
        return _with_script(sc, _slot_of(sc, slot), **{field: value})

    return Knob(name, unit, doc, get, set_, shared=slot is not None)


def _speed_knob(name: str, doc: str, slot: int | None) -> Knob:
    """Speed after the trigger, and before it too where the actor already moves then."""

    def get(sc: Scenario) -> Array:
        return sc.actors.v_post[_slot_of(sc, slot)]

    def set_(sc: Scenario, value: Array) -> Scenario:
        i = _slot_of(sc, slot)
        moving = sc.actors.v_pre[i] > 0.0
        v_pre = jnp.where(moving, value, sc.actors.v_pre[i])
        return _with_script(sc, i, v_post=value, v_pre=v_pre)

    return Knob(name, "m/s", doc, get, set_, shared=slot is not None)


def _lead_knob(name: str, marker: str, doc: str) -> Knob:
    def get(sc: Scenario) -> Array:
        return sc.config.s_conflict - getattr(sc.config, marker)

    def set_(sc: Scenario, value: Array) -> Scenario:
        arc = sc.config.s_conflict - jnp.asarray(value, jnp.float32)
        return sc.replace(config=sc.config.replace(**{marker: arc}))

    return Knob(name, "m", doc, get, set_, shared=True)


KNOBS: dict[str, Knob] = {
    k.name: k
    for k in (
        _speed_knob(
            "hazard_speed",
            "the hazard's scripted speed after its trigger (and before "
            "it, where it already moves then, e.g. the cut-in vehicle)",
            None,
        ),
        _script_knob(
            "hazard_delay",
            "trigger_delay",
            "s",
            "delay of the hazard's trigger after its source (the physical event)",
        ),
        _script_knob(
            "hazard_start",
            "s_init",
            "m",
            "where the hazard starts along its path (its arc at t = 0)",
        ),
        _script_knob(
            "hazard_lateral",
            "lat_shift",
            "m",
            "size of the hazard's lateral manoeuvre after its trigger (+ = left)",
        ),
        _script_knob(
            "hazard_manoeuvre",
            "lat_duration",
            "s",
            "duration of the hazard's lateral manoeuvre (the cut-in lane change)",
        ),
        _speed_knob(
            "scene_speed", "speed of the family's scene actor (the OR lead van)", SCENE_SLOT
        ),
        _script_knob(
            "scene_deadline",
            "trigger_deadline",
            "s",
            "latest trigger time of the scene actor: the OR van's own guard, the time "
            "at which it starts its lane change even if the event has not happened",
            SCENE_SLOT,
        ),
        _lead_knob("warn_lead", "s_warn", "warning point distance before the conflict point"),
        _lead_knob("event_lead", "s_event", "event point distance before the conflict point"),
    )  # fmt: skip
}


def knob(name: str) -> Knob:
    """The knob called ``name``.

    Raises:
        KeyError: listing the known knobs.
    """
    if name not in KNOBS:
        raise KeyError(f"unknown knob {name!r}; known knobs: {', '.join(KNOBS)}")
    return KNOBS[name]


def get_knobs(scenario: Scenario, names: tuple[str, ...] | list[str] | None = None) -> dict:
    """Current values of knobs (default: all), as () float32 arrays keyed by name."""
    return {n: knob(n).get(scenario) for n in (names or KNOBS)}


def apply_knobs(scenario_a: Scenario, scenario_b: Scenario, values: dict) -> tuple:
    """Set knobs on a matched pair: every knob on Route A, shared (scene, marker) knobs on Route
    B too, so the pair keeps sharing everything but the hazard behaviour.

    Returns:
        ``(scenario_a, scenario_b)``.
    """
    shared = {n: v for n, v in values.items() if knob(n).shared}
    return set_knobs(scenario_a, **values), set_knobs(scenario_b, **shared)


def set_knobs(scenario: Scenario, **values: Array) -> Scenario:
    """A copy of ``scenario`` with knobs set (differentiable in every value).

    Example:
        ``set_knobs(scenario, hazard_speed=2.5, warn_lead=20.0)``

    A scenario assembled on the host (NumPy leaves, :func:`~lantern_jax.scenarios.assemble.
    host_arrays`) is taken as JAX arrays first, so the knobs' indexed updates apply to it too.
    The writes run as one compiled program per set of knob names (:func:`_knob_setter`): a
    suite of pairs with knobs builds in about the time of one without, instead of a few hundred
    eager operations per pair.
    """
    if not values:
        return scenario
    names = tuple(values)
    for n in names:
        knob(n)  # an unknown name is refused here, before anything is traced
    return _knob_setter(names)(scenario, tuple(jnp.asarray(values[n], jnp.float32)
                                               for n in names))  # fmt: skip


@functools.cache
def _knob_setter(names: tuple[str, ...]) -> Callable:
    """``jit((scenario, values) -> scenario)`` writing the knobs ``names`` in order (one
    program per name set and scenario shape; inside a trace it is inlined, so gradients flow)."""

    def run(scenario: Scenario, values: tuple) -> Scenario:
        scenario = jax.tree.map(jnp.asarray, scenario)
        for name, value in zip(names, values, strict=True):
            scenario = knob(name).set(scenario, value)
        return scenario

    return jax.jit(run)
