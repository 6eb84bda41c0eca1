"""Several policies in one compiled program: the policy is chosen by an index at run time.

Compiling the rollout for a policy compiles the whole simulator with it (sensing, actors,
protocol, telemetry), and on CPU that compilation costs more than running the suite.  Most of
the program does not depend on the policy, so evaluating several policies with one program
that holds all of them, and picks one by an index that is an ordinary (unbatched) argument,
compiles the simulator once instead of once per policy.

``switch = policy_switch((policy_0, policy_1, ...))`` drives :func:`lantern_jax.sim.step.step`
with parameters :class:`SwitchParams`: the index of the member that drives and the parameters
of every member (the others' only fix the program's argument shapes).  A member is a policy's
program (:attr:`~lantern_jax.policies.base.Policy.program`: act function, sensors, carry), so
policies that differ only in their parameters are one member.  The step builds the cameras'
observation once; a ``lax.switch`` over *branches* runs the chosen member's act function and
adds, in that branch only, what it alone reads: ground truth and forecasts (``"privileged"``)
or the six-camera rig (``"surround_rig"``).  Members whose act function, those sensors and
carry agree share a branch; whether the member receives the warning text is then a per-member
table entry (``ego`` and ``coop`` share one planner branch, ``coop`` with the text).  A stateful
member has a branch of its own; the switch's carry holds every branch's carry.  Under ``vmap``
the index is not batched (every execution of a call runs the same member), so the switch stays
a real branch and the other members cost nothing at run time.

Switches of the same members are one program (compiled programs are keyed by the members'
programs), so every evaluation with the same members reuses one compilation. Results equal those
of the member's own program to float32 rounding: XLA fuses the branch's operations apart from
the rest of the tick, so the last bits of a few values can differ (the evaluation's
reproducibility promise, :data:`lantern_jax.scoring.table.REPRODUCIBLE_ATOL`, covers that).
"""

from __future__ import annotations

import hashlib
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import REFERENCE_POLICIES, get_policy
from lantern_jax.scenarios.warnings import DEFAULT_BANK, TextBank
from lantern_jax.sensors.registry import declared
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import State
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import FRONT_CAMERA, WARNING
from lantern_jax.types.world import Scenario

Array = jax.Array


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


def _branch_key(policy: Policy, index: int) -> tuple:
    """Members with equal keys share a branch: same act function, same sensors apart from the
    warning, stateless (a stateful member gets a branch of its own)."""
    if policy.stateful:
        return ("stateful", index)
    others = tuple(x for x in policy.sensors if x != WARNING)
    return ("stateless", policy.act, others)


class PolicySwitch:
    """Several policies' programs as one driver: see the module docstring.

    Attributes:
        members: one representative :class:`~lantern_jax.policies.base.Policy` per member, in
            index order (distinct programs).
        branch_of: per member, the index of its branch.
        any_privileged: some member reads ground truth (its plan is shielded as in its own
            program, see :mod:`lantern_jax.sim.step`).
    """

    def __init__(self, members: tuple[Policy, ...]) -> None:
        if len(members) < 2:
            raise ValueError(f"policy_switch: needs at least 2 members, got {len(members)}")
        if len({m.program for m in members}) != len(members):
            raise ValueError("policy_switch: members must be distinct programs (Policy.program)")
        self.members = tuple(members)
        keys: dict[tuple, int] = {}
        self.branch_of = tuple(
            keys.setdefault(_branch_key(m, i), len(keys)) for i, m in enumerate(members)
        )
        self.num_branches = len(keys)
        #: per branch, its first member (whose act function and carry the branch runs)
        self.branch_lead = tuple(self.branch_of.index(b) for b in range(self.num_branches))
        self.any_privileged = any(m.privileged for m in members)
        self.any_warning = any(m.reads_warning for m in members)

    def index_of(self, policy: Policy) -> int:
        """The member index of ``policy`` (the member with its program).

        Raises:
            ValueError: when no member has its program.
        """
        for i, m in enumerate(self.members):
            if m.program == policy.program:
                return i
        raise ValueError(f"policy_switch: policy {policy.name!r} is not a member of this switch")

    def initial_carry(self, params: SwitchParams) -> tuple:
        """The switch's carry at the start of an execution: per branch, its member's initial
        carry (the driving member's from its own parameters)."""
        return tuple(
            self.members[lead].initial_carry(params.member(lead)) for lead in self.branch_lead
        )

    def choose(
        self,
        params: SwitchParams,
        carry: tuple,
        scenario: Scenario,
        state: State,
        bank: TextBank = DEFAULT_BANK,
    ) -> tuple[Array, tuple]:
        """Waypoints and new carry of the member ``params.index`` for one execution.

        Args:
            params: :class:`SwitchParams`.
            carry: the switch's carry (:meth:`initial_carry`).
            scenario, state: the execution now; the cameras' observation is built once, and a
                branch adds from them what only its members read.
            bank: the warning texts (``Settings.bank``; traced in a compiled program).

        Returns:
            ((10, 2) float32 waypoints, the new carry).
        """
        sensors = (WARNING,) if self.any_warning else ()
        obs = observe(scenario, state, sensors, bank)
        warned = jnp.asarray([m.reads_warning for m in self.members])[params.index]
        obs = obs.replace(
            warning_tokens=jnp.where(warned, obs.warning_tokens, PAD_ID),
            warning_values=jnp.where(warned, obs.warning_values, 0.0),
        )

        def branch(b: int):
            lead = self.members[self.branch_lead[b]]

            def run(operands):
                pool, carries = operands
                o = obs
                for sensor in declared(lead.sensors):  # the rig, ground truth, user sensors
                    if sensor.name not in (FRONT_CAMERA, WARNING):  # in ``obs`` already
                        o = sensor.add(o, scenario, state, bank)
                # every member of this branch has the lead's act and carry; the parameters are
                # those of the member that drives
                ps = params.replace(pool=pool)
                mine = [i for i, bi in enumerate(self.branch_of) if bi == b]
                if len({_signature(ps.member(i)) for i in mine}) == 1:
                    wp, c = lead.step(_select(ps, mine, params.index), carries[b], o)
                else:  # parameters of other shapes: one call per member
                    calls = [lambda i=i: lead.step(ps.member(i), carries[b], o) for i in mine]
                    local = jnp.argmax(jnp.asarray(mine) == params.index)
                    wp, c = jax.lax.switch(local, calls)
                out = tuple(c if k == b else carries[k] for k in range(self.num_branches))
                return jnp.asarray(wp, jnp.float32), out

            return run

        branches = [branch(b) for b in range(self.num_branches)]
        b_index = jnp.asarray(self.branch_of, jnp.int32)[params.index]
        return jax.lax.switch(b_index, branches, (params.pool, carry))


def _signature(tree: Any) -> tuple:
    """Tree structure, shapes and dtypes of a parameter tree."""
    leaves, treedef = jax.tree.flatten(tree)
    return treedef, tuple((tuple(jnp.shape(x)), str(jnp.result_type(x))) for x in leaves)


def _select(params: SwitchParams, mine: list[int], index: Array) -> Any:
    """The driving member's parameters among members ``mine`` of one branch (one parameter
    signature): leaf by leaf, a selection by the run-time ``index``; a leaf that every member
    shares (one pool entry) is taken as it is."""
    treedef, first = params.layout[mine[0]]
    leaves = []
    for k, place in enumerate(first):
        places = [params.layout[i][1][k] for i in mine]
        leaf = params.pool[place]
        if len(set(places)) > 1:
            for i, pl in zip(mine[1:], places[1:], strict=True):
                leaf = jnp.where(index == i, params.pool[pl], leaf)
        leaves.append(leaf)
    return jax.tree.unflatten(treedef, leaves)


def policy_switch(members) -> PolicySwitch:
    """The :class:`PolicySwitch` of ``members`` (policies of distinct programs).  Two switches
    of the same programs in the same order are the same program
    (:class:`lantern_jax.sim.engine.Program`), so they share one compilation."""
    return PolicySwitch(tuple(members))


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


def shared_program(pols: list[Policy], policy_params: list) -> tuple[PolicySwitch, tuple] | None:
    """One program for every policy of an evaluation, or ``None`` when they share one already.

    Policies with the same program (:attr:`~lantern_jax.policies.base.Policy.program`: act
    function, sensors, carry; e.g. two checkpoints of one architecture) already share a compiled
    program; policies with different ones are joined in a
    :class:`~lantern_jax.sim.switch.PolicySwitch`, so the simulator is compiled once for all of
    them.  When any of them is a reference policy (:data:`REFERENCE_POLICIES`), every reference
    policy is a member, first and in that order, and the others follow in order of first
    appearance: an evaluation of any reference policies (``coop`` alone, ``ego`` and ``coop``
    in either order, the default three) runs the one program the main command compiles, kept in
    the program store, and gives the same bits as that command's rows.  Returns ``(switch,
    members' parameters)`` for :func:`as_member` (each member's parameters those of its first
    policy, or the reference policy's own; they fix the program's argument shapes), or
    ``None`` for fewer than two distinct programs.
    """
    references = [get_policy(n) for n in REFERENCE_POLICIES]
    reference_programs = {r.program for r in references}
    members: dict[tuple, tuple] = {}
    if any(p.program in reference_programs for p in pols):
        for ref in references:
            members.setdefault(ref.program, (ref, ref.init(jax.random.PRNGKey(0))))
    for pol, par in zip(pols, policy_params, strict=True):
        if pol.program not in members:
            params = pol.init(jax.random.PRNGKey(0)) if par is None else par
            members[pol.program] = (pol, params)
    if len(members) < 2:
        return None
    reps, params = zip(*members.values(), strict=True)
    return policy_switch(reps), tuple(params)


def as_member(shared: tuple[PolicySwitch, tuple], policy: Policy,
              params: Any) -> tuple[PolicySwitch, SwitchParams]:  # fmt: skip
    """``(switch, switch parameters)`` that run ``policy`` with ``params`` as its member of a
    shared program (:func:`shared_program`'s ``(switch, members' parameters)``).

    Raises:
        ValueError: when ``policy`` is not a member.
    """
    switch, members = shared
    i = switch.index_of(policy)
    return switch, switch_params(switch, i, (*members[:i], params, *members[i + 1 :]))


def reference_driver(policy: Policy, params: Any) -> tuple[Any, Any]:
    """``(driver, parameters)`` to roll out one policy: a reference policy (or any policy of a
    reference policy's program) as its member of the reference switch (:func:`shared_program`,
    the program every evaluation of reference policies runs), any other policy as itself."""
    shared = shared_program([policy], [params])
    return (policy, params) if shared is None else as_member(shared, policy, params)
