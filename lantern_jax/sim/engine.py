"""The batch engine: a suite's executions as one batch, stepped by one compiled program.

* :func:`build_executions` — every pair of a suite under Route A with warning, Route A without
  warning and Route B (``[A warning | A no-warning | B] x pairs``), optionally under a protocol
  ablation (:mod:`lantern_jax.scenarios.protocol_variants`);
* :func:`run_executions` — rolls a batch to its end through slots refilled inside the compiled
  program (:func:`~lantern_jax.sim.rollout.rollout_scheduled_parallel`), the batch dealt to
  every device; returns the final states;
* :func:`finalize_batch` — the hard per-execution metrics of final states.

Compiled programs are cached by what they depend on and nothing else: the policy's program
(:func:`program_identity`: act function, sensors, carry), the slot layout, the arguments'
shapes and dtypes, and the static part of the settings (they are an argument: a changed
threshold runs the same program with another value, a changed tick window or text bank compiles
another one).  The cache is bounded (:data:`MAX_PROGRAMS`), and kept on disk by the program store
(:mod:`lantern_jax.io.program_store`) for a later process.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from lantern_jax.core import family_codes, jax_setup
from lantern_jax.core.constants import BLOCKS, CONDITIONS, EXECUTIONS_PER_PAIR, FAMILIES, ROUTE_B
from lantern_jax.core.times import ticks_covering
from lantern_jax.io import program_store
from lantern_jax.scenarios.protocol_variants import get_ablation
from lantern_jax.scenarios.suite import Suite, build_suite_batches, load_suite
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.table import route_components
from lantern_jax.sim.distributed import placement
from lantern_jax.sim.programs import (  # noqa: F401  (MAX_PROGRAMS, remember: re-exported)
    MAX_PROGRAMS,
    executable,
    remember,
)
from lantern_jax.sim.rollout import rollout_scheduled_parallel, with_carry
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings, default_settings
from lantern_jax.sim.split import (  # noqa: F401  (initial_states: re-exported)
    initial_states,
    prepare,
    run_split,
    split_slots,
    start_states,
)
from lantern_jax.sim.step import Driver
from lantern_jax.sim.switch import PolicySwitch
from lantern_jax.types.world import Scenario, pad_rows, trim_padding

#: Slot scheduling of large batches (``compact``): each device steps a fixed number of slots
#: ``REFILL_TICKS`` ticks at a time, and a slot whose execution has ended takes the next
#: waiting one (longest timeout first) inside the same compiled loop
#: (:func:`~lantern_jax.sim.rollout.rollout_scheduled`), so that no slot idles behind a few
#: long executions.  Batches smaller than ``COMPACT_MIN_BATCH`` step every execution at once.
#: Slots per device by JAX backend (:func:`compact_slots`): on CPU (one device per core) 24
#: stepped the suite fastest of 16-64 per device (``benchmarks/bench_evaluate.py``).  A GPU
#: steps 4,096: a tick of the fused rollout on an H200 takes little longer for 4,096
#: executions than for 360 (0.69 against 0.43 ms, 16-actor scenes, ``bench_rollout.py``,
#: ``benchmarks/results/gpu_h200.md``), so few slots leave the card idle -- with the 96 kept
#: until 2026-12-04, 16,384 suite-like executions took 22.2 s there, stepped as about 171
#: waves of 96 slots.  The 4,096 is chosen from that throughput curve; the evaluations with
#: it have not been timed on a GPU (``benchmarks/gpu_benchmarks.sh``, step ``compact_slots``).
COMPACT_SLOTS = {"cpu": 24}
COMPACT_SLOTS_OTHER = 4096
#: Environment variable that sets the slots per device on any backend (a whole number >= 1),
#: for measuring them (``benchmarks/gpu_benchmarks.sh``) or fitting a card's memory.
COMPACT_SLOTS_ENV = jax_setup.COMPACT_SLOTS_ENV
REFILL_TICKS = 20
COMPACT_MIN_BATCH = 256


@dataclasses.dataclass
class Executions:
    """The batched executions of a suite: ``[A warning | A no-warning | B]`` x pairs (the
    blocks :data:`~lantern_jax.core.constants.BLOCKS`, each ``num_pairs`` long, in pair order).
    :meth:`block` and :meth:`take` read a block; nothing else needs the layout."""

    scenarios: Scenario  # leaves with leading axis EXECUTIONS_PER_PAIR * num_pairs
    num_pairs: int
    pair_ids: list[str]
    families: list[str]
    weathers: list[str]
    max_ticks: int
    #: run the batch padded to this many executions (:func:`batch_bucket`); None: as it is
    pad_to: int | None = None

    @property
    def num_executions(self) -> int:
        """Executions of the batch (``EXECUTIONS_PER_PAIR * num_pairs``, before any padding)."""
        return EXECUTIONS_PER_PAIR * self.num_pairs

    def block(self, name: str) -> slice:
        """Positions of block ``name`` (``"warning"``, ``"no-warning"`` or ``"route-b"``,
        :data:`~lantern_jax.core.constants.BLOCKS`) on the batch's leading axis.

        Raises:
            ValueError: for a name not in ``BLOCKS``.
        """
        if name not in BLOCKS:
            raise ValueError(f"block: {name!r} is not one of {', '.join(BLOCKS)}")
        i = BLOCKS.index(name)
        return slice(i * self.num_pairs, (i + 1) * self.num_pairs)

    def take(self, tree: Any, name: str) -> Any:
        """Block ``name`` of a tree whose leaves have the batch's leading axis (the scenarios,
        final states, metrics, ...): leaves of leading axis ``num_pairs``, in pair order."""
        sl = self.block(name)
        return jax.tree.map(lambda x: x[sl], tree)


#: Executions built in this process, by suite content and options (a few suites: bounded).
_BUILT_EXECUTIONS: collections.OrderedDict[tuple, Executions] = collections.OrderedDict()
MAX_BUILT_EXECUTIONS = 4


def build_executions(
    suite: Suite, ablation: str = "none", trim: bool = True, bucket: bool = False
) -> Executions:
    """:func:`build_new_executions`, once per suite content (every pair's id, hash, family and
    weather), ablation and options in this process: a second evaluation of the same suite
    (another policy, in a notebook) builds nothing."""
    key = (tuple((p.pair_id, p.sha256, p.family, p.weather) for p in suite.pairs), ablation,
           trim, bucket, tuple(family_codes.codes()))  # fmt: skip
    if key in _BUILT_EXECUTIONS:
        _BUILT_EXECUTIONS.move_to_end(key)
        return _BUILT_EXECUTIONS[key]
    # Built from the package's own families only, the batch is a function of the package's code
    # and the key: kept in the program store for later processes (1.5 s for the built-in suite
    # on a 2-core CPU, a fifth of a new policy's whole-suite table).  A family registered from
    # outside the package (its code not covered by the store's key) is always built.
    stored = (program_store.value_key("executions", repr(key),
                                      repr([repr(p.params) for p in suite.pairs]))
              if all(p.family in FAMILIES for p in suite.pairs) else None)  # fmt: skip
    execs = program_store.kept(stored, lambda: build_new_executions(suite, ablation, trim, bucket),
                               valid=lambda v: isinstance(v, Executions))  # fmt: skip
    _BUILT_EXECUTIONS[key] = execs
    while len(_BUILT_EXECUTIONS) > MAX_BUILT_EXECUTIONS:
        _BUILT_EXECUTIONS.popitem(last=False)
    return execs


def build_new_executions(
    suite: Suite, ablation: str = "none", trim: bool = True, bucket: bool = False
) -> Executions:
    """Build the batched scenarios of every execution of a suite under an ablation.

    With ``trim`` (default) the actor and lane slots past the last one any execution uses are
    cut (:func:`~lantern_jax.types.world.trim_padding`: narrower per-tick work, same results to the
    reproducibility promise); ``trim=False`` keeps the full slot capacity, one batch shape for
    every suite of the same size.  With ``bucket`` a batch that fits in the built-in suite's
    shape takes it (:func:`batch_bucket`): slots are kept to its widths and
    :attr:`Executions.pad_to` says how many executions to run.

    Raises:
        ValueError: listing the valid ablations for an unknown name.
    """
    fn = get_ablation(ablation).apply
    a, b = build_suite_batches(suite)
    on, off = np.ones_like(a.config.is_route_a), np.zeros_like(a.config.is_route_a)
    a_warn = a.replace(config=a.config.replace(warning_enabled=on))
    a_none = a.replace(config=a.config.replace(warning_enabled=off))
    if fn is not None:
        a_warn = a_warn.replace(config=fn(a_warn.config))
        a_none = a_none.replace(config=fn(a_none.config))
    scenarios = jax.tree.map(lambda *x: np.concatenate(x), a_warn, a_none, b)
    pad_to = None
    if trim:
        scenarios = trim_padding(scenarios)
    if trim and bucket:
        pad_to, *widths = batch_bucket(batch_shape(scenarios))
        scenarios = trim_padding(jax.tree.map(lambda *x: np.concatenate(x), a_warn, a_none, b),
                                 at_least=tuple(widths))  # fmt: skip
    scenarios = jax.device_put(scenarios)
    max_ticks = ticks_covering(float(np.max(np.asarray(scenarios.config.timeout_s))))
    assert len(CONDITIONS) == 2  # the batch layout above holds one block per condition
    return Executions(
        scenarios=scenarios,
        num_pairs=len(suite.pairs),
        pair_ids=[p.pair_id for p in suite.pairs],
        families=[p.family for p in suite.pairs],
        weathers=[p.weather for p in suite.pairs],
        max_ticks=max_ticks,
        pad_to=pad_to,
    )


#: Batch shape (executions, actor slots, lane slots) of the built-in suite ``lantern-v3``
#: (``3 x 120`` executions; 10 of 16 actor slots and 9 of 16 lane slots used), to which
#: :func:`batch_bucket` pads a smaller batch that fits: a subset evaluated before or after the
#: suite runs the suite's program (checked against the suite in ``tests/test_evaluate.py``).
SUITE_BATCH_SHAPE = (360, 10, 9)


def batch_shape(scenarios: Scenario) -> tuple[int, int, int]:
    """(executions, actor slots, lane slots) of a batch of scenarios."""
    return (int(np.shape(scenarios.actors.valid)[0]), int(np.shape(scenarios.actors.valid)[-1]),
            int(np.shape(scenarios.lanes.valid)[-1]))  # fmt: skip


def batch_bucket(shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """The shape to run a batch of ``shape`` (executions, actor slots, lane slots) at, so that
    batches of different sizes share a compiled program where padding can make them: the
    built-in suite's (:data:`SUITE_BATCH_SHAPE`) when it holds the batch, else the batch's own.

    The choice depends on the batch alone, never on what the process compiled before, so an
    evaluation runs the same program (and gives the same bits) in any process.  Padding changes
    no result beyond float rounding: extra slots are inert, extra executions start ended and
    are never stepped (:func:`run_executions`' ``pad_to``).
    """
    holds = all(a >= b for a, b in zip(SUITE_BATCH_SHAPE, shape, strict=True))
    return SUITE_BATCH_SHAPE if holds else tuple(shape)


def compact_slots(backend: str | None = None) -> int:
    """Slots per device of the slot scheduling on ``backend`` (default: JAX's default):
    ``$LANTERN_JAX_COMPACT_SLOTS`` if set, else :data:`COMPACT_SLOTS`'s entry for the backend,
    else :data:`COMPACT_SLOTS_OTHER`.  The slots are part of the program's identity, so a
    changed value compiles its own program; results agree to float rounding.

    Raises:
        ValueError: naming the variable when it is not a whole number >= 1.
    """
    given = jax_setup.env_count(COMPACT_SLOTS_ENV)
    if given is not None:
        return given
    return COMPACT_SLOTS.get(backend or jax.default_backend(), COMPACT_SLOTS_OTHER)


def program_identity(policy: Driver) -> tuple:
    """What a rollout program of ``policy`` depends on besides its arguments: the policy's
    program (:attr:`~lantern_jax.policies.base.Policy.program`) or a switch's members'."""
    if isinstance(policy, PolicySwitch):
        return ("switch", tuple(m.program for m in policy.members))
    return ("policy", policy.program)


class Program:
    """A driver (policy or policy switch) as a static argument of ``jit``: equal, and hashing
    equal, by its program (:func:`program_identity`), so policies that differ only in their
    parameters share one compilation."""

    def __init__(self, driver: Driver) -> None:
        self.driver = driver
        self.identity = program_identity(driver)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Program) and other.identity == self.identity

    def __hash__(self) -> int:
        return hash(self.identity)


@functools.partial(jax.jit, static_argnames=("program", "slots", "chunk"))
def _scheduled(scenarios, policy_params, starts, max_ticks, settings, *, program, slots, chunk):
    """Every execution of the batch from its start state to its end (see
    :func:`~lantern_jax.sim.rollout.rollout_scheduled_parallel`)."""
    return rollout_scheduled_parallel(
        scenarios, starts, program.driver, policy_params, max_ticks, slots, chunk, settings
    )


#: :func:`~lantern_jax.scoring.metrics.finalize` of a batch as one compiled program (op by op,
#: its first call compiled each operation on its own: about a second).
_finalize = jax.jit(finalize)

def _take(tree, idx):
    return jax.tree.map(lambda x: x[idx], tree)


def schedule_layout(timeout_s: np.ndarray, devices: int) -> np.ndarray:
    """The order in which the devices' schedulers take a batch's executions.

    Executions sorted by timeout, longest first (stable), are dealt round-robin to the
    devices, so every device gets a similar mix of long and short ones and starts with its
    longest; the batch is padded to a multiple of ``devices`` with copies of the shortest.

    Args:
        timeout_s: (n,) float, s, every execution's timeout.
        devices: number of devices (blocks).

    Returns:
        (devices * ceil(n / devices),) int: execution index at each position of the
        device-major layout (device ``d`` holds the ``d``-th block).
    """
    order = np.argsort(-np.asarray(timeout_s), kind="stable")
    per_device = -(-len(order) // devices)
    order = np.concatenate([order, np.repeat(order[-1:], per_device * devices - len(order))])
    return order.reshape(per_device, devices).T.reshape(-1)


#: How a batch is rolled out (:func:`run_executions`' ``path``): ``"fused"`` -- world and
#: policy in one compiled program; ``"split"`` -- the world program shared by every policy and
#: the policy's own small program, joined tick by tick (:mod:`lantern_jax.sim.split`);
#: ``"auto"`` -- :func:`choose_path`.
PATHS = ("auto", "fused", "split")
#: Above this many executions ``"auto"`` takes the fused program even when it must be
#: compiled: the split rollout's extra time per execution then exceeds the compile it saves
#: (about 15 s of compile against 6 ms per execution on a 2-core CPU,
#: ``benchmarks/bench_iterate.py``).
SPLIT_MAX_EXECUTIONS = 2400


@dataclasses.dataclass(frozen=True)
class PathChoice:
    """Which rollout :func:`run_executions` takes, and why (shown in the progress line and
    kept in the run record)."""

    path: str  # "fused" or "split"
    reason: str  # one line, e.g. "fused program not compiled; world program stored"

    def __str__(self) -> str:
        return f"{self.path} ({self.reason})"


def split_possible(policy: Driver) -> str:
    """Why the split path cannot run ``policy`` here ("" when it can)."""
    if isinstance(policy, PolicySwitch):
        return "a policy switch is one fused program"
    if policy.user_sensors:
        names = ", ".join(s.name for s in policy.user_sensors)
        return f"a sensor registered from user code ({names}) is observed in the fused program"
    if jax.process_count() > 1:
        return "several processes (the split path steps one process's devices)"
    return ""


def fused_kept(policy: Driver) -> bool:
    """Whether a fused program of ``policy`` can be kept between runs: its code is this
    package's (or of a library whose version keys the store), so the program store can describe
    it with certainty (:func:`lantern_jax.io.program_store.describable`).  A policy defined outside
    (a file being written, a notebook cell) cannot."""
    return program_store.describable(("rollout", program_identity(policy)))


def choose_path(policy: Driver, n: int, requested: str = "auto") -> PathChoice:
    """The rollout :func:`run_executions` takes for ``n`` executions of ``policy``.

    ``"auto"`` depends on the policy and the batch only -- never on the backend or on what is
    compiled or cached -- so the same run gives the same bits whatever ran before it:

    * the fused program when the split path cannot run the driver (:func:`split_possible`), for
      a bulk batch (over :data:`SPLIT_MAX_EXECUTIONS`: the split rollout's extra time exceeds the
      compile), or for a policy whose fused program is kept between runs (:func:`fused_kept`:
      the package's own policies, compiled once per machine);
    * else the split path: a policy defined outside the package -- the one being written --
      compiles only its own program beside the world program, which is compiled once and kept.
      This holds on a GPU too: there a tick of the split path costs more than on the CPU
      relative to the fused loop (the suite's split rollout 3.0 s with one worker per core,
      1.6 s with the GPU's layout, against 0.49-0.60 s fused on an H200), but the fused compile
      it saves costs more still (8 s; a new policy's whole-suite table 7.1 s split against
      12.0 s fused with the world program stored, ``benchmarks/results/gpu_h200.md``).

    Raises:
        ValueError: for a path not in :data:`PATHS`, or ``"split"`` where it cannot run.
    """
    if requested not in PATHS:
        raise ValueError(f"path: {requested!r} is not one of {', '.join(PATHS)}")
    why_not = split_possible(policy)
    if requested == "split":
        if why_not:
            raise ValueError(f"path 'split': not possible here: {why_not}")
        return PathChoice("split", "asked for")
    if requested == "fused":
        return PathChoice("fused", "asked for")
    if why_not:
        return PathChoice("fused", why_not)
    if n > SPLIT_MAX_EXECUTIONS:
        return PathChoice("fused", f"bulk batch of {n} executions")
    if fused_kept(policy):
        return PathChoice("fused", "the package's policy: its fused program is compiled once "
                          "and kept")  # fmt: skip
    return PathChoice("split", "a policy from outside the package: only its own program is "
                      "compiled, beside the world program")  # fmt: skip


def run_executions(
    policy: Driver,
    scenarios: Scenario,
    policy_params: Any,
    max_ticks: int,
    settings: Settings | None = None,
    compact: bool | None = None,
    timings: dict | None = None,
    pad_to: int | None = None,
    stage: Callable[[str], None] | None = None,
    path: str | PathChoice = "fused",
    chosen: list | None = None,
):
    """Roll out a batch of executions until all have ended; returns (final states, seconds
    spent compiling).

    With ``path="fused"`` (default) one compiled program does all the stepping, in one call.  A
    small batch steps every execution at once; a large one (``compact``, see ``COMPACT_*`` and
    :func:`compact_slots`) is stepped through a fixed number of slots per device, refilled
    inside the program with the waiting executions as earlier ones end (:func:`schedule_layout`
    deals them to the devices): the same executions, only grouped differently.  Every execution
    starts from its state at ``t = 0`` given by :data:`initial_states` and the policy's initial
    carry.  Under JAX's distributed runtime (several processes) the call runs on the global
    mesh, each process stepping its devices' blocks, and the final states are gathered on every
    process (:mod:`lantern_jax.sim.distributed`).  With ``path="split"`` the world program and
    the policy's program are joined from the host (:func:`lantern_jax.sim.split.run_split`;
    ``compact`` and ``pad_to`` do not apply); ``"auto"`` chooses (:func:`choose_path`).

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` or a
            :class:`~lantern_jax.sim.switch.PolicySwitch`.
        scenarios: (n, ...) batched scenarios.
        policy_params: the policy's parameters.
        max_ticks: horizon, ticks.
        settings: scoring, protocol and text bank (an argument of the compiled program; default
            :func:`~lantern_jax.sim.settings.default_settings`, the paper's values with every
            registered family's texts).
        compact: step through refilled slots (default: for batches of at least
            ``COMPACT_MIN_BATCH``).
        timings: receives ``"trace + lower"``, ``"XLA compile"`` and ``"rollout"`` seconds.
        pad_to: pad the batch to that many executions with copies of the first that start
            ended (never stepped, last in every device's queue), so that batches of different
            sizes share one compiled program at little cost.
        stage: called with what the call does next, for a progress display: ``"compiling"``
            (only when a program must be compiled) and ``"<n> executions"``.
        path: ``"fused"``, ``"split"`` or ``"auto"`` (:data:`PATHS`, :func:`choose_path`), or
            a :class:`PathChoice` made beforehand.
        chosen: if given, receives the :class:`PathChoice` taken (appended).

    Raises:
        ValueError: when ``pad_to`` is smaller than the batch, the settings' bank lacks a
            text the executions read, or ``path`` is unknown or impossible here.

    Returns:
        (final states as NumPy arrays with leading axis ``n``, seconds spent compiling).
    """
    settings = default_settings() if settings is None else settings
    check_texts(settings, scenarios)
    n = jax.tree.leaves(scenarios)[0].shape[0]
    total = n if pad_to is None else pad_to
    if total < n:
        raise ValueError(f"run_executions: pad_to={pad_to} is smaller than the batch ({n})")
    fused = _FusedCall(policy, scenarios, policy_params, max_ticks, settings, compact, total)
    if isinstance(path, PathChoice):
        choice = path
    else:
        choice = choose_path(policy, n, path)
    if chosen is not None:
        chosen.append(choice)
    if choice.path == "split":
        return run_split(policy, scenarios, policy_params, max_ticks, settings, timings, stage)
    return fused.run(timings, stage)


class _FusedCall:
    """The fused program's call for one batch: its arguments, whether it is ready, its run."""

    def __init__(self, policy, scenarios, policy_params, max_ticks, settings, compact, total):
        n = jax.tree.leaves(scenarios)[0].shape[0]
        if compact is None:
            compact = total >= COMPACT_MIN_BATCH and max_ticks > REFILL_TICKS
        self.policy, self.params, self.settings = policy, policy_params, settings
        self.n, self.total, self.max_ticks = n, total, max_ticks
        self.place = placement()
        devices = jax.device_count()
        host = jax.tree.map(np.asarray, scenarios)
        if total > n:  # padding: copies of the first execution, queued after every real one
            host = _take(host, np.concatenate([np.arange(n), np.zeros(total - n, int)]))
        timeout = np.where(np.arange(total) < n, host.config.timeout_s, -np.inf)
        self.layout = schedule_layout(timeout, devices)
        per_device = len(self.layout) // devices
        self.slots = min(per_device, compact_slots()) if compact else per_device
        self.laid = _take(host, self.layout)
        self.static = dict(program=Program(policy), slots=self.slots, chunk=REFILL_TICKS)
        self.identity = ("rollout", program_identity(policy), self.slots, REFILL_TICKS)

    def _args(self, starts) -> tuple:
        place = self.place
        return (
            place.put(self.laid), place.replicate(self.params), place.put(starts),
            place.replicate(np.int32(self.max_ticks)), place.replicate(self.settings),
        )  # fmt: skip

    def run(self, timings: dict | None, stage: Callable[[str], None] | None):
        """Roll the batch out through the fused program; (final states, compile seconds)."""
        n, total, layout, devices = self.n, self.total, self.layout, jax.device_count()
        t0 = time.perf_counter()
        init_timings: dict[str, float] = {}
        starts = start_states(self.laid, min(len(layout), self.slots * devices), self.settings,
                               init_timings)  # fmt: skip
        t_compile = time.perf_counter() - t0
        starts = starts.replace(done=starts.done | (layout >= n))  # padding starts ended
        starts = jax.tree.map(np.asarray, with_carry(starts, self.policy, self.params))
        args = self._args(starts)
        t1 = time.perf_counter()
        exe = executable(_scheduled, *args, static=self.static, timings=timings,
                         identity=self.identity, stage=stage)  # fmt: skip
        t_compile += time.perf_counter() - t1
        if timings is not None:
            for k, v in init_timings.items():
                timings[k] += v
        self.place.align("rollout program ready")  # every process holds it before any runs it
        if stage is not None:
            stage(f"{n} executions")
        final = jax.tree.map(np.asarray, self.place.get(exe(*args)))
        # back to the batch order: the first position of every execution (padding repeats one)
        first = np.empty(total, int)
        first[layout[::-1]] = np.arange(len(layout))[::-1]
        final = _take(final, first[:n])
        if timings is not None:
            timings["rollout"] = time.perf_counter() - t0 - t_compile
        return final, t_compile


def warm_world(suite: Suite | str | None = None, settings: Settings | None = None) -> float:
    """Compile (or load) the world program of a suite's batch shape (the split path's,
    :mod:`lantern_jax.sim.split`) and the scoring programs of its results (the final metrics,
    :func:`finalize_batch`, and the pairs' components,
    :func:`~lantern_jax.scoring.table.route_components`), and keep them for every later
    process: none depends on the policy.  Returns the seconds it took.

    Args:
        suite: a :class:`~lantern_jax.scenarios.suite.Suite` or suite id (default: the built-in
            suite, whose batch shape every subset of it shares).
        settings: default :func:`~lantern_jax.sim.settings.default_settings`.
    """
    if suite is None or isinstance(suite, str):
        suite = load_suite() if suite is None else load_suite(suite)
    execs = build_executions(suite, bucket=True)
    settings = settings or default_settings()
    t0 = time.perf_counter()
    prepare([], execs.scenarios, settings)
    host = jax.tree.map(np.asarray, execs.scenarios)
    n = execs.num_executions
    start = start_states(host, min(n, split_slots()), settings, {})
    metrics = finalize_batch(jax.tree.map(lambda x: x[:n], start.telemetry), settings)
    d_safe = np.asarray(host.config.d_safe, np.float64)[execs.block(ROUTE_B)]
    route_components(execs.take(metrics, CONDITIONS[0]), execs.take(metrics, ROUTE_B), d_safe,
                     settings.scoring)  # fmt: skip
    return time.perf_counter() - t0


def check_texts(settings: Settings, scenarios: Scenario) -> None:
    """:meth:`Settings.check_texts` for the warnings and overrides of batched scenarios."""
    config = scenarios.config
    settings.check_texts(np.concatenate([
        np.asarray(config.text_id).reshape(-1), np.asarray(config.override_text_id).reshape(-1)
    ]))  # fmt: skip


def finalize_batch(telemetry: Any, settings: Settings = DEFAULT_SETTINGS) -> Any:
    """Hard per-execution metrics (:class:`~lantern_jax.scoring.metrics.ExecutionMetrics`,
    NumPy, leading batch axis) of a batch's final telemetry, through one compiled program.

    The batch is padded to a multiple of the built-in suite's executions
    (``SUITE_BATCH_SHAPE[0]``, repeats of its executions, dropped after; every execution's
    metrics are its own), so the suite and every subset of it share one program, which
    :func:`warm_world` keeps."""
    padded, n = pad_rows(telemetry, SUITE_BATCH_SHAPE[0])
    exe = executable(_finalize, padded, settings.scoring, identity=("finalize",))
    return jax.tree.map(lambda x: np.asarray(x)[:n], exe(padded, settings.scoring))
