"""Several policies in one compiled program: the policy is chosen by an index at run time.

Compiling the rollout for a policy compiles the whole simulator with it (sensing, actors,
protocol, telemetry), and on CPU that compilation costs more than running the suite.  Most of
the program does not depend on the policy, so evaluating several policies with one program
that holds all of them, and picks one by an index that is an ordinary (unbatched) argument,
compiles the simulator once instead of once per policy.

``act = policy_switch((act_0, act_1, ...))`` is an ``act`` function for
:func:`lantern_jax.sim.step.step` whose parameters are :class:`SwitchParams`: the index of the
member that drives and the parameters of every member (the others' only fix the program's
argument shapes).  The step builds the plain observation once, and only the chosen member's
branch of a ``lax.switch`` computes what that member alone needs: the privileged forecast
(``act.privileged``) or the six-camera rig (``act.surround``).  Under ``vmap`` the index is not
batched (every execution of a call runs the same member), so the switch stays a real branch and
the other members cost nothing at run time.

A switch is cached by its members (the same tuple of ``act`` functions gives the same switch
object), so every evaluation with the same members reuses one compiled program.  Results equal
those of the member's own program to float32 rounding: XLA fuses the branch's operations apart
from the rest of the tick, so the last bits of a few values can differ (the evaluation's
reproducibility promise, :data:`lantern_jax.scoring.table.REPRODUCIBLE_ATOL`, covers that).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.observation import Observation
from lantern_jax.sim.observe import privileged_view, surround_view
from lantern_jax.sim.state import State
from lantern_jax.world import Scenario

Array = jax.Array
ActFn = Callable[[Any, Observation], Array]


@struct.dataclass
class SwitchParams:
    """Parameters of a :class:`PolicySwitch` (build them with :func:`switch_params`).

    Every member's parameters are kept, as one pool of distinct leaves: members often share
    large frozen arrays (the learned models' 32k x 256 token-embedding table), and the pool
    holds each such array once, so the program's inputs do not grow with copies of it.
    """

    index: Array  # () int32, the member that drives (not batched)
    pool: tuple  # the distinct leaves of every member's parameters
    #: static: per member, its parameters' tree structure and its leaves' places in ``pool``
    layout: tuple = struct.field(pytree_node=False)

    def member(self, i: int) -> Any:
        """Member ``i``'s parameters, rebuilt from the pool."""
        treedef, places = self.layout[i]
        return jax.tree.unflatten(treedef, [self.pool[j] for j in places])


class PolicySwitch:
    """An ``act`` function made of several: see the module docstring.

    Attributes:
        members: the member ``act`` functions, in index order (distinct).
    """

    def __init__(self, members: tuple[ActFn, ...]) -> None:
        if len(members) < 2:
            raise ValueError(f"policy_switch: needs at least 2 members, got {len(members)}")
        if len(set(map(id, members))) != len(members):
            raise ValueError("policy_switch: members must be distinct act functions")
        self.members = tuple(members)
        #: Some member reads the privileged forecast (its plan is shielded as in its own
        #: program, see sim.step).
        self.any_privileged = any(bool(getattr(a, "privileged", False)) for a in members)

    def __call__(self, params: SwitchParams, obs: Observation) -> Array:
        raise TypeError(
            "a PolicySwitch is run by lantern_jax.sim.step.step (it needs the scenario and "
            "state to build each member's observation), not called on an observation"
        )

    def index_of(self, act: ActFn) -> int:
        """The member index of ``act``.

        Raises:
            ValueError: when ``act`` is not a member.
        """
        for i, a in enumerate(self.members):
            if a is act:
                return i
        raise ValueError(f"policy_switch: {act!r} is not a member of this switch")

    def choose(
        self, params: SwitchParams, obs: Observation, scenario: Scenario, state: State
    ) -> Array:
        """(10, 2) float32 waypoints of the member ``params.index`` for one execution.

        Args:
            params: :class:`SwitchParams`.
            obs: the plain observation of the tick (no forecast, no rig), shared by the members.
            scenario, state: the execution now; a branch builds from them what only its
                member reads.
        """

        def branch(member: ActFn, i: int):
            def run(pool: tuple) -> Array:
                o = obs
                if getattr(member, "privileged", False):
                    o = o.replace(privileged=privileged_view(scenario, state))
                if getattr(member, "surround", False):
                    o = o.replace(surround=surround_view(scenario, state))
                return jnp.asarray(member(params.replace(pool=pool).member(i), o), jnp.float32)

            return run

        branches = [branch(m, i) for i, m in enumerate(self.members)]
        return jax.lax.switch(params.index, branches, params.pool)


_SWITCHES: dict[tuple, PolicySwitch] = {}  # by the members themselves (functions hash by identity)


def policy_switch(members) -> PolicySwitch:
    """The :class:`PolicySwitch` of ``members`` (a sequence of distinct ``act`` functions),
    cached: the same members in the same order give the same object, hence one compiled
    program per process."""
    members = tuple(members)
    if members not in _SWITCHES:
        _SWITCHES[members] = PolicySwitch(members)
    return _SWITCHES[members]


#: bytes: leaves at least this large are compared by content when the pool is built (smaller
#: ones only by identity: hashing them would cost more than sharing saves).
SHARE_MIN_BYTES = 1 << 20


def _leaf_key(leaf: Any) -> tuple:
    """A key under which equal large arrays meet (content), other leaves by identity."""
    if getattr(leaf, "nbytes", 0) >= SHARE_MIN_BYTES:  # NumPy and JAX arrays (no host copy
        a = np.ascontiguousarray(leaf)  # of the small ones)
        return ("content", a.shape, str(a.dtype), hashlib.sha256(a.tobytes()).hexdigest())
    return ("id", id(leaf))


def switch_params(switch: PolicySwitch, index: int, members: tuple) -> SwitchParams:
    """:class:`SwitchParams` that run member ``index``.

    Args:
        switch: the :class:`PolicySwitch`.
        index: the member that drives.
        members: every member's parameters, in member order; equal large arrays among them
            (:data:`SHARE_MIN_BYTES`) are kept once.

    Raises:
        ValueError: for an index outside the members or a parameter set per member missing.
    """
    if not 0 <= index < len(switch.members):
        raise ValueError(f"switch_params.index: {index} not in [0, {len(switch.members)})")
    if len(members) != len(switch.members):
        raise ValueError(
            f"switch_params.members: {len(members)} parameter sets for "
            f"{len(switch.members)} members"
        )
    pool: list = []
    where: dict[tuple, int] = {}
    layout = []
    for m in members:
        leaves, treedef = jax.tree.flatten(m)
        places = []
        for leaf in leaves:
            key = _leaf_key(leaf)
            if key not in where:
                where[key] = len(pool)
                pool.append(leaf)
            places.append(where[key])
        layout.append((treedef, tuple(places)))
    return SwitchParams(index=jnp.asarray(index, jnp.int32), pool=tuple(pool), layout=tuple(layout))
