"""The policy interface (the registry of policies by name is :mod:`lantern_jax.policies.registry`).

A policy is a small record (:class:`Policy`): a name, ``init(key) -> params`` and an ``act``
function, the **sensors** it reads (the simulator builds its observation from those and from
nothing else; :mod:`lantern_jax.types.observation`) and, for a policy with memory, an initial carry.

Stateless (the default, as short as it can be)::

    Policy("brake-at-red", init, act)          # act(params, obs) -> (10, 2) waypoints

With memory (a frame history, a recurrent state, a counter)::

    Policy("mine", init, act, sensors=("warning",), init_carry=lambda params: jnp.zeros(()))
    # act(params, carry, obs) -> ((10, 2) waypoints, new carry)

``init``, ``act`` and ``init_carry`` must be jittable; ``act`` sees one scenario (no batch
axis) and the simulator vmaps it.  The carry is any pytree of arrays of fixed shapes; every
execution starts from ``init_carry(params)`` (also when a slot of the batched evaluation is
reused for the next execution), and an execution that has ended keeps its last carry.
Waypoints are 0.25 s apart in the ego frame (x forward, y right), metres.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.sensors.registry import Sensor, declared, normalize_sensors
from lantern_jax.types.observation import FRONT_CAMERA, SURROUND_RIG, WARNING, Observation

InitFn = Callable[[jax.Array], Any]
ActFn = Callable[..., Any]
CarryFn = Callable[[Any], Any]


@dataclasses.dataclass(frozen=True)
class Policy:
    """A named driving policy (see the module docstring).

    Attributes:
        name: the name its result rows carry.
        init: ``init(key) -> params`` (any pytree).
        act: ``act(params, obs) -> (10, 2)`` waypoints, or with ``init_carry``
            ``act(params, carry, obs) -> (waypoints, carry)``.
        description: one line, shown by ``lantern-jax policies``.
        sensors: the sensors it reads, names of the sensor table
            (:mod:`lantern_jax.sensors.registry`: the built-in ``"front_camera"``,
            ``"warning"``, ``"surround_rig"``, ``"privileged"`` and those registered from user
            code; ``"front_camera"`` is always included); stored sorted.
        init_carry: ``init_carry(params) -> carry`` for a policy with memory; ``None`` for a
            stateless one.
    """

    name: str
    init: InitFn
    act: ActFn
    description: str = ""
    sensors: tuple[str, ...] = (FRONT_CAMERA,)
    init_carry: CarryFn | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Policy.name: expected a non-empty string, got {self.name!r}")
        for field in ("init", "act"):
            if not callable(getattr(self, field)):
                raise TypeError(f"Policy {self.name!r}: {field} must be callable")
        if self.init_carry is not None and not callable(self.init_carry):
            raise TypeError(f"Policy {self.name!r}: init_carry must be callable or None")
        try:
            sensors = normalize_sensors(self.sensors)
        except ValueError as e:
            raise ValueError(f"Policy {self.name!r}: {e}") from None
        object.__setattr__(self, "sensors", sensors)

    @property
    def privileged(self) -> bool:
        """It reads ground truth (a reference-only sensor, the ``"privileged"`` one): an upper
        reference."""
        return any(s.reference_only for s in declared(self.sensors))

    @property
    def surround(self) -> bool:
        """It reads the six-camera rig."""
        return SURROUND_RIG in self.sensors

    @property
    def reads_warning(self) -> bool:
        """It receives the delivered warning text."""
        return WARNING in self.sensors

    @property
    def user_sensors(self) -> tuple[Sensor, ...]:
        """The sensors registered from user code that it declares (their entries)."""
        return tuple(s for s in declared(self.sensors) if not s.builtin)

    @property
    def stateful(self) -> bool:
        """It carries memory between ticks."""
        return self.init_carry is not None

    @property
    def program(self) -> tuple:
        """What its compiled rollout depends on besides the arguments: the act function, the
        sensors (with the entries of those registered from user code) and the carry's
        initialiser (policies equal here share a program)."""
        extra = self.user_sensors
        return (self.act, self.sensors, self.init_carry, *((extra,) if extra else ()))

    def initial_carry(self, params: Any) -> Any:
        """The carry every execution starts from (``()`` for a stateless policy)."""
        return () if self.init_carry is None else self.init_carry(params)

    def step(self, params: Any, carry: Any, obs: Observation) -> tuple[jax.Array, Any]:
        """``(waypoints, new carry)`` for one observation, whether or not the policy is
        stateful (a stateless one keeps the empty carry)."""
        if self.init_carry is None:
            return self.act(params, obs), carry
        return self.act(params, carry, obs)


def check_policy_output(policy: Policy, params: Any, obs: Observation) -> None:
    """Trace ``policy.act`` abstractly and check its output shape and dtype, and that a
    stateful policy returns a carry of the structure, shapes and dtypes it was given.

    Raises:
        ValueError: naming the policy and what was expected.
    """
    carry = jax.eval_shape(policy.initial_carry, params)
    out, new_carry = jax.eval_shape(policy.step, params, carry, obs)
    shape = getattr(out, "shape", None)
    if shape != (NUM_WAYPOINTS, 2) or not jnp.issubdtype(out.dtype, jnp.floating):
        raise ValueError(
            f"policy {policy.name!r} returned {shape} {getattr(out, 'dtype', type(out))}; "
            f"expected waypoints of shape ({NUM_WAYPOINTS}, 2) float (ego frame, x forward, "
            "y right, 0.25 s apart)"
        )
    if jax.tree.structure(carry) != jax.tree.structure(new_carry) or any(
        (a.shape, a.dtype) != (b.shape, b.dtype)
        for a, b in zip(jax.tree.leaves(carry), jax.tree.leaves(new_carry), strict=True)
    ):
        raise ValueError(
            f"policy {policy.name!r}: act returned a carry {jax.tree.map(_spec, new_carry)} "
            f"unlike the one it was given {jax.tree.map(_spec, carry)} (init_carry's structure, "
            "shapes and dtypes must be kept)"
        )


def _spec(x: Any) -> str:
    return f"{x.dtype}{list(x.shape)}"
