"""One-call evaluation of policies on a suite: every pair under Route A with warning, Route A
without warning and Route B, stepped in one jitted, vmapped call per policy
(:mod:`lantern_jax.sim.engine`), then scored into the route-level table and the summary tables.

Route B carries no warning, so a policy sees the same Route B under both conditions: Route B
runs once per policy and is paired with both Route A executions.  Ablations (paper §4.4) change
only protocol data of the batch (:mod:`lantern_jax.scenarios.protocol_variants`).

Example::

    from lantern_jax import evaluate
    result = evaluate(["expert", "ego", "coop"])          # built-in suite lantern-v3
    print(result.family_table)
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.metadata as md
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.core.checks import check_seed
from lantern_jax.core.constants import CONDITIONS, DT, ROUTE_B, SUITE_ID
from lantern_jax.core.progress import tqdm
from lantern_jax.core.times import happened, time_or_nan
from lantern_jax.policies.base import Policy, check_policy_output
from lantern_jax.policies.external import is_policy_source
from lantern_jax.policies.failures import PolicyError, explain_failure
from lantern_jax.policies.registry import (
    get_policy,
    policy_names,
    policy_source,
    register_policy_source,
)
from lantern_jax.report import write_outputs
from lantern_jax.report.page import build_report
from lantern_jax.report.results import Evaluation, PolicyRun
from lantern_jax.scenarios.protocol_variants import ablation_names
from lantern_jax.scenarios.suite import Suite, load_suite
from lantern_jax.scoring.aggregate import (
    PREMISE_ROWS,
    decomposition_table,
    family_table,
    premise_table,
)
from lantern_jax.scoring.table import build_route_table
from lantern_jax.scoring.uncertainty import SEED, table_intervals
from lantern_jax.sim.engine import (
    PATHS,
    Executions,
    PathChoice,
    build_executions,
    choose_path,
    finalize_batch,
    fused_kept,
    run_executions,
)
from lantern_jax.sim.observe import observe
from lantern_jax.sim.programs import abstract
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings, default_settings, settings_record
from lantern_jax.sim.split import declared_observation, prepare
from lantern_jax.sim.state import init_state
from lantern_jax.sim.switch import PolicySwitch, as_member, shared_program

__all__ = [
    "CONDITIONS", "EvalResult", "Executions", "PolicyError", "PolicyRun", "ablation_names",
    "build_executions", "evaluate", "params_hash", "run_policy", "shared_program",
]  # fmt: skip


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


def _route_rows(
    m_struct: Any, proto: dict, execs: Executions, model: str, settings: Settings
) -> pd.DataFrame:
    """The route-level rows of one policy's final metrics and protocol (both conditions)."""
    onset = np.asarray(time_or_nan(proto["t_warn_on"]))
    d_safe = np.asarray(execs.scenarios.config.d_safe)
    reached = np.asarray(happened(proto["t_warn_point"]))
    hidden_at = reached & ~np.asarray(proto["hazard_visible_at_warn"], bool)
    hidden_before = reached & ~np.asarray(proto["hazard_seen_before_warn"], bool)
    rows = []
    for cond in CONDITIONS:
        sl = execs.block(cond)
        rows.append(
            build_route_table(
                execs.take(m_struct, cond),
                execs.take(m_struct, ROUTE_B),
                model=model,
                condition=cond,
                pair_ids=execs.pair_ids,
                families=execs.families,
                weathers=execs.weathers,
                t_warn_on=onset[sl],
                d_safe=d_safe[sl],
                warning_ticks=np.asarray(proto["warning_ticks"])[sl],
                hidden_at_warning=hidden_at[sl],
                hidden_before_warning=hidden_before[sl],
                settings=settings.scoring,
            )  # fmt: skip
        )
    return pd.concat(rows, ignore_index=True)


def _first_observation(scenario: Any, sensors: tuple[str, ...], bank: Any) -> Any:
    """The observation of one execution's start state through ``sensors`` (for its shapes)."""
    return observe(scenario, init_state(scenario), sensors, bank)


def run_policy(
    policy: Policy | str,
    execs: Executions,
    policy_params: Any = None,
    model: str | None = None,
    shared: tuple[PolicySwitch, tuple] | None = None,
    settings: Settings = DEFAULT_SETTINGS,
    stage: Callable[[str], None] | None = None,
    path: str | PathChoice = "auto",
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
        settings: scoring, protocol and text bank.
        stage: called with what the run does next (``"compiling"``, ``"<n> executions"``,
            ``"scoring"``), for a progress display.
        path: ``"auto"``, ``"fused"`` or ``"split"``
            (:func:`~lantern_jax.sim.engine.choose_path`; a shared program is always fused), or
            a :class:`~lantern_jax.sim.engine.PathChoice` made beforehand.
    """
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    sc0 = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), execs.scenarios)
    bank = hashlib.sha256(repr(settings.bank).encode()).hexdigest()
    if isinstance(path, PathChoice) and path.path == "split":  # the world's signature has it
        obs = declared_observation(pol, sc0, settings)
    else:
        obs = abstract("observe", functools.partial(_first_observation, sensors=pol.sensors,
                                                    bank=settings.bank), sc0,
                       parts=(repr(pol.sensors), bank))  # fmt: skip
    check_policy_output(pol, params, obs)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    driver, run_params = (pol, params) if shared is None else as_member(shared, pol, params)
    chosen: list = []
    shown = stage if stage is None else lambda what: stage(f"{what}, {chosen[-1].path} path")
    final, t_compile = run_executions(
        driver, execs.scenarios, run_params, execs.max_ticks, settings, timings=timings,
        pad_to=execs.pad_to, stage=shown, path=path, chosen=chosen,
    )  # fmt: skip
    if stage is not None:
        stage("scoring")
    t2 = time.perf_counter()
    telemetry = jax.tree.map(np.asarray, final.telemetry)  # read back once, kept in the run
    m_struct = finalize_batch(telemetry, settings)
    proto = jax.tree.map(np.asarray, final.protocol)
    proto = {f.name: getattr(proto, f.name) for f in dataclasses.fields(proto)}
    table = _route_rows(m_struct, proto, execs, model or pol.name, settings)
    timings["scoring"] = time.perf_counter() - t2
    return PolicyRun(
        policy=model or pol.name,
        params_sha256=params_hash(params),
        metrics={f.name: getattr(m_struct, f.name) for f in dataclasses.fields(m_struct)},
        protocol=proto,
        route_table=table,
        seconds_compile=t_compile,
        seconds_run=t2 - t0 - t_compile,
        timings=timings,
        program=str(chosen[-1]),
        telemetry=telemetry,
    )


@dataclasses.dataclass
class EvalResult(Evaluation):
    """Everything an evaluation produces (the fields of
    :class:`~lantern_jax.report.results.Evaluation`), and the methods that write it."""

    def write(self, folder: str | os.PathLike, run_record: dict | None = None) -> dict[str, Path]:
        """Write this evaluation's files into ``folder``, the same set as ``lantern-jax
        evaluate --out folder`` (tables, route-level CSV and its schema, reproducibility
        manifest, run record): :func:`lantern_jax.report.write_outputs`.

        Args:
            folder: output folder (created if needed; result files already there are
                replaced together, other entries kept).
            run_record: more entries for the run record (e.g. how the result was made).

        Returns:
            File name -> path of every file written.

        Raises:
            ValueError: when the route-level table does not satisfy its schema (nothing is
                written).
            lantern_jax.io.files.OutputFolderError: when ``folder`` cannot receive the set.
        """

        return write_outputs(self, folder, run_record=run_record)

    def report(self, path: str | os.PathLike, folder: str | os.PathLike | None = None) -> Path:
        """Write this evaluation's result files and its HTML report
        (:func:`lantern_jax.report.page.build_report`: built from the files, as ``lantern-jax
        report`` builds it; failure figures: ``lantern-jax report --figures``).

        Args:
            path: the HTML file.
            folder: where the result files go (default: ``<path's stem>_results`` beside it).

        Returns:
            The HTML file's path.
        """

        path = Path(path)
        folder = path.with_name(path.stem + "_results") if folder is None else Path(folder)
        self.write(folder)
        return build_report([folder], path)


def _policies_to_run(policies, suite, settings_given: Any = None) -> list[Policy]:
    """Resolve policy names and refuse inputs that cannot give a well-keyed result."""
    if isinstance(policies, str | Policy):
        policies = [policies]
    policies = list(policies)
    if not policies:
        raise ValueError("evaluate: no policies given")
    names = [p if isinstance(p, str) else getattr(p, "name", repr(p)) for p in policies]
    if settings_given is not None and not isinstance(settings_given, Settings):
        raise TypeError(f"evaluate: settings must be a lantern_jax.Settings, got "
                        f"{type(settings_given).__name__}")  # fmt: skip
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(
            f"evaluate: policy name(s) {', '.join(map(repr, twice))} given more than once; "
            "results are keyed by policy name"
        )
    if isinstance(suite, Suite) and not suite.pairs:
        raise ValueError(f"evaluate: suite {suite.suite_id!r} has no pairs")
    out = []
    for p in policies:
        if not isinstance(p, str | Policy):
            raise TypeError(f"evaluate: a policy is a registered name or a Policy, got "
                            f"{type(p).__name__} {p!r}")  # fmt: skip
        if isinstance(p, str) and is_policy_source(p):  # file.py:NAME or package.module:attr
            p = register_policy_source(p)
        if isinstance(p, Policy):
            bad = sorted({c for c in p.name if c in NAME_BREAKERS or not c.isprintable()})
            if bad:
                raise ValueError(f"evaluate: policy name {p.name!r} holds {bad}, which break "
                                 "the result tables and the command line's lists")  # fmt: skip
            if p.name in policy_names():
                _check_not_impostor(p)
        out.append(get_policy(p) if isinstance(p, str) else p)
    return out


#: Characters a policy's name may not hold: they split the command line's lists (``,``) and
#: the Markdown tables (``|``).
NAME_BREAKERS = (",", "|")


def _check_not_impostor(pol: Policy) -> None:
    """Refuse a Policy object that carries a registered policy's name but is another policy --
    another act function, sensors, carry or parameters (its rows would be labelled as the
    registered one's)."""
    registered = get_policy(pol.name)
    same = (pol.act, pol.sensors, pol.init_carry) == (
        registered.act, registered.sensors, registered.init_carry
    )  # fmt: skip
    key = jax.random.PRNGKey(0)
    if not same or params_hash(pol.init(key)) != params_hash(registered.init(key)):
        raise ValueError(
            f"evaluate: policy name {pol.name!r} is a registered policy's, but this Policy "
            "is another one (its rows could not be told from the registered policy's); give it "
            "a name of its own"
        )


#: The evaluation's progress bar: policies done, elapsed time and what the current policy does
#: (``starting``, ``compiling``, ``<n> executions``, ``scoring``); no remaining-time estimate,
#: which the first policy's compilation would make meaningless.
BAR_FORMAT = "{desc}: {n_fmt}/{total_fmt} policies [{elapsed}]{postfix}"


def _show_stage(bar: Any, name: str, what: str) -> None:
    """Show what policy ``name`` does now on the progress bar."""
    bar.set_postfix_str(f"{name}: {what}")


def _initial_params(pol: Policy, params: Any, suite_id: str) -> Any:
    """``params``, or the policy's ``init(PRNGKey(0))`` when None (called once per evaluation:
    a new policy's ``init`` may compile its random draws)."""
    if params is not None:
        return params
    try:
        return pol.init(jax.random.PRNGKey(0))
    except Exception as e:
        raise PolicyError(
            f"policy {pol.name!r} failed while being traced or run on suite {suite_id}: "
            f"{explain_failure(e)}"
        ) from e


def _run_all(pols: list[Policy], policy_params: list, execs: Executions, suite_id: str,
             progress: bool, share: bool, settings: Settings,
             path: str = "auto") -> tuple[list[PolicyRun], float]:  # fmt: skip
    """Run every policy (progress bar per policy); a failing policy raises :class:`PolicyError`.

    How each runs is :func:`_plan`'s choice (with ``share``, one fused program for several
    policies where that is cheaper).  Returns the runs and the wall seconds spent preparing the
    split path's programs together (0 when none)."""
    bar = None
    if progress:
        bar = tqdm(total=len(pols), desc=f"evaluating on {suite_id}", unit="policy",
                   bar_format=BAR_FORMAT)  # fmt: skip
    runs: list[PolicyRun] = []
    try:
        policy_params = [_initial_params(p, par, suite_id) for p, par in
                         zip(pols, policy_params, strict=True)]  # fmt: skip
        shared, choices, prepared = _plan(pols, policy_params, execs, settings, share, path,
                                          bar)  # fmt: skip
        for pol, par, choice in zip(pols, policy_params, choices, strict=True):
            stage = None if bar is None else functools.partial(_show_stage, bar, pol.name)
            if stage is not None:
                stage("starting")
            try:
                joined = shared if choice.path == "fused" else None
                runs.append(run_policy(pol, execs, par, shared=joined, settings=settings,
                                       stage=stage, path=choice))  # fmt: skip
                runs[-1].seconds_compile += prepared.get(pol.name, 0.0)
            except Exception as e:
                raise PolicyError(
                    f"policy {pol.name!r} failed while being traced or run on suite {suite_id}: "
                    f"{explain_failure(e)}"
                ) from e
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return runs, prepared.get("programs", 0.0)


def _plan(pols: list[Policy], policy_params: list, execs: Executions, settings: Settings,
          share: bool, path: str, bar: Any) -> tuple[Any, list, dict[str, float]]:  # fmt: skip
    """How every policy of an evaluation is rolled out: ``(shared, choices, seconds)``.

    Each policy's path is :func:`~lantern_jax.sim.engine.choose_path`'s (the policy, the batch
    and the backend decide, never what is cached); beside a policy that takes the split path,
    the package's policies take it too (the world program is compiled for it anyway).
    ``shared`` joins the policies that take the fused path in one program
    (:func:`shared_program`, with ``share``: one compilation for all of them), or is None.
    The split policies' programs are compiled at once (:func:`lantern_jax.sim.split.prepare`);
    ``seconds`` gives each one's compile time."""
    n = execs.num_executions if execs.pad_to is None else execs.pad_to
    choices = [choose_path(p, n, path) for p in pols]
    if path == "auto" and any(c.path == "split" for c in choices):
        # the world program serves one policy: the package's policies beside it need only
        # their own small programs too (the same choice for the same policies, whatever ran)
        choices = [PathChoice("split", "beside a policy from outside the package, whose world "
                              "program it shares") if fused_kept(p) and c.path == "fused" else c
                   for p, c in zip(pols, choices, strict=True)]  # fmt: skip
    fused = [(p, par) for p, par, c in zip(pols, policy_params, choices, strict=True)
             if c.path == "fused"]  # fmt: skip
    shared = None
    if share and fused:
        shared = shared_program([p for p, _ in fused], [par for _, par in fused])
    split = [(p, par) for p, par, c in zip(pols, policy_params, choices, strict=True)
             if c.path == "split"]  # fmt: skip
    if not split:
        return shared, choices, {}
    if bar is not None:
        bar.set_postfix_str(f"programs of the world and {len(split)} "
                            f"polic{'ies' if len(split) > 1 else 'y'}")  # fmt: skip
    try:
        return shared, choices, prepare(split, execs.scenarios, settings)
    except Exception:  # noqa: BLE001  (a policy that fails is named when it runs on its own)
        return shared, choices, {}


def _manifest(s: Suite, ablation: str, execs: Executions, runs: list[PolicyRun],
              intervals: dict, settings: Settings) -> dict:  # fmt: skip
    """The reproducibility manifest of an evaluation (``intervals``: the bootstrap's settings,
    :func:`lantern_jax.scoring.uncertainty.settings`)."""
    return dict(
        suite_id=s.suite_id,
        suite_sha256=s.suite_sha256,
        suite_seed=s.seed,
        num_pairs=len(s.pairs),
        ablation=ablation,
        conditions=list(CONDITIONS),
        executions_per_policy=execs.num_executions,
        max_ticks=execs.max_ticks,
        dt_s=DT,
        settings=settings_record(settings),
        policies=[
            dict(
                name=r.policy,
                params_sha256=r.params_sha256,
                seconds_compile=round(r.seconds_compile, 3),
                seconds_run=round(r.seconds_run, 3),
                program=r.program,
                # a policy loaded from a user's code: its file and the SHA-256 of its source
                **({"source": policy_source(r.policy)} if policy_source(r.policy) else {}),
            )
            for r in runs
        ],
        policy_init_seed=0,
        intervals=intervals,
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
    bootstrap_seed: int = SEED,
    settings: Settings | None = None,
    path: str = "auto",
) -> EvalResult:
    """Evaluate policies on a suite: one jitted, vmapped rollout call per policy, then score.

    Args:
        policies: policy names / objects (one or several).
        policy_params: parameters per policy (default: each policy's ``init``).
        suite: a :class:`Suite` or a suite id / manifest path.
        ablation: one of :func:`ablation_names`.
        progress: show a progress bar.
        one_program: run policies with different programs in one compiled program
            (:func:`shared_program`: the simulator is compiled once, not once per policy);
            ``False`` compiles each policy's own program (results equal to float32 rounding).
        bootstrap_seed: seed of the pair-level bootstrap of the tables' intervals (recorded in
            the manifest).
        settings: scoring thresholds and weights, protocol thresholds, text bank
            (:class:`~lantern_jax.sim.settings.Settings`; recorded in the manifest; default:
            :func:`~lantern_jax.sim.settings.default_settings`, the paper's).
        path: how each policy is rolled out: ``"fused"`` (world and policy one compiled
            program), ``"split"`` (the world program shared by every policy, the policy's own
            small program) or ``"auto"`` (the package's policies and bulk batches fused, a
            policy from outside the package split: :func:`~lantern_jax.sim.engine.choose_path`,
            which never depends on what is cached); recorded per policy in the run record.
            The two paths' results agree to float32 rounding.

    Returns:
        :class:`EvalResult` with the route-level table, the family table (with paired warning
        gains), the decomposition table, their intervals and the reproducibility manifest.

    Raises:
        ValueError: for no policies, a policy given twice (rows are keyed by policy name), a
            suite without pairs, or settings out of range.
        PolicyError: naming the policy whose ``act`` failed while traced or run.
    """
    if jax.config.jax_enable_x64:
        raise ValueError("evaluate: JAX's 64-bit mode is on (JAX_ENABLE_X64): the simulator, its "
                         "scores and its stored programs are float32; turn it off")  # fmt: skip
    pols = _policies_to_run(policies, suite, settings)
    check_seed("evaluate: bootstrap_seed", bootstrap_seed)
    if path not in PATHS:
        raise ValueError(f"evaluate: path {path!r} is not one of {', '.join(PATHS)}")
    settings = (default_settings() if settings is None else settings).validate()
    if policy_params is None:
        policy_params = [None] * len(pols)
    if len(policy_params) != len(pols):
        raise ValueError(f"policy_params: {len(policy_params)} entries for {len(pols)} policies")
    s = load_suite(suite) if isinstance(suite, str) else suite
    ids = [p.pair_id for p in s.pairs]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise ValueError(f"evaluate: suite {s.suite_id!r} holds pair(s) {twice} more than once")
    t0 = time.perf_counter()
    execs = build_executions(s, ablation, bucket=True)
    t_build = time.perf_counter() - t0
    runs, t_programs = _run_all(pols, list(policy_params), execs, s.suite_id, progress,
                                one_program, settings, path)  # fmt: skip
    t0 = time.perf_counter()
    route = pd.concat([r.route_table for r in runs], ignore_index=True)
    tables = dict(
        family_table=family_table(route),
        decomposition=decomposition_table(route).reset_index(),
        premise=premise_table(route),
    )
    t1 = time.perf_counter()
    intervals = table_intervals(route, PREMISE_ROWS, seed=bootstrap_seed)
    t2 = time.perf_counter()
    result = EvalResult(
        route_table=route,
        manifest=_manifest(s, ablation, execs, runs, intervals.settings, settings),
        runs=runs,
        intervals=intervals,
        **tables,
    )
    result.seconds = {"world build": t_build, "tables": t1 - t0, "intervals": t2 - t1}
    if t_programs:
        result.seconds["split programs"] = t_programs
    return result
