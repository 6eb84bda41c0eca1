"""The world compiled apart from the policy: one world program shared by every policy, a small
program per policy, joined tick by tick from the host.

Compiling a fused rollout (:func:`lantern_jax.sim.engine.run_executions`) compiles the whole
world's tick -- sensing, actors, protocol, measurement, about 600 XLA kernels -- together with
the policy's ``act``, so a changed policy pays for compiling the world again (about 90 % of a
15-20 s compile on a 2-core CPU).  Here the two are separate programs:

* the **world program** (:func:`world_programs`) advances ``slots`` executions by one tick
  under given waypoints and returns their new states and the observations of the new tick (a
  slot marked inactive keeps its state and is only observed: that gives the first
  observations): every sensor's but the ground truth, which only a privileged policy reads and
  its own program computes from the state (:func:`policy_program`).  It depends only on the
  :class:`WorldSignature` (slot count, scenario shapes, the sensors observed, the static
  settings), never on the policy, and is kept in the program store: every policy -- and every
  later process -- reuses it.  The start states come from
  :data:`initial_states`, which the fused path shares;
* the **policy program** (:func:`policy_program`) is ``vmap(policy.step)`` over the slots'
  observations (with the ground-truth view computed there for a privileged policy): the only
  thing compiled for a new policy (1-2 s).

:func:`run_split` steps a batch from the host: every ``REFILL_TICKS`` ticks it reads the slots
back, stores the states of the executions that ended and gives their slots the next waiting
ones (the same slot scheduling as the fused program's, longest timeout first).  One worker
thread per CPU core steps its own slots (its own share of the executions, dealt before the run
so that every execution always runs in the same slot of the same worker: the results do not
depend on timing); on a GPU one worker steps 360 slots (:data:`SPLIT_LAYOUT_ACCELERATOR`).
States, scenarios and observations cross the program boundary packed
(:mod:`lantern_jax.sim.packing`), so a call costs microseconds, not one per leaf.

Results equal the fused rollout's to float32 rounding (the two programs are fused differently
by XLA), within :data:`lantern_jax.scoring.table.REPRODUCIBLE_ATOL`; bit-identical from run to
run.  The host loop costs a dispatch per program per tick, so the rollout itself is slower than
the fused one (``docs/performance.md`` gives the measured ratio); it pays where compiling the
fused program would cost more than it saves, which :func:`lantern_jax.sim.engine.choose_path`
decides.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import os
import threading
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core import jax_setup
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.io import program_store
from lantern_jax.policies.base import Policy
from lantern_jax.sim.observe import no_warning_fields, observe_every_sensor, privileged_view
from lantern_jax.sim.packing import Layout
from lantern_jax.sim.programs import executable
from lantern_jax.sim.settings import Settings
from lantern_jax.sim.state import State, init_state
from lantern_jax.sim.step import transition
from lantern_jax.types.observation import WARNING
from lantern_jax.types.world import Scenario

Array = jax.Array

#: Executions one worker steps together on the CPU.  On a 2-core CPU 48 stepped the suite
#: fastest of 24, 48 and 90 (``benchmarks/bench_iterate.py --slots``): the per-call overhead
#: favours many slots, the tail of long executions few.
SPLIT_SLOTS = 48
#: The split path's layout on a backend other than the CPU (a GPU): ``(worker threads, slots
#: each steps together)``.  One device there runs the calls of every thread one after another,
#: so one thread stepping the built-in suite's 360 executions at once wastes the least: on an
#: H200 the suite's split rollout took 1.55 / 1.61 s as 1 x 360, 2.11 / 2.34 s as 2 x 180 and
#: 5.67 / 6.12 s as one thread per core (8 x 48), the fused rollout 0.60 s (two interleaved
#: rounds, ``benchmarks/bench_split_workers.py``, ``benchmarks/results/gpu_h200.md``).
SPLIT_LAYOUT_ACCELERATOR = (1, 360)
#: ``jit(vmap(init_state))``: the executions' states at ``t = 0`` (ego, actors, the first
#: sensing, empty telemetry of the scoring settings' ring lengths).  It depends on neither the
#: policy nor the path, so every policy, ablation and rollout path of a batch shape reuses one
#: program (:func:`start_states`).
initial_states = jax.jit(jax.vmap(init_state, in_axes=(0, None, None)))
#: Ticks between two refills of ended slots (as the fused program's ``REFILL_TICKS``).
SPLIT_REFILL_TICKS = 20
#: Environment variable that sets the number of worker threads (default: one per core on the
#: CPU, :data:`SPLIT_LAYOUT_ACCELERATOR`'s elsewhere).
WORKERS_ENV = jax_setup.SPLIT_WORKERS_ENV


def _on_cpu(backend: str | None) -> bool:
    """Whether ``backend`` (default: JAX's default backend) is the CPU."""
    return (backend or jax.default_backend()) == "cpu"


def split_slots(backend: str | None = None) -> int:
    """Executions one worker steps together on ``backend`` (default: JAX's default backend):
    :data:`SPLIT_SLOTS` on the CPU, :data:`SPLIT_LAYOUT_ACCELERATOR`'s elsewhere.  The world
    program's shape has it, so one backend compiles one world program per batch shape."""
    return SPLIT_SLOTS if _on_cpu(backend) else SPLIT_LAYOUT_ACCELERATOR[1]


@dataclasses.dataclass(frozen=True)
class WorldSignature:
    """What a world program depends on besides this package's code: everything else is an
    argument.

    Attributes:
        slots: executions stepped per call.
        scenario, state, observation, privileged, settings: the packed layouts of one
            execution's scenario, state, observation (every sensor's fields but the ground
            truth, :func:`~lantern_jax.sim.observe.observe_every_sensor`), ground-truth view,
            and of the settings (:class:`~lantern_jax.sim.packing.Layout`).
    """

    slots: int
    scenario: Layout
    state: Layout
    observation: Layout  # without the ground truth (``privileged=None``)
    privileged: Layout  # the ground truth and forecasts (:class:`PrivilegedView`)
    settings: Layout

    def observations(self, slots: int, device: Any) -> tuple:
        """Zero packed observations (the world program's: no ground truth) of ``slots``
        executions."""
        return _blank(self.observation, slots, device)

    def identity(self) -> tuple:
        """The program store's identity of its programs (plain values only: the layouts are
        determined by the scenario's leaf shapes, the settings' structure and the code)."""
        shapes = tuple(leaf.shape for leaf in self.scenario.leaves)
        return ("world", self.slots, shapes, str(self.settings.treedef))


def world_signature(scenario: Scenario, settings: Settings, slots: int) -> WorldSignature:
    """The :class:`WorldSignature` of a batch's executions (``scenario``: one execution, or
    ShapeDtypeStructs of one); computed once per process for each scenario structure, settings
    structure and slot count (it traces the observation abstractly)."""
    one = jax.tree.map(lambda x: jax.ShapeDtypeStruct(np.shape(x), jnp.result_type(x)), scenario)
    leaves, treedef = jax.tree.flatten(one)
    key = (treedef, tuple((x.shape, str(x.dtype)) for x in leaves), jax.tree.structure(settings),
           slots)  # fmt: skip
    if key not in _SIGNATURES:
        _SIGNATURES[key] = _stored_signature(one, settings, slots)
    return _SIGNATURES[key]


def _stored_signature(one: Scenario, settings: Settings, slots: int) -> WorldSignature:
    """The signature kept in the program store by an earlier process (its abstract trace costs
    about 0.8 s on a 2-core CPU, a sixth of a new policy's first table), else computed and
    kept.  Its key names everything it depends on: the package's code and environment
    (:func:`lantern_jax.io.program_store.value_key`), the scenario's and settings' structures and
    leaf shapes, and the slot count; a stored one is also checked against the layouts computed
    here from ``one`` and ``settings``."""
    leaves, treedef = jax.tree.flatten(one)
    set_leaves, set_def = jax.tree.flatten(settings)
    key = program_store.value_key(
        "world signature", str(slots), str(treedef),
        repr([(x.shape, str(x.dtype)) for x in leaves]), str(set_def),
        repr([(np.shape(x), str(jnp.result_type(x))) for x in set_leaves]),
    )  # fmt: skip
    expected = (slots, Layout.of(one), Layout.of(settings))
    return program_store.kept(
        key, lambda: _new_signature(one, settings, slots),
        valid=lambda v: isinstance(v, WorldSignature)
        and (v.slots, v.scenario, v.settings) == expected,
    )  # fmt: skip


#: The signatures computed in this process (a few: one per batch structure and slot count).
_SIGNATURES: dict[tuple, WorldSignature] = {}


def _new_signature(one: Scenario, settings: Settings, slots: int) -> WorldSignature:
    on = jnp.asarray(True)
    state = jax.eval_shape(lambda sc: init_state(sc, (), settings.scoring), one)
    obs, view = jax.eval_shape(
        lambda sc: observe_every_sensor(sc, init_state(sc), on, on, settings.bank), one
    )
    return WorldSignature(slots, Layout.of(one), Layout.of(state), Layout.of(obs),
                          Layout.of(view), Layout.of(settings))  # fmt: skip


def sensor_switches(policy: Policy) -> np.ndarray:
    """(1,) bool: the world program observes the six-camera rig (the
    :func:`~lantern_jax.sim.observe.observe_every_sensor` switch of ``policy``'s sensors; the
    ground truth is the policy program's own, :func:`policy_program`)."""
    return np.asarray([policy.surround])


def _tick_one(sig: WorldSignature, scp: tuple, stp: tuple, waypoints: Array, active: Array,
              switches: Array, setp: tuple) -> tuple:  # fmt: skip
    """One execution's tick under ``waypoints`` (:func:`~lantern_jax.sim.step.transition`;
    a slot that is not ``active`` keeps its state), and the next tick's observation with the
    rig on where ``switches`` (:func:`sensor_switches`) say so.  The ground truth is not
    observed here: most policies do not read it, and writing its 3,300 numbers per execution
    every tick cost the split rollout about a tenth of its time on a 2-core CPU
    (``docs/performance.md``); a privileged policy's program computes it.

    Returns:
        (packed state, packed observation, () bool: the policy's carry is to be kept -- the
        execution has ended or its slot is idle).
    """
    # The barrier materialises the unpacked leaves once: without it XLA fuses each leaf's
    # slice of the packed buffer into every kernel that reads it (3-7 % slower per call on a
    # 2-core CPU, ``benchmarks/bench_split_tick.py``).
    sc, st, settings = jax.lax.optimization_barrier(
        (sig.scenario.unpack(scp), sig.state.unpack(stp), sig.settings.unpack(setp))
    )
    new, _ = transition(sc, st, waypoints, settings)
    new = jax.tree.map(lambda n, o: jnp.where(active, n, o), new, st)
    obs, _ = observe_every_sensor(sc, new, jnp.asarray(False), switches[0], settings.bank)
    return sig.state.pack(new), sig.observation.pack(obs), new.done | ~active


@dataclasses.dataclass(frozen=True)
class _Signed:
    """A world function as a static argument of ``jit``: equal by signature."""

    sig: WorldSignature


def _tick_batch(scp, stp, waypoints, active, switches, setp, *, signed):
    return jax.vmap(lambda a, b, w, m: _tick_one(signed.sig, a, b, w, m, switches, setp))(
        scp, stp, waypoints, active
    )


_tick_jit = jax.jit(_tick_batch, static_argnames=("signed",), donate_argnums=(1,))


def _blank(layout: Layout, slots: int, device: Any) -> tuple:
    """Zero buffers of ``slots`` items of a layout, on ``device``."""
    return tuple(jax.device_put(np.zeros((slots, size), dt), device) for dt, size in layout.groups)


@dataclasses.dataclass
class WorldPrograms:
    """The compiled world program of one :class:`WorldSignature`."""

    sig: WorldSignature
    #: (scenarios, states, waypoints, active, sensor switches, settings) -> (states,
    #: observations, keep carry), packed, ``slots`` executions; an inactive slot keeps its
    #: state and is observed as it is
    tick: Any


def world_programs(sig: WorldSignature, setp: tuple, device: Any, timings: dict | None = None,
                   stage: Callable[[str], None] | None = None) -> WorldPrograms:  # fmt: skip
    """The world program of ``sig`` on ``device``: from this process, the program store, or
    compiled (``setp``: the packed settings on ``device``; ``timings`` as
    :func:`~lantern_jax.sim.programs.executable` gives them)."""
    tick = executable(_tick_jit, *_tick_args(sig, setp, device), static=dict(signed=_Signed(sig)),
                      timings=timings, identity=(sig.identity(), "tick"), stage=stage)  # fmt: skip
    return WorldPrograms(sig, tick)


def _tick_args(sig: WorldSignature, setp: tuple, device: Any) -> tuple:
    """Example arguments of the world program (zeros of its shapes)."""
    s = sig.slots
    return (
        _blank(sig.scenario, s, device), _blank(sig.state, s, device),
        jax.device_put(np.zeros((s, NUM_WAYPOINTS, 2), np.float32), device),
        jax.device_put(np.zeros(s, bool), device), jax.device_put(np.zeros(1, bool), device),
        setp,
    )  # fmt: skip


def _take(tree: Any, idx: np.ndarray) -> Any:
    return jax.tree.map(lambda x: x[idx], tree)


def start_states(laid: Scenario, block: int, settings: Settings, timings: dict) -> Any:
    """The executions' states at ``t = 0`` (NumPy, leading axis ``n``), through
    :data:`initial_states` in blocks of ``block`` executions (one compiled shape whatever the
    batch size)."""
    n = len(jax.tree.leaves(laid)[0])
    exe = executable(
        initial_states, _take(laid, np.resize(np.arange(n), block)), (), settings.scoring,
        timings=timings, identity=("initial_states",),
    )  # fmt: skip
    parts = []
    for lo in range(0, n, block):
        rows = np.resize(np.arange(lo, min(lo + block, n)), block)
        out = jax.tree.map(np.asarray, exe(_take(laid, rows), (), settings.scoring))
        parts.append(_take(out, np.arange(min(block, n - lo))))
    return jax.tree.map(lambda *x: np.concatenate(x), *parts)


@dataclasses.dataclass(frozen=True)
class _PolicyStep:
    """A policy's per-slot step as a static argument of ``jit``: equal by the policy's program
    and the layouts it reads."""

    policy: Policy
    observation: Layout
    scenario: Layout
    state: Layout
    params: Layout
    carry: Layout

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _PolicyStep) and self.key() == other.key()

    def __hash__(self) -> int:
        return hash(self.key())

    def key(self) -> tuple:
        return (self.policy.program, self.observation, self.scenario, self.state, self.params,
                self.carry)  # fmt: skip


def _declared(policy: Policy, observation: Layout, op: tuple, truth: Callable[[], Any]) -> Any:
    """What ``policy`` observes of one execution's packed observation (the world program's):
    the sensors it did not declare dropped, and the ground truth ``truth()`` added for a
    privileged policy, as :func:`~lantern_jax.sim.observe.observe` would build it."""
    obs = observation.unpack(op)
    obs = obs.replace(privileged=truth() if policy.privileged else None,
                      surround=obs.surround if policy.surround else None)  # fmt: skip
    if WARNING not in policy.sensors:
        obs = obs.replace(**no_warning_fields())
    return obs


def declared_observation(policy: Policy, scenario: Scenario, settings: Settings,
                         slots: int | None = None) -> Any:  # fmt: skip
    """The shapes and dtypes (``ShapeDtypeStruct``) of the observation that ``policy``'s
    program is given on the split path, from the world signature of ``scenario`` (one
    execution, or ShapeDtypeStructs of one): the same structure as
    :func:`~lantern_jax.sim.observe.observe` of its sensors builds, without tracing the
    observation again (the signature is computed once per machine).  ``slots``: default
    :func:`split_slots`."""
    sig = world_signature(scenario, settings, slots or split_slots())
    op = tuple(jax.ShapeDtypeStruct((size,), jnp.dtype(dt)) for dt, size in sig.observation.groups)
    view = tuple(jax.ShapeDtypeStruct((size,), jnp.dtype(dt)) for dt, size in sig.privileged.groups)
    return jax.eval_shape(
        lambda o, v: _declared(policy, sig.observation, o, lambda: sig.privileged.unpack(v)),
        op, view,
    )  # fmt: skip


def _policy_batch(parp, carryp, obp, fresh, keep, world, *, step):
    """``vmap`` of one slot's policy step: the observation trimmed to the policy's own sensors,
    the carry reset where the slot took a new execution (``fresh``) and kept where the
    execution has ended (``keep``).  ``world``: for a privileged policy the packed scenarios and
    states of the slots, whose ground truth it observes
    (:func:`~lantern_jax.sensors.views.privileged_view`), else ``()``."""
    pol = step.policy
    params = step.params.unpack(parp)
    start = pol.initial_carry(params)

    def one(cp, op, f, k, w):
        def truth():
            return privileged_view(step.scenario.unpack(w[0]), step.state.unpack(w[1]))

        obs = _declared(pol, step.observation, op, truth)
        carry = jax.tree.map(lambda c0, c: jnp.where(f, c0, c), start, step.carry.unpack(cp))
        waypoints, new = pol.step(params, carry, obs)
        new = jax.tree.map(lambda n, c: jnp.where(k, c, n), new, carry)
        return jnp.asarray(waypoints, jnp.float32), step.carry.pack(new)

    return jax.vmap(one)(carryp, obp, fresh, keep, world)


_policy_jit = jax.jit(_policy_batch, static_argnames=("step",))


def policy_program(
    policy: Policy,
    params: Any,
    sig: WorldSignature,
    device: Any,
    timings: dict | None = None,
    stage: Callable[[str], None] | None = None,
) -> tuple[Any, tuple, Layout]:
    """The compiled per-slot step of ``policy`` for world ``sig`` and its packed parameters.

    Returns:
        (the program ``(params, carry, obs, fresh, keep, world) -> (waypoints, carry)``, the
        packed parameters on ``device``, the carry's layout), where ``world`` is
        :func:`ground_truth_inputs` of the slots' scenarios and states.
    """
    carry = jax.eval_shape(policy.initial_carry, params)
    step = _PolicyStep(policy, sig.observation, sig.scenario, sig.state, Layout.of(params),
                       Layout.of(carry))  # fmt: skip
    parp = tuple(jax.device_put(b, device) for b in _pack_one(step.params, params))
    s = sig.slots
    args = (
        parp, _blank(step.carry, s, device), sig.observations(s, device),
        jax.device_put(np.zeros(s, bool), device), jax.device_put(np.zeros(s, bool), device),
        ground_truth_inputs(policy, _blank(sig.scenario, s, device), _blank(sig.state, s, device)),
    )  # fmt: skip
    identity = ("policy-step", policy.program, sig.identity())
    exe = executable(_policy_jit, *args, static=dict(step=step), timings=timings,
                     identity=identity, stage=stage)  # fmt: skip
    return exe, parp, step.carry


def ground_truth_inputs(policy: Policy, scenarios: tuple, states: tuple) -> tuple:
    """The policy program's ``world`` argument: the slots' packed scenarios and states for a
    privileged policy (its program computes their ground truth), ``()`` for any other (nothing
    more crosses the boundary)."""
    return (scenarios, states) if policy.privileged else ()


def _pack_one(layout: Layout, tree: Any) -> tuple[np.ndarray, ...]:
    """One item (no batch axis) packed on the host."""
    return tuple(b[0] for b in layout.pack_host(jax.tree.map(lambda x: np.asarray(x)[None], tree)))


def worker_count(backend: str | None = None) -> int:
    """Worker threads of :func:`run_split`: ``$LANTERN_JAX_SPLIT_WORKERS``, else on the CPU one
    per core this process may run on, on another ``backend`` (default: JAX's default)
    :data:`SPLIT_LAYOUT_ACCELERATOR`'s.

    Raises:
        ValueError: naming the variable when it is not a whole number >= 1.
    """
    given = jax_setup.env_count(WORKERS_ENV)
    if given is not None:
        return given
    if not _on_cpu(backend):
        return SPLIT_LAYOUT_ACCELERATOR[0]
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def deal(timeout_s: np.ndarray, workers: int) -> list[np.ndarray]:
    """The executions of every worker, in the order it takes them: sorted by timeout, longest
    first (stable), dealt round-robin (as :func:`~lantern_jax.sim.engine.schedule_layout`)."""
    order = np.argsort(-np.asarray(timeout_s), kind="stable")
    return [order[w::workers] for w in range(workers)]


@dataclasses.dataclass
class _Run:
    """What every worker of one :func:`run_split` call shares (read-only but ``final``)."""

    world: WorldPrograms
    policy: Any
    params: tuple
    carry: Layout
    settings: tuple
    switches: Array  # (1,) bool, :func:`sensor_switches` of the policy, on the device
    truth: Callable[[tuple, tuple], tuple]  # :func:`ground_truth_inputs` of the policy
    scenarios: tuple  # (n, size) NumPy buffers
    starts: tuple  # (n, size) packed start states
    first_obs: tuple  # (n, size) packed first observations
    final: list  # (n, size) packed final states, written by the workers (disjoint rows)
    final_carry: list  # (n, size) packed final policy carries, written likewise
    max_ticks: int
    device: Any
    done: tuple  # (group, offset) of the state's ``done`` leaf
    tick: tuple  # (group, offset) of the state's ``tick`` leaf
    stop: threading.Event


def _field(layout: Layout, path: str) -> tuple[int, int]:
    leaf = layout.index_of(path)
    return leaf.group, leaf.offset


def _worker(run: _Run, mine: np.ndarray) -> int:
    """Step the executions ``mine`` (in order) through this worker's slots to their ends;
    writes their final states into ``run.final`` and their policy's final carries into
    ``run.final_carry``; returns the ticks stepped."""
    s, put = run.world.sig.slots, lambda x: jax.device_put(x, run.device)
    queue = list(mine)
    slot_of = np.full(s, -1)
    h_sc = [np.zeros((s, b.shape[1]), b.dtype) for b in run.scenarios]
    h_st = [np.zeros((s, b.shape[1]), b.dtype) for b in run.starts]
    h_ob = [np.zeros((s, b.shape[1]), b.dtype) for b in run.first_obs]
    fresh = np.zeros(s, bool)

    def fill(free) -> None:
        for k in free:
            if not queue:
                return
            i = queue.pop(0)
            slot_of[k], fresh[k] = i, True
            for dst, src in ((h_sc, run.scenarios), (h_st, run.starts), (h_ob, run.first_obs)):
                for a, b in zip(dst, src, strict=True):
                    a[k] = b[i]

    fill(range(s))
    carry = _blank(run.carry, s, run.device)
    no_fresh = put(np.zeros(s, bool))
    ticks = 0
    while (slot_of >= 0).any():
        if run.stop.is_set():
            return ticks
        active = slot_of >= 0
        d_sc, d_st, d_ob = (tuple(put(x) for x in h) for h in (h_sc, h_st, h_ob))
        d_active, keep = put(active), put(~active)
        d_fresh = put(fresh.copy())
        for k in range(SPLIT_REFILL_TICKS):
            waypoints, carry = run.policy(run.params, carry, d_ob, d_fresh if k == 0 else no_fresh,
                                          keep, run.truth(d_sc, d_st))  # fmt: skip
            d_st, d_ob, keep = run.world.tick(d_sc, d_st, waypoints, d_active, run.switches,
                                              run.settings)  # fmt: skip
        ticks += SPLIT_REFILL_TICKS
        h_st, h_ob = [np.array(x) for x in d_st], [np.array(x) for x in d_ob]
        fresh[:] = False
        ended = h_st[run.done[0]][:, run.done[1]].astype(bool)
        ended |= h_st[run.tick[0]][:, run.tick[1]] >= run.max_ticks
        free = np.flatnonzero(active & ended)
        # an ended execution's carry is kept until its slot takes the next one (``keep``)
        h_carry = [np.array(x) for x in carry] if len(free) else []
        for k in free:
            for f, x in zip(run.final, h_st, strict=True):
                f[slot_of[k]] = x[k]
            for f, x in zip(run.final_carry, h_carry, strict=True):
                f[slot_of[k]] = x[k]
            slot_of[k] = -1
        fill(free)
    return ticks


def run_split(
    policy: Policy,
    scenarios: Scenario,
    policy_params: Any,
    max_ticks: int,
    settings: Settings,
    timings: dict | None = None,
    stage: Callable[[str], None] | None = None,
    slots: int | None = None,
    workers: int | None = None,
) -> tuple[State, float]:
    """Roll out a batch with the world and the policy as two programs (module docstring).

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` (a policy switch is the fused
            program's; here every policy has its own small program).
        scenarios: (n, ...) batched scenarios.
        policy_params: the policy's parameters.
        max_ticks: horizon, ticks (an execution still ends at its own timeout).
        settings: scoring, protocol and text bank.
        timings: receives ``"trace + lower"``, ``"XLA compile"``, ``"program load"`` (world and
            policy programs together) and ``"rollout"`` seconds.
        stage: called with ``"compiling"`` (only when a program must be compiled) and
            ``"<n> executions"``, for a progress display.
        slots: executions per worker stepped together (default :func:`split_slots`).
        workers: worker threads (default :func:`worker_count`; at most one per ``slots``
            executions).

    Returns:
        (final states as NumPy arrays with leading axis ``n``, the policy's final carry in
        ``policy_carry`` as the fused path gives it; seconds spent compiling or loading
        programs).
    """
    host = jax.tree.map(np.asarray, scenarios)
    n = int(host.config.timeout_s.shape[0])
    slots = slots or split_slots()
    workers = max(1, min(worker_count() if workers is None else workers, -(-n // slots)))
    device = jax.local_devices()[0]
    one = jax.tree.map(lambda x: x[0], host)
    sig = world_signature(one, settings, slots)
    setp = tuple(jax.device_put(b, device) for b in _pack_one(sig.settings, settings))
    t0 = time.perf_counter()
    tw: dict[str, float] = {}
    tp: dict[str, float] = {}
    ts: dict[str, float] = {}
    with concurrent.futures.ThreadPoolExecutor(3) as pool:  # compiled or loaded at once
        fw = pool.submit(world_programs, sig, setp, device, tw, stage)
        fp = pool.submit(policy_program, policy, policy_params, sig, device, tp, stage)
        fs = pool.submit(start_states, host, slots, settings, ts)
        world, (pol_exe, parp, carry), start = fw.result(), fp.result(), fs.result()
    t_compile = time.perf_counter() - t0
    scp = sig.scenario.pack_host(host)
    starts = sig.state.pack_host(start)
    switches = jax.device_put(sensor_switches(policy), device)
    first_obs = _first_observations(world, scp, starts, switches, setp, device)
    run = _Run(
        world, pol_exe, parp, carry, setp, switches,
        lambda sc, st: ground_truth_inputs(policy, sc, st), scp, starts, first_obs,
        [b.copy() for b in starts], [np.zeros((n, size), dt) for dt, size in carry.groups],
        int(max_ticks), device, _field(sig.state, ".done"),
        _field(sig.state, ".tick"), threading.Event(),
    )  # fmt: skip
    if stage is not None:
        stage(f"{n} executions")
    t1 = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(workers) as pool:
        futures = [pool.submit(_worker, run, mine) for mine in deal(host.config.timeout_s, workers)]
        try:
            for f in futures:
                f.result()
        except BaseException:
            run.stop.set()
            raise
    final = sig.state.unpack_host(run.final).replace(
        policy_carry=carry.unpack_host(tuple(run.final_carry))
    )
    if timings is not None:
        for k in ("trace + lower", "XLA compile", "program load"):
            timings[k] = tw.get(k, 0.0) + tp.get(k, 0.0) + ts.get(k, 0.0)
        timings["rollout"] = time.perf_counter() - t1
    return final, t_compile


def prepare(policies: list[tuple[Policy, Any]], scenarios: Scenario, settings: Settings,
            slots: int | None = None) -> dict[str, float]:  # fmt: skip
    """Compile (or load) every program that :func:`run_split` needs for several policies on
    one batch: the world program, one program per policy and the start states' program, side
    by side in threads (a policy's tracing overlaps the world's compilation).  A later
    :func:`run_split` of each policy finds them in this process.

    Args:
        policies: ``(policy, parameters)`` pairs.
        scenarios: the batch (only its shapes matter).
        settings: as :func:`run_split` will be given them.
        slots: as :func:`run_split` will be given them (default :func:`split_slots`).

    Returns:
        Wall seconds of the whole preparation under ``"programs"``, and per policy name the
        seconds its own program took (overlapping the others).
    """
    host = jax.tree.map(np.asarray, scenarios)
    one = jax.tree.map(lambda x: x[0], host)
    slots = slots or split_slots()
    device = jax.local_devices()[0]
    setp = tuple(jax.device_put(b, device) for b in _pack_one(Layout.of(settings), settings))
    sig = world_signature(one, settings, slots)
    block = _take(host, np.arange(min(slots, host.config.timeout_s.shape[0])))  # shapes only
    out: dict[str, float] = {}

    def timed(name: str, fn, *args) -> None:
        t0 = time.perf_counter()
        fn(*args)
        out[name] = time.perf_counter() - t0

    t0 = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(max(2, worker_count())) as pool:
        jobs = [pool.submit(world_programs, sig, setp, device)]
        jobs.append(pool.submit(start_states, block, slots, settings, {}))
        jobs += [pool.submit(timed, p.name, policy_program, p, par, sig, device)
                 for p, par in policies]  # fmt: skip
        for job in jobs:
            job.result()
    out["programs"] = time.perf_counter() - t0
    return out


def _first_observations(world: WorldPrograms, scp: tuple, stp: tuple, switches: Array,
                        setp: tuple, device: Any) -> tuple:  # fmt: skip
    """Every execution's packed observation of its start state: the world program with every
    slot inactive (states kept, observed as they are), ``slots`` executions at a time."""
    s, n = world.sig.slots, scp[0].shape[0]
    idle = jax.device_put(np.zeros(s, bool), device)
    waypoints = jax.device_put(np.zeros((s, NUM_WAYPOINTS, 2), np.float32), device)
    parts = []
    for lo in range(0, n, s):
        rows = np.resize(np.arange(lo, min(lo + s, n)), s)
        put = [tuple(jax.device_put(b[rows], device) for b in x) for x in (scp, stp)]
        _, obs, _ = world.tick(put[0], put[1], waypoints, idle, switches, setp)
        parts.append([np.asarray(b)[: min(s, n - lo)] for b in obs])
    return tuple(np.concatenate(c) for c in zip(*parts, strict=True))
