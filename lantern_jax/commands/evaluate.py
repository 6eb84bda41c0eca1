"""``lantern-jax evaluate``: evaluate policies on a suite and write the result tables.

::

    lantern-jax evaluate                 # built-in suite, reference policies expert, ego, coop
    lantern-jax evaluate --policy coop --ablation late_onset --pairs-per-family 2 --out runs/x
    lantern-jax evaluate --config configs/quick.toml --policy coop     # the file, one option
    lantern-jax evaluate --fresh-suites 2 --seed 424242 --out runs/suites   # 3 suites, spread

Options may also come from an experiment file (``--config``, TOML, one ``[evaluate]`` table;
see :func:`load_config`); an option given on the command line always wins over the file.
``--fresh-suites`` is :mod:`lantern_jax.commands.fresh_suites`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import (
    check_out,
    list_written,
    load_selected_suite,
    option_source,
    register_checkpoints,
    resolve_policies,
    run_record,
    split_values,
    stage,
    write_failed,
)
from lantern_jax.commands.runtime import add_cache_flag, check_interrupt
from lantern_jax.commands.values import count, seed, whole
from lantern_jax.core.constants import EXECUTIONS_PER_PAIR, SUITE_ID

#: Defaults of the ``evaluate`` options an experiment file may set (used when neither the
#: command line nor the file gives one).
EVALUATE_DEFAULTS = {
    "policy": None,  # all reference policies (only the checkpoints' when --checkpoint is given)
    "checkpoint": None,  # no saved learned models
    "ablation": "none",
    "suite": SUITE_ID,
    "pairs_per_family": None,  # every pair
    "pairs": None,  # every pair
    "out": "results",
}

#: Keys of an ``evaluate`` experiment file and their accepted types.
CONFIG_KEYS = {
    "policy": (str, list),
    "checkpoint": (str, list),
    "ablation": (str,),
    "suite": (str,),
    "pairs_per_family": (int,),
    "pairs": (list,),
    "out": (str,),
}
#: The table of an experiment file.
CONFIG_TABLE = "evaluate"


# ---------------------------------------------------------------------------------------------
# the experiment file
# ---------------------------------------------------------------------------------------------
def load_config(path: str) -> dict:
    """Read an ``evaluate`` experiment file.

    The one layout: a TOML file with a single ``[evaluate]`` table whose keys are those of
    :data:`CONFIG_KEYS` (the long option names with ``_`` for ``-``)::

        [evaluate]
        suite = SUITE_ID
        policy = ["expert", "coop"]      # or one name, or "all"
        pairs_per_family = 2             # or pairs = ["pe_0001", "vc_0002"]
        ablation = "none"
        out = "results/quick"

    Returns:
        The ``[evaluate]`` table as a dict.

    Raises:
        UsageError: naming the file and the offending key for a key outside the table, an
            unknown key, a wrong type, an empty selection or a pair count below 1
            (:mod:`lantern_jax.io.config_file` reads the file).
    """
    from lantern_jax.io.config_file import ConfigFileError, check_keys, read_table, typed_value

    try:
        cfg = read_table(path, CONFIG_TABLE)
        for key, value in cfg.items():
            check_keys(path, CONFIG_TABLE, [key], tuple(CONFIG_KEYS))
            typed_value(value, CONFIG_KEYS[key], f"config {path}: {key}")
            _check_value(path, key, value)
    except ConfigFileError as e:
        raise UsageError(str(e)) from None
    return cfg


def _check_value(path: str, key: str, value) -> None:
    """What an experiment file's value must be besides its type: a list of strings, not empty,
    a pair count of at least 1."""
    if isinstance(value, list) and not all(isinstance(v, str) for v in value):
        raise UsageError(f"config {path}: {key} must be a list of strings, got {value!r}")
    names = [value] if isinstance(value, str) else value if isinstance(value, list) else None
    if names is not None and not split_values(names):
        raise UsageError(f"config {path}: {key} is empty (leave the key out for the default)")
    if key == "pairs_per_family" and value < 1:
        raise UsageError(f"config {path}: {key} must be >= 1 (got {value})")


def apply_config(args: argparse.Namespace) -> None:
    """Fill the ``evaluate`` options the command line did not give: from ``--config`` when it
    sets them, else from :data:`EVALUATE_DEFAULTS`.

    Options are parsed with ``None`` as their default, so an option given on the command line
    (even with its default value) always wins over the file.  ``args.sources`` records the
    options the file gave, so that a message names the file and key
    (:func:`~lantern_jax.commands.common.option_source`).
    """
    cfg = load_config(args.config) if args.config else {}
    args.sources = {}
    for key, default in EVALUATE_DEFAULTS.items():
        if getattr(args, key) is not None:
            continue
        if key in cfg:
            args.sources[key] = f"config {args.config}: {key}"
        value = cfg.get(key, default)
        if key in ("policy", "pairs", "checkpoint") and value is not None:
            value = [value] if isinstance(value, str) else [",".join(value)]
        setattr(args, key, value)


# ---------------------------------------------------------------------------------------------
# the command
# ---------------------------------------------------------------------------------------------
def _policies(args: argparse.Namespace) -> list[str]:
    """The policies to evaluate: ``--policy`` (default: the reference policies) and the
    ``--checkpoint`` models, or only the checkpoints' when no ``--policy`` is given."""
    if args.policy is not None and not split_values(args.policy):
        raise UsageError("--policy: no policy name given (leave the option out for 'all')")
    checkpoints = register_checkpoints(args.checkpoint, option_source(args, "checkpoint"))
    if checkpoints and args.policy is None:
        return checkpoints
    policies = resolve_policies(args.policy, option_source(args, "policy")) + checkpoints
    return list(dict.fromkeys(policies))


def _check_ablation(args: argparse.Namespace) -> None:
    from lantern_jax.apps.evaluation import ablation_names

    if args.ablation not in ablation_names():
        raise UsageError(
            f"{option_source(args, 'ablation')}: unknown ablation {args.ablation!r}; valid "
            f"ablations: {', '.join(ablation_names())}"
        )


def cmd_evaluate(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax evaluate``: run, print the tables, write the files (``--profile``: then
    where the time went, :func:`_evaluate_breakdown`)."""
    from lantern_jax.core.timing import Breakdown

    bd = Breakdown()
    bd.before_creation("start-up (Python, lantern_jax command line)")
    with bd.phase("imports (JAX, evaluator, tables)"):
        import lantern_jax.report  # noqa: F401  (used by _report; imported here to time it)
        from lantern_jax.apps.evaluation import PolicyError, evaluate
    apply_config(args)
    policies = _policies(args)
    _check_ablation(args)
    from lantern_jax.report import OUTPUT_FILES

    check_out(args.out, option_source(args, "out"), owned=OUTPUT_FILES)
    stage(args, f"loading suite {args.suite}")
    with bd.phase("suite load and validation"):
        suite = load_selected_suite(args)
    # the bootstrap's seed only when given (evaluate's default is the project's fixed seed)
    kwargs = dict(ablation=args.ablation, one_program=not args.program_per_policy,
                  path=args.rollout)  # fmt: skip
    if args.bootstrap_seed is not None:
        kwargs["bootstrap_seed"] = args.bootstrap_seed
    if args.seed is not None and args.fresh_suites is None:
        raise UsageError("--seed is the fresh suites' generation seed; give --fresh-suites K too")
    try:
        if args.fresh_suites is not None:
            from lantern_jax.commands.fresh_suites import run_fresh_suites

            return run_fresh_suites(args, argv, policies, suite, lambda m: stage(args, m), kwargs)
        stage(
            args,
            f"suite {suite.suite_id}: {len(suite)} pairs (hash {suite.suite_sha256[:12]}); "
            f"building {EXECUTIONS_PER_PAIR * len(suite)} executions per policy "
            f"(ablation {args.ablation}); "
            f"policies: {', '.join(policies)}",
        )
        t0 = time.perf_counter()
        result = evaluate(policies, suite=suite, progress=not args.quiet, **kwargs)
    except PolicyError as e:
        print(f"lantern-jax evaluate: error: {e}", file=sys.stderr)
        return 1
    return _report(args, argv, bd, result, time.perf_counter() - t0)


def _report(args: argparse.Namespace, argv: Sequence[str], bd, result, t_eval: float) -> int:
    """Write the result set, then print the tables, the files and (``--profile``) where the
    time went; only process 0 of a distributed run does so."""
    import jax

    from lantern_jax.report import format_tables, write_outputs

    if jax.process_index() != 0:  # every process has the whole result; one writes it
        return 0
    if "split programs" in result.seconds:
        seconds = result.seconds["split programs"]
        stage(args, f"world and policy programs (split path): {seconds:.1f} s")
    for run in result.manifest["policies"]:
        how = f" ({run['program']})" if run.get("program") else ""
        stage(
            args,
            f"{run['name']}: compile {run['seconds_compile']:.1f} s, "
            f"rollout {run['seconds_run']:.2f} s{how}",
        )
    stage(args, f"evaluation done in {t_eval:.1f} s; writing {args.out}")
    _evaluate_breakdown(bd, result, t_eval)
    check_interrupt()
    try:
        with bd.phase("writing the result files"):
            files = write_outputs(result, args.out, run_record=run_record(argv))
    except OSError as e:
        return write_failed(args.out, e)
    t_print = time.perf_counter()
    print(format_tables(result))
    print()
    list_written(files.values())
    bd.add("printing the tables", time.perf_counter() - t_print)
    if args.profile:
        print()
        print(bd.format("Where the time went"))
    return 0


def _evaluate_breakdown(bd, result, seconds: float) -> None:
    """Add the phases of :func:`lantern_jax.apps.evaluation.evaluate` (``seconds`` of wall time in
    all) to a breakdown: world build, per policy trace + lower, XLA compile, rollout and
    scoring, then the tables; the remainder is the rest of the evaluation (checks, progress)."""
    start = len(bd.phases)
    bd.add(f"world build ({result.manifest['executions_per_policy']} executions)",
           result.seconds.get("world build", 0.0))  # fmt: skip
    if "split programs" in result.seconds:
        bd.add("world and policy programs (split path, together)",
               result.seconds["split programs"])  # fmt: skip
    for run in result.runs:
        bd.add(f"policy {run.policy}", sum(run.timings.values()))
        for label, value in run.timings.items():
            bd.add(label, value, indent=1)
    bd.add("tables (family, decomposition, premise)", result.seconds.get("tables", 0.0))
    bd.add("intervals (pair-level bootstrap)", result.seconds.get("intervals", 0.0))
    accounted = sum(p.seconds for p in bd.phases[start:] if p.indent == 0)
    bd.add("rest of the evaluation (checks, progress)", max(0.0, seconds - accounted))


# ---------------------------------------------------------------------------------------------
# the parser
# ---------------------------------------------------------------------------------------------
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``evaluate`` on the command line's sub-parsers."""
    ev = sub.add_parser(
        "evaluate",
        allow_abbrev=False,
        help="evaluate policies on a suite and write the result tables",
        description="Evaluate policies on a suite (Route A with and without warning, Route B), "
        "print the per-family CUS and decomposition tables and write them with the route-level "
        "CSV, its schema and a reproducibility manifest.",
    )
    _add_selection(ev)
    ev.add_argument(
        "--out",
        metavar="DIR",
        help="output folder (default: results); the result set replaces an earlier one there "
        "as a whole, other entries of the folder are kept",
    )
    ev.add_argument("--quiet", action="store_true", help="no progress bar or stage lines")
    ev.add_argument(
        "--bootstrap-seed",
        type=seed(),
        metavar="N",
        help="seed of the pair-level bootstrap behind every interval (default: the project's "
        "fixed seed, lantern_jax.scoring.uncertainty.SEED); recorded in the manifest",
    )
    ev.add_argument(
        "--fresh-suites",
        type=count(100),
        metavar="K",
        help="also generate K fresh suites (the --suite's design and validator, seeds S .. "
        "S + K - 1 from --seed), evaluate --suite and each of them, and report every suite's "
        "tables and the mean and spread across suites (OUT/across_suites.md)",
    )
    ev.add_argument(
        "--seed",
        type=seed(),
        metavar="S",
        help="generation seed of the first fresh suite (with --fresh-suites)",
    )
    _add_running(ev)
    ev.add_argument(
        "--config",
        metavar="TOML",
        help="experiment file with an [evaluate] table (e.g. configs/quick.toml); options "
        "given on the command line win over it",
    )
    add_cache_flag(ev)
    ev.set_defaults(func=cmd_evaluate)


def _add_selection(ev: argparse.ArgumentParser) -> None:
    """What is evaluated: policies, checkpoints, ablation, suite and pairs."""
    ev.add_argument(
        "--policy",
        action="append",
        metavar="NAME",
        help="policy name, comma-separated names or 'all' (= expert, ego, coop; the default), "
        "or a policy in your own code as path/to/file.py:NAME or package.module:attr (a Policy "
        "or a function returning one; the manifest records its file's SHA-256); may be repeated",
    )
    ev.add_argument(
        "--checkpoint",
        action="append",
        metavar="PATH",
        help="a saved learned model (lantern-jax train) to evaluate under the name it was "
        "trained under; may be repeated; without --policy only the checkpoints are evaluated",
    )
    ev.add_argument("--ablation", metavar="NAME", help="protocol ablation (default: none)")
    ev.add_argument(
        "--suite", metavar="ID|PATH", help=f"suite id or manifest path (default: {SUITE_ID})"
    )
    ev.add_argument(
        "--pairs-per-family", type=count(), metavar="N",
        help="only the first N pairs of each family",
    )
    ev.add_argument("--pairs", action="append", metavar="ID[,ID...]", help="only these pair ids")


def _add_running(ev: argparse.ArgumentParser) -> None:
    """How the evaluation runs: profile, programs, processes."""
    ev.add_argument(
        "--profile",
        action="store_true",
        help="after the tables, print where the wall time went: start-up, imports, suite "
        "load, world build, per policy trace + lower, XLA compile, rollout and scoring, "
        "tables, writing",
    )
    ev.add_argument(
        "--program-per-policy",
        action="store_true",
        help="compile each policy's own rollout program (default: policies with different act "
        "functions share one program that picks the policy at run time, so the simulator is "
        "compiled once; results are the same to float32 rounding)",
    )
    ev.add_argument(
        "--rollout",
        choices=("auto", "fused", "split"),
        default="auto",
        help="how each policy is rolled out: 'fused' compiles world and policy as one program "
        "(the fastest rollout, a full compile per new policy), 'split' runs the world program "
        "shared by every policy (compiled once, kept on disk) beside the policy's own small "
        "program, 'auto' runs the package's policies fused (compiled once, kept) and a policy "
        "from your own file split; the run record says which ran and why",
    )
    ev.add_argument(
        "--coordinator",
        metavar="HOST:PORT",
        help="run across processes with JAX's distributed runtime: address of process 0 "
        "(with --num-processes and --process-id; process 0 writes the results)",
    )
    ev.add_argument("--num-processes", type=count(4096), metavar="N", help="processes in the run")
    ev.add_argument("--process-id", type=whole(0, 4095), metavar="I",
                    help="this process, 0 .. N-1")  # fmt: skip
