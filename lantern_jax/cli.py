"""The ``lantern-jax`` command line.

::

    lantern-jax evaluate                 # built-in suite, reference policies expert, ego, coop
    lantern-jax evaluate --policy coop --ablation late_onset --pairs-per-family 2 --out runs/x
    lantern-jax evaluate --fresh-suites 2 --seed 424242 --out runs/suites   # 3 suites, spread
    lantern-jax suite --list             # pairs, suite hash, generation report
    lantern-jax suite --verify           # regenerate lantern-v3 from its seed, compare hashes
    lantern-jax suite --regenerate suite.json
    lantern-jax evaluate --checkpoint my-coop=runs/train/coop/learned-coop.msgpack --policy all
    lantern-jax policies
    lantern-jax dataset --out data/lantern            # the open-loop training dataset
    lantern-jax train --config configs/train_base.toml
    lantern-jax wording --policy coop    # warning wording by ambiguity (paper appendix table)
    lantern-jax diagnostics nonactionable --policy coop   # non-actionable warnings, empty road
    lantern-jax diagnostics distance --policy coop        # near vs far warning on Route B
    lantern-jax diagnostics language --policy coop        # does the policy read the words?
    lantern-jax ablations --list         # the protocol ablations
    lantern-jax ablations --policy coop  # the paper's ablation table for one policy
    lantern-jax compare results --policy coop --policy expert   # paired difference, p-values
    lantern-jax unseen --policy coop     # the paper's unseen-hazard tables
    lantern-jax --families my_families.py evaluate --suite my_suite.json   # user families

Options may also come from an experiment file (``--config``, TOML, one ``[evaluate]`` table; see
:func:`load_config`); an option given on the command line always wins over the file.  Options
must be spelled out in full (no abbreviations).

Exit codes: 0 success, 1 failure (a policy that fails, results that cannot be written, a suite
that does not regenerate, standard output that cannot be written), 2 usage errors (unknown
policy, ablation, suite or pair; an invalid suite file, checkpoint or config; an empty
selection; an output folder that cannot be written — all found before anything is compiled),
130 interrupted (Ctrl-C), 141 the reader of standard output went away (``| head``).
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import signal
import sys
import threading
import time
from collections.abc import Sequence

from lantern_jax.commands import CommandError, write_and_list
from lantern_jax.commands import compare as compare_command
from lantern_jax.commands import dataset as dataset_command
from lantern_jax.commands import families as families_option
from lantern_jax.commands import stress as stress_command
from lantern_jax.commands import train as train_command
from lantern_jax.commands import unseen as unseen_command
from lantern_jax.constants import FAMILIES, SUITE_ID

REFERENCE_POLICIES = ("expert", "ego", "coop")
#: The policy ``wording`` and ``diagnostics`` run when given neither --policy nor --checkpoint.
ONE_POLICY_DEFAULT = "coop"
EXIT_INTERRUPTED = 130
#: Exit code when the reader of standard output has gone (128 + SIGPIPE, as a shell reports a
#: command that a closed pipe stopped).
EXIT_STDOUT_CLOSED = 141

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


#: Environment variable that sets the number of XLA CPU devices of the command line.
CPU_DEVICES_ENV = "LANTERN_JAX_CPU_DEVICES"


def expose_cpu_cores() -> None:
    """Expose one XLA CPU device per core, so that the evaluator can split its batch over them.

    Only possible before JAX starts; skipped when JAX is already imported, when ``XLA_FLAGS``
    already sets a device count, or when ``LANTERN_JAX_CPU_DEVICES`` says otherwise (e.g. 1).

    Raises:
        UsageError: when ``LANTERN_JAX_CPU_DEVICES`` is not a whole number >= 1.
    """
    given = os.environ.get(CPU_DEVICES_ENV)
    if given is not None and not (given.strip().isdigit() and int(given) >= 1):
        raise UsageError(f"environment variable {CPU_DEVICES_ENV}: expected a whole number "
                         f">= 1, got {given!r}")  # fmt: skip
    if "jax" in sys.modules:
        return
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_force_host_platform_device_count" in flags:
        return
    n = int(given) if given is not None else os.cpu_count() or 1
    if n > 1:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n}".strip()


#: Environment variable that moves the persistent compilation cache of the command line.
CACHE_DIR_ENV = "LANTERN_JAX_CACHE_DIR"


def compile_cache_dir() -> str:
    """Where the command line keeps compiled programs between runs.

    ``$LANTERN_JAX_CACHE_DIR`` if set, else JAX's own ``$JAX_COMPILATION_CACHE_DIR`` if set,
    else ``$XDG_CACHE_HOME/lantern-jax/jax`` (``~/.cache/lantern-jax/jax`` by default).
    """
    for var in (CACHE_DIR_ENV, "JAX_COMPILATION_CACHE_DIR"):
        if os.environ.get(var):
            return os.environ[var]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "lantern-jax", "jax")


def configure_compile_cache(enabled: bool) -> str | None:
    """Turn JAX's persistent compilation cache on (in :func:`compile_cache_dir`) or off.

    A second run of the same command then loads its compiled programs instead of compiling
    them again (``--no-compile-cache`` turns this off).  Must run before the first compile.

    Returns:
        The cache folder, or None when disabled.
    """
    import jax

    jax.config.update("jax_enable_compilation_cache", enabled)
    if not enabled:
        return None
    path = compile_cache_dir()
    jax.config.update("jax_compilation_cache_dir", path)
    return path


class UsageError(Exception):
    """A user error that ends the command with exit code 2."""


def initialize_distributed(args: argparse.Namespace) -> None:
    """Join JAX's distributed runtime (``--coordinator``, ``--num-processes``, ``--process-id``)
    before anything runs on a device; the evaluation then spans every process's devices.

    Raises:
        UsageError: for an incomplete or inconsistent set of the three options.
    """
    n, i, addr = args.num_processes, args.process_id, args.coordinator
    if addr is None or n is None or i is None:
        raise UsageError("--coordinator, --num-processes and --process-id go together")
    if n < 1 or not 0 <= i < n:
        raise UsageError(f"--process-id must be in [0, {n}) and --num-processes >= 1")
    import jax

    jax.distributed.initialize(coordinator_address=addr, num_processes=n, process_id=i)


def _stage(args: argparse.Namespace, msg: str) -> None:
    check_interrupt()
    if not getattr(args, "quiet", False):
        print(f"[lantern-jax] {msg}", file=sys.stderr, flush=True)


def suite_to_manifest(suite, suite_id: str | None = None) -> dict:
    """A suite manifest dict (the format :func:`~lantern_jax.scenarios.suite.load_suite` reads)
    of a loaded :class:`~lantern_jax.scenarios.suite.Suite` (e.g. a ``select``-ed part of one).

    Args:
        suite: the suite.
        suite_id: id stored in the manifest (default: the suite's id).
    """

    def pair(p) -> dict:
        d = dict(pair_id=p.pair_id, family=p.family, weather=p.weather, sha256=p.sha256,
                 params=p.params)  # fmt: skip
        if p.route_2m is not None:
            d["route_2m"] = p.route_2m
        return d

    return dict(
        suite_id=suite_id or suite.suite_id,
        format_version=1,
        seed=suite.seed,
        pairs=[pair(p) for p in suite.pairs],
        suite_sha256=suite.suite_sha256,
        generation_report=suite.report,
    )


def _source(args: argparse.Namespace, key: str) -> str:
    """Where the value of option ``key`` came from: ``--key`` or ``config FILE: key``."""
    return getattr(args, "sources", {}).get(key) or "--" + key.replace("_", "-")


def resolve_policies(names: Sequence[str] | None, source: str = "--policy") -> list[str]:
    """Expand ``all`` and comma-separated lists; check every name against the registry.

    Args:
        names: the values given (each a name or comma-separated names).
        source: where they came from, for the messages (an option or a config key).

    Raises:
        UsageError: naming the unknown policy and where it came from, listing the known ones.
    """
    from lantern_jax.policies.registry import get_policy, policy_names

    out: list[str] = []
    for item in names or ["all"]:
        for name in (n.strip() for n in item.split(",")):
            if not name:
                continue
            expanded = list(REFERENCE_POLICIES) if name == "all" else [name]
            for n in expanded:
                try:
                    get_policy(n)
                except KeyError:
                    raise UsageError(
                        f"{source}: unknown policy {n!r}; known policies: "
                        f"{', '.join(policy_names())} (or 'all' = {', '.join(REFERENCE_POLICIES)})"
                    ) from None
                if n not in out:
                    out.append(n)
    if not out:
        raise UsageError(f"{source}: no policy given")
    return out


def _load_suite(args: argparse.Namespace):
    from lantern_jax.scenarios.suite import SuiteError, load_suite

    try:
        suite = load_suite(args.suite)
    except FileNotFoundError as e:
        raise UsageError(f"{_source(args, 'suite')}: " + str(e).strip("'\"")) from None
    except SuiteError as e:
        raise UsageError(str(e)) from None
    given = getattr(args, "pairs", None)
    if given is not None:
        src = _source(args, "pairs")
        pairs = [p.strip() for item in given for p in item.split(",")]
        pairs = [p for p in pairs if p]
        if not pairs:
            raise UsageError(f"{src}: no pair id given (leave the option out for every pair)")
        try:
            suite = suite.select(pairs)
        except KeyError as e:
            raise UsageError(f"{src}: " + str(e).strip("'\"")) from None
        except ValueError as e:
            raise UsageError(f"{src}: {e}") from None
    n = getattr(args, "pairs_per_family", None)
    if n is not None:
        if n < 1:
            raise UsageError(f"{_source(args, 'pairs_per_family')} must be >= 1 (got {n})")
        suite = suite.subset(n)
    if len(suite) == 0:
        raise UsageError(f"suite {suite.suite_id!r} has no pairs")
    return suite


# ---------------------------------------------------------------------------------------------
# commands
# ---------------------------------------------------------------------------------------------
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


CONFIG_TABLE = "evaluate"


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
            (:mod:`lantern_jax.config_file` reads the file).
    """
    from lantern_jax.config_file import ConfigFileError, check_keys, read_table, typed_value

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
    if names is not None and not any(n.strip() for v in names for n in v.split(",")):
        raise UsageError(f"config {path}: {key} is empty (leave the key out for the default)")
    if key == "pairs_per_family" and value < 1:
        raise UsageError(f"config {path}: {key} must be >= 1 (got {value})")


def _apply_config(args: argparse.Namespace) -> None:
    """Fill the ``evaluate`` options the command line did not give: from ``--config`` when it
    sets them, else from :data:`EVALUATE_DEFAULTS`.

    Options are parsed with ``None`` as their default, so an option given on the command line
    (even with its default value) always wins over the file.  ``args.sources`` records the
    options the file gave, so that a message names the file and key (:func:`_source`).
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


def _checkpoint_item(item: str) -> tuple[str | None, str]:
    """``(name, path)`` of a ``--checkpoint`` value: ``NAME=PATH`` or just ``PATH`` (an
    existing file whose name holds ``=`` is a path)."""
    from lantern_jax.policies.names import name_problem

    name, sep, path = item.partition("=")
    if sep and not name_problem(name) and not os.path.exists(item):
        return name, path
    return None, item


def register_checkpoints(paths: Sequence[str] | None, source: str = "--checkpoint") -> list[str]:
    """Register saved learned models (``--checkpoint PATH`` or ``NAME=PATH``) as policies;
    returns their names.

    Args:
        paths: the values given (each one or comma-separated checkpoints), or None.
        source: where they came from, for the messages (an option or a config key).

    Raises:
        UsageError: naming the file for a missing, invalid or mismatching checkpoint, one whose
            name is already registered for another policy, or when values were given but
            name no checkpoint.
    """
    from lantern_jax.policies.learned.checkpoint import CheckpointError
    from lantern_jax.policies.registry import register_checkpoint

    names = []
    for item in paths or []:
        for value in (p.strip() for p in item.split(",")):
            if not value:
                continue
            name, path = _checkpoint_item(value)
            try:
                names.append(register_checkpoint(path, name))
            except CheckpointError as e:
                raise UsageError(f"{source}: {e}") from None
    if paths is not None and not names:
        raise UsageError(f"{source}: no checkpoint given (leave the option out for none)")
    return names


def _check_out(out: str, source: str = "--out") -> None:
    """Refuse an output folder that cannot receive the result set, before evaluating."""
    from lantern_jax.files import OutputFolderError
    from lantern_jax.report import check_output_folder

    try:
        check_output_folder(out)
    except OutputFolderError as e:
        raise UsageError(f"{source}: {e}") from None


def cmd_evaluate(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax evaluate``: run, print the tables, write the files (``--profile``: then
    where the time went, :func:`_evaluate_breakdown`)."""
    from lantern_jax.timing import Breakdown

    bd = Breakdown()
    bd.before_creation("start-up (Python, lantern_jax command line)")
    with bd.phase("imports (JAX, evaluator, tables)"):
        from lantern_jax.evaluation import PolicyError, ablation_names, evaluate
        from lantern_jax.report import format_tables, write_outputs
    _apply_config(args)
    if args.policy is not None and not any(n.strip() for v in args.policy for n in v.split(",")):
        raise UsageError("--policy: no policy name given (leave the option out for 'all')")
    checkpoints = register_checkpoints(args.checkpoint, _source(args, "checkpoint"))
    if checkpoints and args.policy is None:
        policies = checkpoints
    else:
        policies = resolve_policies(args.policy, _source(args, "policy")) + checkpoints
        policies = list(dict.fromkeys(policies))
    if args.ablation not in ablation_names():
        raise UsageError(
            f"{_source(args, 'ablation')}: unknown ablation {args.ablation!r}; valid ablations: "
            f"{', '.join(ablation_names())}"
        )
    _check_out(args.out, _source(args, "out"))
    _stage(args, f"loading suite {args.suite}")
    with bd.phase("suite load and validation"):
        suite = _load_suite(args)
    # the bootstrap's seed only when given (evaluate's default is the project's fixed seed)
    boot = {} if args.bootstrap_seed is None else {"bootstrap_seed": args.bootstrap_seed}
    if args.seed is not None and args.fresh_suites is None:
        raise UsageError("--seed is the fresh suites' generation seed; give --fresh-suites K too")
    if args.fresh_suites is not None:
        from lantern_jax.commands.fresh_suites import run_fresh_suites

        kwargs = dict(
            ablation=args.ablation,
            one_program=not getattr(args, "program_per_policy", False),
            **boot,
        )
        try:
            return run_fresh_suites(args, argv, policies, suite, lambda m: _stage(args, m), kwargs)
        except PolicyError as e:
            print(f"lantern-jax evaluate: error: {e}", file=sys.stderr)
            return 1
    _stage(
        args,
        f"suite {suite.suite_id}: {len(suite)} pairs (hash {suite.suite_sha256[:12]}); "
        f"building {3 * len(suite)} executions per policy (ablation {args.ablation}); "
        f"policies: {', '.join(policies)}",
    )
    t0 = time.perf_counter()
    try:
        result = evaluate(
            policies, suite=suite, ablation=args.ablation, progress=not args.quiet,
            one_program=not getattr(args, "program_per_policy", False), **boot,
        )  # fmt: skip
    except PolicyError as e:
        print(f"lantern-jax evaluate: error: {e}", file=sys.stderr)
        return 1
    import jax

    if jax.process_index() != 0:  # every process has the whole result; one writes it
        return 0
    for run in result.manifest["policies"]:
        _stage(
            args,
            f"{run['name']}: compile {run['seconds_compile']:.1f} s, "
            f"rollout {run['seconds_run']:.2f} s",
        )
    t_eval = time.perf_counter() - t0
    _stage(args, f"evaluation done in {t_eval:.1f} s; writing {args.out}")
    _evaluate_breakdown(bd, result, t_eval)
    check_interrupt()
    try:
        with bd.phase("writing the result files"):
            files = write_outputs(result, args.out, run_record=_run_record(argv))
    except OSError as e:
        print(f"lantern-jax: error: cannot write results to {args.out}: {e}", file=sys.stderr)
        return 1
    t_print = time.perf_counter()
    print(format_tables(result))
    print()
    print(f"Wrote {len(files)} files:")
    for path in files.values():
        print(f"  {path}")
    bd.add("printing the tables", time.perf_counter() - t_print)
    if args.profile:
        print()
        print(bd.format("Where the time went"))
    return 0


def _run_record(argv: Sequence[str]) -> dict:
    """What the run record of a result set says about this command (besides the timings)."""
    return {"command": shlex.join(["lantern-jax", *argv])}


def _evaluate_breakdown(bd, result, seconds: float) -> None:
    """Add the phases of :func:`lantern_jax.evaluation.evaluate` (``seconds`` of wall time in
    all) to a breakdown: world build, per policy trace + lower, XLA compile, rollout and
    scoring, then the tables; the remainder is the rest of the evaluation (checks, progress)."""
    start = len(bd.phases)
    bd.add(f"world build ({result.manifest['executions_per_policy']} executions)",
           result.seconds.get("world build", 0.0))  # fmt: skip
    for run in result.runs:
        bd.add(f"policy {run.policy}", sum(run.timings.values()))
        for label, value in run.timings.items():
            bd.add(label, value, indent=1)
    bd.add("tables (family, decomposition, premise)", result.seconds.get("tables", 0.0))
    bd.add("intervals (pair-level bootstrap)", result.seconds.get("intervals", 0.0))
    accounted = sum(p.seconds for p in bd.phases[start:] if p.indent == 0)
    bd.add("rest of the evaluation (checks, progress)", max(0.0, seconds - accounted))


def _print_suite(suite) -> None:
    from tabulate import tabulate

    from lantern_jax import family_codes

    families = family_codes.table_codes(p.family for p in suite.pairs)  # the six, then others
    rows = [
        [
            p.pair_id,
            p.family,
            p.weather,
            f"{float(p.params.get('route_length', float('nan'))):.1f}",
            p.sha256[:12],
        ]
        for p in suite.pairs
    ]
    print(
        tabulate(
            rows,
            headers=["pair", "family", "weather", "route (m)", "sha256"],
            disable_numparse=True,
            colalign=("left", "left", "left", "right", "left"),
        )
    )
    print()
    counts = {f: sum(p.family == f for p in suite.pairs) for f in families}
    per_family = ", ".join(f"{f} {n}" for f, n in counts.items())
    print(f"suite {suite.suite_id}: {len(suite)} pairs ({per_family})")
    print(f"suite sha256: {suite.suite_sha256}")
    print(f"seed: {suite.seed}")
    rep = suite.report or {}
    rate = rep.get("expert_pass_rate")
    if rate:
        tried = rep.get("dynamic_tried", {})
        who = rep.get("validator", "expert-v1")
        print(f"generation report: expert pass rate before filtering (candidates run; "
              f"validator {who})")  # fmt: skip
        for f in families:
            if f in rate:
                print(f"  {f:<4} {100.0 * float(rate[f]):5.1f} %  ({tried.get(f, '?')})")
        for key, label in (("static_rejected", "static rejects"),
                           ("premise_rejected", "premise rejects (hazard visible)"),
                           ("near_duplicate_rejected", "near-duplicate rejects")):  # fmt: skip
            counts = rep.get(key)
            if counts:
                print(f"  {label}: " + ", ".join(f"{f} {counts.get(f, 0)}" for f in families))
    else:
        print("generation report: none in the manifest")


def cmd_suite(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax suite``: list, verify or regenerate a suite."""
    del argv
    from lantern_jax.generate import (
        DEFAULT_SEED,
        generate_suite,
        suite_validator,
        verify_regeneration,
    )
    from lantern_jax.scenarios.suite import write_manifest

    rc = 0
    if args.regenerate is not None:
        where = os.path.dirname(os.path.abspath(args.regenerate))
        if not args.regenerate.strip() or os.path.isdir(args.regenerate):
            raise UsageError(f"--regenerate {args.regenerate!r}: give the path of a file to write")
        if os.path.exists(where) and not os.path.isdir(where):
            raise UsageError(f"--regenerate {args.regenerate}: {where} is a file, not a folder")
    do_list = args.list or not (args.verify or args.regenerate)
    if do_list:
        _print_suite(_load_suite(args))
    if args.regenerate:
        seed = DEFAULT_SEED if args.seed is None else args.seed
        validator = args.validator or suite_validator(_load_suite(args).report)
        resolve_policies([validator])
        _stage(args, f"generating a suite from seed {seed} (runs {validator} on every candidate)")
        manifest = generate_suite(seed, progress=not args.quiet, validator=validator)
        try:
            write_manifest(manifest, args.regenerate)
        except OSError as e:
            print(f"lantern-jax suite: error: cannot write {args.regenerate}: {e}", file=sys.stderr)
            return 1
        print(f"wrote {args.regenerate}: {len(manifest['pairs'])} pairs, "
              f"suite sha256 {manifest['suite_sha256']}")  # fmt: skip
    if args.verify:
        _load_suite(args)  # hash check of the manifest itself
        _stage(args, f"regenerating {args.suite} from its seed and comparing hashes")
        ok, msg = verify_regeneration(args.suite)
        print(f"{'OK' if ok else 'MISMATCH'}: {args.suite}: {msg}")
        rc = 0 if ok else 1
    return rc


def cmd_policies(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax policies``: registered policies with descriptions."""
    del args, argv
    from lantern_jax.policies.registry import get_policy, policy_names

    rows = []
    for name in policy_names():
        p = get_policy(name)
        rows.append([name, ", ".join(p.sensors), p.description])
    from tabulate import tabulate

    print(tabulate(rows, headers=["policy", "sensors", "description"], disable_numparse=True))
    return 0


def _list_ablations() -> None:
    from tabulate import tabulate

    from lantern_jax.scenarios.ablations import ABLATIONS

    rows = [[a.name, a.description] for a in ABLATIONS]
    print(tabulate(rows, headers=["ablation", "description"], disable_numparse=True))


def cmd_ablations(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax ablations``: list the protocol ablations, or run the ablation table."""
    if args.list or args.policy is None:
        _list_ablations()
        if args.policy is None and not args.list:
            print("\n(run the table with: lantern-jax ablations --policy NAME)")
        return 0
    policies = resolve_policies([args.policy])
    if len(policies) != 1:
        raise UsageError(f"--policy: give one policy, got {', '.join(policies)}")
    _check_out(args.out)
    suite = _load_suite(args)
    from lantern_jax.ablations import run_ablations
    from lantern_jax.evaluation import PolicyError
    from lantern_jax.report import format_ablation_table, interval_note, write_ablation_outputs
    from lantern_jax.scenarios.ablations import ABLATIONS

    _stage(
        args,
        f"suite {suite.suite_id}: {len(suite)} pairs; policy {policies[0]}; "
        f"{len(ABLATIONS)} protocol variants x {3 * len(suite)} executions",
    )
    t0 = time.perf_counter()
    try:
        result = run_ablations(policies[0], suite=suite, progress=not args.quiet)
    except PolicyError as e:
        print(f"lantern-jax ablations: error: {e}", file=sys.stderr)
        return 1
    _stage(args, f"done in {time.perf_counter() - t0:.1f} s; writing {args.out}")
    try:
        files = write_ablation_outputs(result, args.out, run_record=_run_record(argv))
    except OSError as e:
        print(f"lantern-jax: error: cannot write results to {args.out}: {e}", file=sys.stderr)
        return 1
    m = result.manifest
    print(
        f"Ablations  (suite {m['suite_id']}, {m['num_pairs']} pairs, policy {policies[0]}, "
        "warning condition; all entries 0-100)"
    )
    print(format_ablation_table(result.table, intervals=result.intervals))
    print(interval_note(m.get("intervals")))
    print()
    print(f"Wrote {len(files)} files:")
    for path in files.values():
        print(f"  {path}")
    return 0


def _one_policy(args: argparse.Namespace) -> str:
    """The one policy of ``wording`` / ``diagnostics``: ``--checkpoint`` or ``--policy`` (default
    ``coop``), never both."""
    if args.checkpoint is not None:
        if args.policy is not None:
            raise UsageError("--policy and --checkpoint: give one of them (a checkpoint is the "
                             "policy that is run)")  # fmt: skip
        return register_checkpoints([args.checkpoint])[0]
    names = resolve_policies([args.policy or ONE_POLICY_DEFAULT])
    if len(names) != 1:
        raise UsageError(f"--policy: give one policy name, got {', '.join(names)}")
    return names[0]


def _print_and_write(args: argparse.Namespace, tables: dict, note: str) -> int:
    """Print every (title, table) and write them as CSV + Markdown into ``--out``."""
    from tabulate import tabulate

    for title, df, *display in tables.values():
        print(title)
        print(tabulate(display[0] if display else df, headers="keys", showindex=False,
                       floatfmt=".1f", disable_numparse=bool(display)))  # fmt: skip
        print()
    if note:
        print(note)
    return write_and_list(tables, args.out)


def cmd_wording(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax wording``: the warning-wording table by ambiguity tier."""
    del argv
    policy = _one_policy(args)
    _check_out(args.out)
    suite = _load_suite(args)
    _stage(args, f"{policy} on {suite.suite_id} ({len(suite)} pairs): canonical and tiered "
                 "paraphrase warnings")  # fmt: skip
    from lantern_jax.diagnostics import WORDING_COLUMNS, wording_table
    from lantern_jax.report import interval_display, interval_note

    table = wording_table(policy, suite)
    title = (
        f"Warning wording by ambiguity  ({policy}, suite {suite.suite_id}; Route A with warning; "
        "retention = paraphrase / matched canonical CUS)"
    )
    note = (
        "Matched no-warning = the same pairs without any warning (what ignoring the text scores). "
        + interval_note(over="each row's route pairs; retention paired")
        + "."
    )
    display = interval_display(table, WORDING_COLUMNS, "n")
    return _print_and_write(args, {"wording": (title, table, display)}, note)


#: Options of ``diagnostics`` that only the distance diagnostic reads.
DISTANCE_OPTIONS = ("suite", "family", "routes", "window")


def cmd_diagnostics(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax diagnostics nonactionable|distance|language``."""
    del argv
    reads = {"nonactionable": (), "distance": DISTANCE_OPTIONS,
             "language": ("suite", "pairs_per_family")}[args.which]  # fmt: skip
    given = [
        f"--{k.replace('_', '-')}"
        for k in (*DISTANCE_OPTIONS, "pairs_per_family")
        if getattr(args, k) is not None and k not in reads
    ]
    if given:
        raise UsageError(f"{', '.join(given)}: the {args.which} diagnostic does not read "
                         f"{'it' if len(given) == 1 else 'them'}")  # fmt: skip
    policy = _one_policy(args)
    _check_out(args.out)
    from lantern_jax import diagnostics as dg

    if args.which == "language":
        args.suite = args.suite or SUITE_ID
        suite = _load_suite(args)
        _stage(args, f"{policy} on {suite.suite_id} ({len(suite)} pairs): delivered text, "
                     "another family's text, empty text, no warning")  # fmt: skip
        table = dg.language_table(policy, suite)
        title = (
            f"Language sensitivity  ({policy}, suite {suite.suite_id}; Route A CUS per family; "
            "other family's text: PE<->LWW, VC<->RWW, OR<->RTY canonical texts at the same "
            "position)"
        )
        note = (
            "gain kept = (variant - no warning) / (delivered text - no warning); a policy that "
            "reads the words keeps little of its gain under another family's text or an empty "
            f"one ('-' where the gain is below {dg.MIN_GAIN_FOR_SHARE:.0f} point)."
        )
        return _print_and_write(args, {"language": (title, table)}, note)

    if args.which == "nonactionable":
        _stage(args, f"{policy}: non-actionable warnings on an empty road")
        table = dg.nonactionable_table(policy)
        title = (
            f"Non-actionable warnings  ({policy}; empty {dg.EMPTY_ROAD_LENGTH_M:.0f} m road at "
            f"{dg.EMPTY_ROAD_SPEED_MPS:.0f} m/s, warning from t = {dg.ONSET_S:.0f} s to the end)"
        )
        note = (
            "dv_max: largest additional speed reduction vs no warning; Stop: longest standstill; "
            "non-actionable = dv_max < 2 m/s, no stop >= 1 s, RC drop <= 5 points. Each row is "
            "one execution on one road (n = 1): there is no sample to give an interval."
        )
        return _print_and_write(args, {"nonactionable": (title, table)}, note)
    args.suite = args.suite or SUITE_ID
    args.family = args.family or dg.DISTANCE_FAMILY
    args.routes = dg.DISTANCE_ROUTES if args.routes is None else args.routes
    args.window = dg.DISTANCE_WINDOW_S if args.window is None else args.window
    if args.routes < 1:
        raise UsageError(f"--routes must be >= 1 (got {args.routes})")
    if not (math.isfinite(args.window) and args.window > 0):
        raise UsageError(f"--window must be a finite number of seconds > 0 (got {args.window})")
    suite = _load_suite(args)
    available = sum(p.family == args.family for p in suite.pairs)
    if args.routes > available:
        raise UsageError(f"--routes {args.routes}: suite {suite.suite_id} has {available} "
                         f"{args.family} pairs")  # fmt: skip
    _stage(args, f"{policy}: near vs far {args.family} warning on Route B of {suite.suite_id}")
    try:
        open_loop, closed_loop = dg.distance_table(
            policy, suite, family=args.family, routes=args.routes, window_s=args.window
        )
    except ValueError as e:
        raise UsageError(str(e)) from None
    near, far = dg.DISTANCE_POSITIONS["near"], dg.DISTANCE_POSITIONS["far"]
    tables = {
        "distance": (
            f"Distance-conditioned warning  ({policy}; Route B, {args.family} template at "
            f"{near} m (near) or {far} m (far) in the ego frame from the warning point): final "
            "predicted progress (m) of the plan at the warning point",
            open_loop,
        ),
        "distance_closed_loop": (
            f"Same runs in closed loop (warning window {args.window:.1f} s)",
            closed_loop,
        ),
    }
    from lantern_jax.report import interval_display, interval_note

    summary = dg.distance_summary(open_loop)
    tables["distance_summary"] = (
        f"Over the {len(open_loop)} routes: mean predicted progress (m) and retention",
        summary,
        interval_display(summary, dg.DISTANCE_COLUMNS, "Routes"),
    )
    note = (
        f"Retention = far / no-warning predicted progress. Summary: {interval_note(over='routes')}."
    )
    return _print_and_write(args, tables, note)


# ---------------------------------------------------------------------------------------------
# parser
# ---------------------------------------------------------------------------------------------
def _add_cache_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not keep compiled programs between runs (default: kept in "
        f"$XDG_CACHE_HOME/lantern-jax/jax; ${CACHE_DIR_ENV} moves it)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lantern-jax``."""
    parser = argparse.ArgumentParser(
        prog="lantern-jax",
        description="LANTERN cooperative-warning driving benchmark (JAX, batched).",
        allow_abbrev=False,
    )
    families_option.add_option(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    ev = sub.add_parser(
        "evaluate",
        allow_abbrev=False,
        help="evaluate policies on a suite and write the result tables",
        description="Evaluate policies on a suite (Route A with and without warning, Route B), "
        "print the per-family CUS and decomposition tables and write them with the route-level "
        "CSV, its schema and a reproducibility manifest.",
    )
    ev.add_argument(
        "--policy",
        action="append",
        metavar="NAME",
        help="policy name, comma-separated names or 'all' (= expert, ego, coop; the default); "
        "may be repeated",
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
        "--pairs-per-family", type=int, metavar="N", help="only the first N pairs of each family"
    )
    ev.add_argument("--pairs", action="append", metavar="ID[,ID...]", help="only these pair ids")
    ev.add_argument(
        "--out",
        metavar="DIR",
        help="output folder (default: results); the result set replaces an earlier one there "
        "as a whole, other entries of the folder are kept",
    )
    ev.add_argument("--quiet", action="store_true", help="no progress bar or stage lines")
    ev.add_argument(
        "--bootstrap-seed",
        type=int,
        metavar="N",
        help="seed of the pair-level bootstrap behind every interval (default: the project's "
        "fixed seed, lantern_jax.scoring.uncertainty.SEED); recorded in the manifest",
    )
    ev.add_argument(
        "--fresh-suites",
        type=int,
        metavar="K",
        help="also generate K fresh suites (the --suite's design and validator, seeds S .. "
        "S + K - 1 from --seed), evaluate --suite and each of them, and report every suite's "
        "tables and the mean and spread across suites (OUT/across_suites.md)",
    )
    ev.add_argument(
        "--seed",
        type=int,
        metavar="S",
        help="generation seed of the first fresh suite (with --fresh-suites)",
    )
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
        "--coordinator",
        metavar="HOST:PORT",
        help="run across processes with JAX's distributed runtime: address of process 0 "
        "(with --num-processes and --process-id; process 0 writes the results)",
    )
    ev.add_argument("--num-processes", type=int, metavar="N", help="processes in the run")
    ev.add_argument("--process-id", type=int, metavar="I", help="this process, 0 .. N-1")
    ev.add_argument(
        "--config",
        metavar="TOML",
        help="experiment file with an [evaluate] table (e.g. configs/quick.toml); options "
        "given on the command line win over it",
    )
    _add_cache_flag(ev)
    ev.set_defaults(func=cmd_evaluate)

    su = sub.add_parser(
        "suite",
        allow_abbrev=False,
        help="list, verify or regenerate a suite",
        description="Inspect a suite manifest (default: list its pairs), check that it "
        "regenerates from its seed, or generate a fresh manifest.",
    )
    su.add_argument("--list", action="store_true", help="list pairs, hash and generation report")
    su.add_argument(
        "--verify", action="store_true", help="regenerate from the seed and compare every hash"
    )
    su.add_argument("--regenerate", metavar="PATH", help="write a freshly generated manifest")
    su.add_argument("--seed", type=int, help="generation seed for --regenerate")
    su.add_argument(
        "--validator",
        metavar="POLICY",
        help="policy of the dynamic validation for --regenerate (default: the one that "
        "filtered --suite, as its manifest records; expert-v1 for lantern-v3)",
    )
    su.add_argument(
        "--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or manifest path"
    )
    su.add_argument("--quiet", action="store_true", help="no stage lines")
    _add_cache_flag(su)
    su.set_defaults(func=cmd_suite)

    po = sub.add_parser("policies", help="list registered policies", allow_abbrev=False)
    po.set_defaults(func=cmd_policies)
    ab = sub.add_parser(
        "ablations",
        allow_abbrev=False,
        help="list the protocol ablations, or run the ablation table for a policy",
        description="Without --policy (or with --list): list the protocol ablations. With "
        "--policy NAME: evaluate the policy under the full temporal protocol and each of the "
        "five variants, print the paper's ablation table (CUS, A-Prog., Event Exp., Ant., "
        "Rec., Coll.-A, Block-A; warning condition) and write it with every variant's "
        "route-level rows.",
    )
    ab.add_argument("--list", action="store_true", help="list the ablations and exit")
    ab.add_argument("--policy", metavar="NAME", help="run the table for this policy")
    ab.add_argument(
        "--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or manifest path"
    )
    ab.add_argument(
        "--pairs-per-family", type=int, metavar="N", help="only the first N pairs of each family"
    )
    ab.add_argument("--pairs", action="append", metavar="ID[,ID...]", help="only these pair ids")
    ab.add_argument(
        "--out",
        default="results/ablations",
        metavar="DIR",
        help="output folder "
        "(default: results/ablations; the set replaces an earlier one there as a whole)",
    )
    ab.add_argument("--quiet", action="store_true", help="no progress bar or stage lines")
    ab.set_defaults(func=cmd_ablations)
    stress_command.add_parser(sub)
    compare_command.add_parser(sub)
    dataset_command.add_parser(sub)
    train_command.add_parser(sub)
    unseen_command.add_parser(sub)
    _add_language_commands(sub)
    return parser


def _add_language_commands(sub) -> None:
    """``wording`` and ``diagnostics`` (paper appendices on warning language)."""
    wo = sub.add_parser(
        "wording",
        allow_abbrev=False,
        help="warning wording by ambiguity tier (paraphrase vs canonical CUS)",
        description="Run a policy on the suite with the canonical warnings and with held-out "
        "paraphrases of three ambiguity tiers (three disjoint thirds of the suite), print and "
        "write the paraphrase CUS, matched canonical CUS, retention and collision rate per tier.",
    )
    wo.add_argument("--policy", metavar="NAME", help=f"policy (default: {ONE_POLICY_DEFAULT})")
    wo.add_argument(
        "--checkpoint", metavar="PATH", help="a saved learned model (instead of --policy)"
    )
    wo.add_argument("--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or path")
    wo.add_argument(
        "--pairs-per-family", type=int, metavar="N", help="only the first N pairs of each family"
    )
    wo.add_argument("--out", default="results/language", metavar="DIR", help="output folder")
    wo.add_argument("--quiet", action="store_true", help="no stage lines")
    wo.set_defaults(func=cmd_wording, pairs=None)

    dg = sub.add_parser(
        "diagnostics",
        allow_abbrev=False,
        help="non-actionable, distance-conditioned and language-sensitivity diagnostics",
        description="nonactionable: the paper's five non-actionable warnings on an empty road "
        "(max additional speed reduction, longest stop, route completion, criterion). "
        "distance: a family's warning at a near vs a far ego-frame position on Route B "
        "(final predicted progress; closed-loop speed, stop and completion). "
        "language: the warning condition with the delivered text, another family's text at the "
        "same position, an empty text and no warning (CUS per family, share of the gain kept).",
    )
    dg.add_argument(
        "which", choices=("nonactionable", "distance", "language"), help="which diagnostic"
    )
    dg.add_argument("--policy", metavar="NAME", help=f"policy (default: {ONE_POLICY_DEFAULT})")
    dg.add_argument(
        "--checkpoint", metavar="PATH", help="a saved learned model (instead of --policy)"
    )
    dg.add_argument(
        "--suite", metavar="ID|PATH", help=f"suite (distance, language; default: {SUITE_ID})"
    )
    dg.add_argument(
        "--pairs-per-family",
        type=int,
        metavar="N",
        help="only the first N pairs of each family (language)",
    )
    dg.add_argument(
        "--family", choices=FAMILIES, help="family (distance; default: diagnostics.DISTANCE_FAMILY)"
    )
    dg.add_argument(
        "--routes", type=int, metavar="N",
        help="Route B count (distance; default: diagnostics.DISTANCE_ROUTES)",
    )  # fmt: skip
    dg.add_argument(
        "--window", type=float, metavar="S",
        help="warning window, s (distance; default: diagnostics.DISTANCE_WINDOW_S)",
    )  # fmt: skip
    dg.add_argument("--out", default="results/language", metavar="DIR", help="output folder")
    dg.add_argument("--quiet", action="store_true", help="no stage lines")
    dg.set_defaults(func=cmd_diagnostics, pairs=None)


#: Set by the command line's Ctrl-C handler; see :func:`check_interrupt`.
_SIGINT_SEEN = False


def _on_sigint(signum, frame) -> None:
    """SIGINT handler of the command line: remember the interrupt, then raise it as usual."""
    global _SIGINT_SEEN
    _SIGINT_SEEN = True
    raise KeyboardInterrupt


def check_interrupt() -> None:
    """Raise ``KeyboardInterrupt`` if Ctrl-C was pressed during this command.

    Python raises the interrupt wherever the main thread next runs Python code; when that is a
    finalizer run on the way back from a long native call (an XLA compile), the exception is
    printed as "ignored" and lost, and the command would go on to write its results.  The
    command line checks this flag at its stage boundaries and before it writes anything.
    """
    if _SIGINT_SEEN:
        raise KeyboardInterrupt


def _interrupted(exit_process: bool) -> int:
    print("lantern-jax: interrupted", file=sys.stderr)
    if exit_process:
        # XLA compiles on its own threads; a Ctrl-C unwinds Python while a compile is still
        # running there, and normal interpreter shutdown then destroys the XLA client under
        # that thread (a segmentation fault).  Leave without the shutdown: nothing of ours is
        # left to flush (a staged result set was already discarded on the way out).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


class _StdoutError(Exception):
    """Standard output could not be written (the ``OSError`` is the cause)."""


class _GuardedStdout:
    """Standard output during a command: a failed write or flush raises :class:`_StdoutError`,
    so that it is told apart from a failure to write a result file."""

    def __init__(self, stream) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        """Write to the stream; see the class docstring."""
        try:
            return self._stream.write(text)
        except OSError as e:
            raise _StdoutError from e

    def flush(self) -> None:
        """Flush the stream; see the class docstring."""
        try:
            self._stream.flush()
        except OSError as e:
            raise _StdoutError from e

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _detach_stdout() -> None:
    """Point standard output at the null device, so that the interpreter's own last flush of
    what is left in the buffer does not fail again with a second report."""
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, sys.stdout.fileno())
        os.close(fd)
    except (OSError, ValueError):  # no file descriptor (output captured in memory)
        pass


def main(argv: Sequence[str] | None = None, exit_on_interrupt: bool | None = None) -> int:
    """Run the command line; returns the exit code.

    Args:
        argv: the arguments (default: ``sys.argv[1:]``).
        exit_on_interrupt: on Ctrl-C, end the process at once with exit code 130 instead of
            returning it (default: when ``argv`` is not given, i.e. when run as the program).
    """
    global _SIGINT_SEEN
    try:
        expose_cpu_cores()
    except UsageError as e:
        print(f"lantern-jax: error: {e}", file=sys.stderr)
        return 2
    if exit_on_interrupt is None:
        exit_on_interrupt = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    _SIGINT_SEEN = False
    installed, previous = False, None
    if threading.current_thread() is threading.main_thread():
        previous, installed = signal.signal(signal.SIGINT, _on_sigint), True
    stdout = sys.stdout
    sys.stdout = _GuardedStdout(stdout)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, or an argparse usage error (already printed)
            return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
        try:
            families_option.load(args.families)
            if hasattr(args, "no_compile_cache"):
                configure_compile_cache(not args.no_compile_cache)
            if getattr(args, "coordinator", None) or getattr(args, "num_processes", None):
                initialize_distributed(args)
            code = args.func(args, argv)
            check_interrupt()  # an interrupt that was raised but swallowed on the way
            sys.stdout.flush()  # a full disk or a closed pipe is reported here, not at exit
            return code
        except (UsageError, CommandError) as e:
            print(f"lantern-jax {args.command}: error: {e}", file=sys.stderr)
            return 2
    except KeyboardInterrupt:
        return _interrupted(exit_on_interrupt)
    except _StdoutError as e:
        sys.stdout = stdout
        _detach_stdout()
        if isinstance(e.__cause__, BrokenPipeError):  # the reader left (``| head -1``)
            return EXIT_STDOUT_CLOSED
        why = getattr(e.__cause__, "strerror", None) or e.__cause__
        print(f"lantern-jax: error: cannot write to standard output ({why})", file=sys.stderr)
        return 1
    finally:
        sys.stdout = stdout
        if installed:
            signal.signal(
                signal.SIGINT, signal.default_int_handler if previous is None else previous
            )


if __name__ == "__main__":
    sys.exit(main())
