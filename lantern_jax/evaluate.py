"""One-call evaluation of a policy on a suite: every pair under Route A with warning, Route A
without warning and Route B, stepped in one jitted, vmapped call, then scored.

Route B carries no warning, so a policy sees the same Route B under both conditions: Route B
runs once per policy and is paired with both Route A executions.  Ablations (paper §4.4) change only
protocol data of the batch (:data:`ABLATIONS`).

Example::

    from lantern_jax.evaluate import evaluate
    result = evaluate(["expert", "ego", "coop"])          # built-in suite lantern-v3
    print(result.family_table)
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata as md
import platform
import sys
import time
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from lantern_jax import family_codes, program_store
from lantern_jax.constants import DT
from lantern_jax.policies.base import Policy, check_policy_output
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import SUITE_ID, Suite, build_suite_batches, load_suite
from lantern_jax.scenarios.warnings import paraphrase_text_ids
from lantern_jax.scoring.aggregate import decomposition_table, family_scores
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.table import build_route_table
from lantern_jax.sim.distributed import placement
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import rollout_scheduled_parallel, with_carry
from lantern_jax.sim.state import init_state
from lantern_jax.sim.step import Driver
from lantern_jax.sim.switch import PolicySwitch, policy_switch, switch_params
from lantern_jax.times import happened, time_or_nan
from lantern_jax.world import Scenario, trim_padding

CONDITIONS = ("warning", "no-warning")


def _ablate(field: str, value):
    def apply(config):
        return config.replace(**{field: jnp.full_like(getattr(config, field), value)})

    return apply


def _paraphrase(config):
    """Held-out paraphrases by ambiguity tier (``warnings.paraphrase_text_ids``): the pairs
    fall into three disjoint subsets (low / medium / high ambiguity) and each pair reads a
    paraphrase of its family and tier; the paper's ablation aggregates the three tiers."""
    return config.replace(text_id=jnp.asarray(paraphrase_text_ids(config), jnp.int32))


#: Ablations of the temporal protocol and the warning (paper Table "Sensitivity ...").
ABLATIONS: dict[str, Any] = {
    "none": None,
    "late_onset": _ablate("late_onset", True),
    "warning_beyond_termination": _ablate("warn_hold_extra", 10.0),
    "no_anti_deadlock": _ablate("force_event", False),
    "noisy_position": _ablate("pos_noise_m", 2.0),
    "held_out_paraphrase": _paraphrase,
}


def ablation_names() -> list[str]:
    """Valid ablation names."""
    return list(ABLATIONS)


@dataclasses.dataclass
class Executions:
    """The batched executions of a suite: ``[A warning | A no-warning | B]`` x pairs."""

    scenarios: Scenario  # leaves with leading axis 3 * num_pairs
    num_pairs: int
    pair_ids: list[str]
    families: list[str]
    weathers: list[str]
    max_ticks: int


def build_executions(suite: Suite, ablation: str = "none", trim: bool = True) -> Executions:
    """Build the batched scenarios of every execution of a suite under an ablation.

    With ``trim`` (default) the actor and lane slots past the last one any execution uses are
    cut (:func:`~lantern_jax.world.trim_padding`: narrower per-tick work, same results to the
    reproducibility promise); ``trim=False`` keeps the full slot capacity, one batch shape for
    every suite of the same size.

    Raises:
        ValueError: listing the valid ablations for an unknown name.
    """
    if ablation not in ABLATIONS:
        raise ValueError(f"unknown ablation {ablation!r}; valid: {', '.join(ABLATIONS)}")
    a, b = build_suite_batches(suite)
    on, off = np.ones_like(a.config.is_route_a), np.zeros_like(a.config.is_route_a)
    a_warn = a.replace(config=a.config.replace(warning_enabled=on))
    a_none = a.replace(config=a.config.replace(warning_enabled=off))
    fn = ABLATIONS[ablation]
    if fn is not None:
        a_warn = a_warn.replace(config=fn(a_warn.config))
        a_none = a_none.replace(config=fn(a_none.config))
    scenarios = jax.tree.map(lambda *x: np.concatenate(x), a_warn, a_none, b)
    if trim:
        scenarios = trim_padding(scenarios)
    scenarios = jax.device_put(scenarios)
    max_ticks = int(np.ceil(float(np.max(np.asarray(scenarios.config.timeout_s))) / DT))
    return Executions(
        scenarios=scenarios,
        num_pairs=len(suite.pairs),
        pair_ids=[p.pair_id for p in suite.pairs],
        families=[p.family for p in suite.pairs],
        weathers=[p.weather for p in suite.pairs],
        max_ticks=max_ticks,
    )


_COMPILED: dict[tuple, Any] = {}

#: Slot scheduling of large batches (``compact``): each device steps a fixed number of slots
#: ``REFILL_TICKS`` ticks at a time, and a slot whose execution has ended takes the next
#: waiting one (longest timeout first) inside the same compiled loop
#: (:func:`~lantern_jax.sim.rollout.rollout_scheduled`), so that no slot idles behind a few
#: long executions.  Batches smaller than ``COMPACT_MIN_BATCH`` step every execution at once.
#: Slots per device by JAX backend (:func:`compact_slots`): on CPU (one device per core) 24
#: stepped the suite fastest of 16-64 per device (``benchmarks/bench_evaluate.py``); other
#: backends keep 96, the value before refills moved into the program (not re-measured there).
COMPACT_SLOTS = {"cpu": 24}
COMPACT_SLOTS_OTHER = 96
REFILL_TICKS = 20
COMPACT_MIN_BATCH = 256


def compact_slots(backend: str | None = None) -> int:
    """Slots per device of the slot scheduling on ``backend`` (default: JAX's default)."""
    return COMPACT_SLOTS.get(backend or jax.default_backend(), COMPACT_SLOTS_OTHER)


def program_identity(policy: Driver) -> tuple:
    """What a rollout program of ``policy`` depends on besides its arguments: the policy's
    program (:attr:`~lantern_jax.policies.base.Policy.program`) or a switch's members'."""
    if isinstance(policy, PolicySwitch):
        return ("switch", tuple(m.program for m in policy.members))
    return ("policy", policy.program)


def compiled_rollout(policy: Driver, slots: int = COMPACT_SLOTS_OTHER,
                     chunk: int = REFILL_TICKS):  # fmt: skip
    """The jitted scheduled rollout program for a policy (cached per
    :func:`program_identity`, ``slots`` and ``chunk``).

    ``program(scenarios, policy_params, starts, max_ticks)`` rolls every execution of the
    batch from its state in ``starts`` to its end through ``slots`` slots per device, refilled
    every ``chunk`` ticks (:func:`~lantern_jax.sim.rollout.rollout_scheduled_parallel`); the
    batch is dealt in equal blocks to the devices.  The horizon ``max_ticks`` (int32 scalar) is
    an argument, not a constant, so one compiled program serves every horizon.  Initial states
    come from :data:`initial_states` (a separate program shared by every policy), so the
    policy's program holds no second copy of the sensing code.
    """
    key = ("program", program_identity(policy), slots, chunk)
    if key not in _COMPILED:

        def program(scenarios, policy_params, starts, max_ticks):
            return rollout_scheduled_parallel(
                scenarios, starts, policy, policy_params, max_ticks, slots, chunk
            )

        _COMPILED[key] = jax.jit(program)
    return _COMPILED[key]


#: ``jit(vmap(init_state))``: the executions' states at ``t = 0`` (ego, actors, the first
#: sensing, empty telemetry).  It does not depend on the policy, so every policy (and every
#: ablation of the same batch shape) reuses one compiled program.
initial_states = jax.jit(jax.vmap(init_state))


def _executable(fn, *args, timings: dict | None = None, identity: Any = None):
    """AOT-compile ``fn`` for ``args`` once (cached by function and argument shapes).

    With an ``identity`` (what determines the program besides the code and the arguments'
    shapes, see :func:`lantern_jax.program_store.program_key`) the compiled program is also
    kept on disk in the program store and, in a later process, loaded from there without
    tracing, lowering or compiling.

    ``timings`` (optional) receives the seconds of tracing and lowering (``"trace + lower"``),
    of XLA's compilation or the load from JAX's persistent cache (``"XLA compile"``) and of a
    load from the program store (``"program load"``); all 0 when the program was already
    compiled in this process.
    """
    shapes = jax.tree.map(lambda x: (tuple(np.shape(x)), str(np.result_type(x))), args)
    key = ("exe", fn, jax.tree.structure(args), str(jax.tree.leaves(shapes)))
    spent = {"trace + lower": 0.0, "XLA compile": 0.0, "program load": 0.0}
    if key not in _COMPILED:
        t0 = time.perf_counter()
        stored = program_store.program_key(identity, args) if identity is not None else None
        exe = program_store.load(stored) if stored is not None else None
        if exe is not None:
            spent["program load"] = time.perf_counter() - t0
        else:
            lowered = fn.lower(*args)
            t1 = time.perf_counter()
            exe, fresh = program_store.compile_lowered(lowered)
            spent["trace + lower"], spent["XLA compile"] = t1 - t0, time.perf_counter() - t1
            if stored is not None and fresh:
                program_store.save(stored, exe)
        _COMPILED[key] = exe
    if timings is not None:
        timings.update(spent)
    return _COMPILED[key]


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


def run_executions(
    policy: Driver,
    scenarios: Scenario,
    policy_params: Any,
    max_ticks: int,
    compact: bool | None = None,
    timings: dict | None = None,
    pad_to: int | None = None,
):
    """Roll out a batch of executions until all have ended; returns (final states, seconds
    spent compiling).

    One compiled program (:func:`compiled_rollout`) does all the stepping, in one call.  A
    small batch steps every execution at once; a large one (``compact``, see ``COMPACT_*``
    and :func:`compact_slots`) is stepped through a fixed number of slots per device,
    refilled inside the program with the waiting executions as earlier ones end
    (:func:`schedule_layout` deals them to the devices): the same executions, only grouped
    differently.  Every execution starts from
    its state at ``t = 0`` given by :data:`initial_states` (one compiled program per block
    shape, shared by every policy) and the policy's initial carry.  ``policy`` is a
    :class:`~lantern_jax.policies.base.Policy` or a
    :class:`~lantern_jax.sim.switch.PolicySwitch`.  Under JAX's distributed runtime (several
    processes) the call runs on the global mesh, each process stepping its devices' blocks,
    and the final states are gathered on every process (:mod:`lantern_jax.sim.distributed`).
    ``timings`` (optional dict) receives ``"trace + lower"``, ``"XLA compile"`` and
    ``"rollout"`` seconds.
    ``pad_to`` (optional) pads the batch to that many executions with copies of the first
    that start ended (never stepped, last in every device's queue), so that batches of
    different sizes share one compiled program at little cost.

    Raises:
        ValueError: when ``pad_to`` is smaller than the batch.

    Returns:
        (final states as NumPy arrays with leading axis ``n``, seconds spent compiling).
    """
    n = jax.tree.leaves(scenarios)[0].shape[0]
    total = n if pad_to is None else pad_to
    if total < n:
        raise ValueError(f"run_executions: pad_to={pad_to} is smaller than the batch ({n})")
    if compact is None:
        compact = total >= COMPACT_MIN_BATCH and max_ticks > REFILL_TICKS
    place = placement()
    devices = jax.device_count()
    host = jax.tree.map(np.asarray, scenarios)
    if total > n:  # padding: copies of the first execution, queued after every real one
        host = _take(host, np.concatenate([np.arange(n), np.zeros(total - n, int)]))
    timeout = np.where(np.arange(total) < n, host.config.timeout_s, -np.inf)
    layout = schedule_layout(timeout, devices)
    per_device = len(layout) // devices
    slots = min(per_device, compact_slots()) if compact else per_device
    params = place.replicate(policy_params)
    laid = _take(host, layout)

    t0 = time.perf_counter()
    block = min(len(layout), slots * devices)  # the initial-state program's batch shape
    init_timings: dict[str, float] = {}
    init_exe = _executable(
        initial_states,
        _take(laid, np.arange(block)),
        timings=init_timings,
        identity=("initial_states",),
    )
    t_compile = time.perf_counter() - t0
    parts = []
    for lo in range(0, len(layout), block):
        rows = np.resize(np.arange(lo, min(lo + block, len(layout))), block)
        out = jax.tree.map(np.asarray, init_exe(_take(laid, rows)))
        parts.append(_take(out, np.arange(min(block, len(layout) - lo))))
    starts = jax.tree.map(lambda *x: np.concatenate(x), *parts)
    starts = starts.replace(done=starts.done | (layout >= n))  # padding starts ended
    starts = jax.tree.map(np.asarray, with_carry(starts, policy, policy_params))
    args = (place.put(laid), params, place.put(starts), place.replicate(np.int32(max_ticks)))
    t1 = time.perf_counter()
    exe = _executable(
        compiled_rollout(policy, slots, REFILL_TICKS),
        *args,
        timings=timings,
        identity=("rollout", program_identity(policy), slots, REFILL_TICKS),
    )
    t_compile += time.perf_counter() - t1
    if timings is not None:
        for k, v in init_timings.items():
            timings[k] += v
    final = jax.tree.map(np.asarray, place.get(exe(*args)))
    # back to the batch order: the first position of every execution (padding repeats one)
    first = np.empty(total, int)
    first[layout[::-1]] = np.arange(len(layout))[::-1]
    final = _take(final, first[:n])
    if timings is not None:
        timings["rollout"] = time.perf_counter() - t0 - t_compile
    return final, t_compile


#: :func:`~lantern_jax.scoring.metrics.finalize` as one compiled program (op by op, its first
#: call compiled each operation on its own: about a second).
_finalize_jit = jax.jit(finalize)


def params_hash(params: Any) -> str:
    """SHA-256 over the policy parameter leaves (shapes, dtypes and bytes)."""
    h = hashlib.sha256()
    for leaf in jax.tree.leaves(params):
        a = np.asarray(leaf)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def package_versions() -> dict[str, str]:
    """Versions of the packages that determine the results."""
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("lantern-jax", "jax", "jaxlib", "flax", "numpy", "pandas"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "not installed"
    out["jax_backend"] = jax.default_backend()
    return out


@dataclasses.dataclass
class PolicyRun:
    """Raw results of one policy on one suite."""

    policy: str
    params_sha256: str
    metrics: dict[str, np.ndarray]  # per execution (3 * num_pairs), numpy
    protocol: dict[str, np.ndarray]
    route_table: pd.DataFrame
    seconds_compile: float
    seconds_run: float
    #: wall seconds by phase: "trace + lower", "XLA compile", "rollout", "scoring"
    timings: dict[str, float] = dataclasses.field(default_factory=dict)


def run_policy(
    policy: Policy | str,
    execs: Executions,
    policy_params: Any = None,
    model: str | None = None,
    shared: tuple[PolicySwitch, tuple] | None = None,
) -> PolicyRun:
    """Run one policy on prepared executions and build its route-level rows.

    Args:
        policy: a :class:`Policy` or a registered name.
        execs: from :func:`build_executions`.
        policy_params: policy parameters (default ``policy.init(PRNGKey(0))``).
        model: name used in the tables (default: the policy name).
        shared: ``(switch, members' parameters)``: run the policy as its member of a
            :class:`~lantern_jax.sim.switch.PolicySwitch` (one program for several policies,
            see :func:`shared_program`); ``None`` compiles the policy's own program.
    """
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    sc0 = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), execs.scenarios)
    obs = jax.eval_shape(lambda sc: observe(sc, init_state(sc), pol.sensors), sc0)
    check_policy_output(pol, params, obs)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    driver, run_params = pol, params
    if shared is not None:
        switch, members = shared
        i = switch.index_of(pol)
        members = (*members[:i], params, *members[i + 1 :])
        driver, run_params = switch, switch_params(switch, i, members)
    final, t_compile = run_executions(
        driver, execs.scenarios, run_params, execs.max_ticks, timings=timings
    )
    t2 = time.perf_counter()
    t1 = t0 + t_compile
    finalize_exe = _executable(_finalize_jit, final.telemetry, identity=("finalize",))
    m_struct = jax.tree.map(np.asarray, finalize_exe(final.telemetry))
    metrics = {f.name: getattr(m_struct, f.name) for f in dataclasses.fields(m_struct)}
    proto = jax.tree.map(np.asarray, final.protocol)
    proto = {f.name: getattr(proto, f.name) for f in dataclasses.fields(proto)}
    n = execs.num_pairs
    rows = []
    onset = np.asarray(time_or_nan(final.protocol.t_warn_on))
    shown = np.asarray(final.protocol.warning_ticks)
    d_safe = np.asarray(execs.scenarios.config.d_safe)
    reached = np.asarray(happened(proto["t_warn_point"]))
    hidden_at = reached & ~np.asarray(proto["hazard_visible_at_warn"], bool)
    hidden_before = reached & ~np.asarray(proto["hazard_seen_before_warn"], bool)
    for ci, cond in enumerate(CONDITIONS):
        sl = slice(ci * n, (ci + 1) * n)
        rows.append(
            build_route_table(
                jax.tree.map(lambda x, sl=sl: x[sl], m_struct),
                jax.tree.map(lambda x: x[2 * n : 3 * n], m_struct),
                model=model or pol.name,
                condition=cond,
                pair_ids=execs.pair_ids,
                families=execs.families,
                weathers=execs.weathers,
                t_warn_on=onset[sl],
                d_safe=d_safe[sl],
                warning_ticks=shown[sl],
                hidden_at_warning=hidden_at[sl],
                hidden_before_warning=hidden_before[sl],
            )
        )
    table = pd.concat(rows, ignore_index=True)
    timings["scoring"] = time.perf_counter() - t2
    return PolicyRun(
        policy=model or pol.name,
        params_sha256=params_hash(params),
        metrics=metrics,
        protocol=proto,
        route_table=table,
        seconds_compile=t1 - t0,
        seconds_run=t2 - t1,
        timings=timings,
    )


def family_table(route_table: pd.DataFrame) -> pd.DataFrame:
    """Per-family CUS rows for every (model, condition) plus each model's paired warning gain.

    Columns: ``model, condition, PE, VC, OR, LWW, RWW, RTY``, the registered families the
    rows hold (:func:`lantern_jax.family_codes.table_codes`), ``Overall``.
    """
    fam = family_scores(route_table).reset_index()
    out = []
    for model in dict.fromkeys(fam["model"]):
        sub = fam[fam["model"] == model].set_index("condition")
        for cond in CONDITIONS:
            if cond in sub.index:
                out.append({"model": model, "condition": cond, **sub.loc[cond].drop("model")})
        if all(c in sub.index for c in CONDITIONS):
            gain = sub.loc["warning"].drop("model") - sub.loc["no-warning"].drop("model")
            out.append({"model": model, "condition": "warning gain", **gain})
    cols = ["model", "condition", *family_codes.table_codes(route_table["family"]), "Overall"]
    return pd.DataFrame(out)[cols]


PREMISE_ROWS = (
    ("hazard_hidden_at_warning", "hidden at the warning point"),
    ("hazard_hidden_before_warning", "hidden for the whole approach"),
)


def premise_table(route_table: pd.DataFrame) -> pd.DataFrame:
    """The benchmark's premise, measured: per family, the share (%) of Route A executions
    (every model and condition in ``route_table``) whose hazard the front camera could not see
    at the warning point, and could not see at any tick of the approach up to it.

    Columns: ``measure, PE, VC, OR, LWW, RWW, RTY``, the registered families the rows hold,
    ``Overall`` (Overall pools all executions); the last row, ``Route A executions``, counts
    them per family.
    """
    families = family_codes.table_codes(route_table["family"])
    rows = []
    for col, label in PREMISE_ROWS:
        row = {"measure": label}
        for f in families:
            v = route_table.loc[route_table["family"] == f, col]
            row[f] = 100.0 * float(v.mean()) if len(v) else np.nan
        row["Overall"] = 100.0 * float(route_table[col].mean()) if len(route_table) else np.nan
        rows.append(row)
    counts = {"measure": "Route A executions"}
    counts.update({f: float((route_table["family"] == f).sum()) for f in families})
    counts["Overall"] = float(len(route_table))
    return pd.DataFrame([*rows, counts])


class PolicyError(ValueError):
    """A policy that cannot be evaluated: its ``act`` failed while being traced, compiled or
    run, or returned the wrong shape; the message names the policy."""


@dataclasses.dataclass
class EvalResult:
    """Everything an evaluation produces."""

    route_table: pd.DataFrame
    family_table: pd.DataFrame
    decomposition: pd.DataFrame
    manifest: dict
    runs: list[PolicyRun]
    premise: pd.DataFrame  # % of Route A executions with the hazard unseen (:func:`premise_table`)
    #: wall seconds of the shared phases: "world build" and "tables" (per policy: ``runs``)
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)


def _policies_to_run(policies, suite) -> list[Policy]:
    """Resolve policy names and refuse inputs that cannot give a well-keyed result."""
    if isinstance(policies, str | Policy):
        policies = [policies]
    policies = list(policies)
    if not policies:
        raise ValueError("evaluate: no policies given")
    names = [p if isinstance(p, str) else getattr(p, "name", repr(p)) for p in policies]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(
            f"evaluate: policy name(s) {', '.join(map(repr, twice))} given more than once; "
            "results are keyed by policy name"
        )
    if isinstance(suite, Suite) and not suite.pairs:
        raise ValueError(f"evaluate: suite {suite.suite_id!r} has no pairs")
    return [get_policy(p) if isinstance(p, str) else p for p in policies]


def shared_program(pols: list[Policy], policy_params: list) -> tuple[PolicySwitch, tuple] | None:
    """One program for every policy of an evaluation, or ``None`` when they share one already.

    Policies with the same program (:attr:`~lantern_jax.policies.base.Policy.program`: act
    function, sensors, carry; e.g. two checkpoints of one architecture) already share a compiled
    program; policies with different ones are joined in a
    :class:`~lantern_jax.sim.switch.PolicySwitch` (members in order of first appearance), so
    the simulator is compiled once for all of them.  Returns ``(switch, members' parameters)``
    for :func:`run_policy` (each member's parameters those of its first policy; they fix the
    program's argument shapes), or ``None`` for fewer than two distinct programs.
    """
    members: dict[tuple, tuple] = {}
    for pol, par in zip(pols, policy_params, strict=True):
        if pol.program not in members:
            params = pol.init(jax.random.PRNGKey(0)) if par is None else par
            members[pol.program] = (pol, params)
    if len(members) < 2:
        return None
    reps, params = zip(*members.values(), strict=True)
    return policy_switch(reps), tuple(params)


def _run_all(
    pols: list[Policy],
    policy_params: list,
    execs: Executions,
    suite_id: str,
    progress: bool,
    share: bool = True,
) -> list[PolicyRun]:
    """Run every policy (progress bar per policy); a failing policy raises :class:`PolicyError`.

    With ``share`` the policies run in one program (:func:`shared_program`)."""
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(pols), desc=f"evaluating on {suite_id}", unit="policy")
    runs: list[PolicyRun] = []
    try:
        shared = shared_program(pols, policy_params) if share else None
        for pol, par in zip(pols, policy_params, strict=True):
            if bar is not None:
                bar.set_postfix_str(f"{pol.name}: compile + {3 * execs.num_pairs} executions")
            try:
                runs.append(run_policy(pol, execs, par, shared=shared))
            except Exception as e:
                lines = str(e).strip().splitlines() or [""]
                why = lines[0] if len(lines) == 1 else f"{lines[0]} ... {lines[-1]}"
                raise PolicyError(
                    f"policy {pol.name!r} failed while being traced or run on suite {suite_id}: "
                    f"{type(e).__name__}: {why}"
                ) from e
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return runs


def _manifest(s: Suite, ablation: str, execs: Executions, runs: list[PolicyRun]) -> dict:
    """The reproducibility manifest of an evaluation."""
    return dict(
        suite_id=s.suite_id,
        suite_sha256=s.suite_sha256,
        suite_seed=s.seed,
        num_pairs=len(s.pairs),
        ablation=ablation,
        conditions=list(CONDITIONS),
        executions_per_policy=3 * execs.num_pairs,
        max_ticks=execs.max_ticks,
        dt_s=DT,
        policies=[
            dict(
                name=r.policy,
                params_sha256=r.params_sha256,
                seconds_compile=round(r.seconds_compile, 3),
                seconds_run=round(r.seconds_run, 3),
            )
            for r in runs
        ],
        policy_init_seed=0,
        devices=jax.device_count(),  # every process's devices (the global mesh)
        processes=jax.process_count(),
        packages=package_versions(),
    )


def evaluate(
    policies: Sequence[str | Policy] | str | Policy = ("expert", "ego", "coop"),
    policy_params: Sequence[Any] | None = None,
    suite: Suite | str = SUITE_ID,
    ablation: str = "none",
    progress: bool = True,
    one_program: bool = True,
) -> EvalResult:
    """Evaluate policies on a suite: one jitted, vmapped rollout call per policy, then score.

    Args:
        policies: policy names / objects (one or several).
        policy_params: parameters per policy (default: each policy's ``init``).
        suite: a :class:`Suite` or a suite id / manifest path.
        ablation: one of :func:`ablation_names`.
        progress: show a progress bar.
        one_program: run policies with different ``act`` functions in one compiled program
            (:func:`shared_program`: the simulator is compiled once, not once per policy);
            ``False`` compiles each policy's own program (results equal to float32 rounding).

    Returns:
        :class:`EvalResult` with the route-level table, the family table (with paired warning
        gains), the decomposition table and the reproducibility manifest.

    Raises:
        ValueError: for no policies, a policy given twice (rows are keyed by policy name), or
            a suite without pairs.
        PolicyError: naming the policy whose ``act`` failed while traced or run.
    """
    pols = _policies_to_run(policies, suite)
    if policy_params is None:
        policy_params = [None] * len(pols)
    if len(policy_params) != len(pols):
        raise ValueError(f"policy_params: {len(policy_params)} entries for {len(pols)} policies")
    s = load_suite(suite) if isinstance(suite, str) else suite
    t0 = time.perf_counter()
    execs = build_executions(s, ablation)
    t_build = time.perf_counter() - t0
    runs = _run_all(pols, list(policy_params), execs, s.suite_id, progress, one_program)
    t0 = time.perf_counter()
    route = pd.concat([r.route_table for r in runs], ignore_index=True)
    result = EvalResult(
        route_table=route,
        family_table=family_table(route),
        decomposition=decomposition_table(route).reset_index(),
        manifest=_manifest(s, ablation, execs, runs),
        runs=runs,
        premise=premise_table(route),
    )
    result.seconds = {"world build": t_build, "tables": time.perf_counter() - t0}
    return result
