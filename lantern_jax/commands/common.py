"""What several commands share: stage lines, the policies, checkpoints and suite an option
names, output folders, and printing and writing tables.

A message names the option a bad value came from, or the experiment file and key
(:func:`option_source`).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Collection, Iterable, Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.runtime import check_interrupt
from lantern_jax.policies.names import REFERENCE_POLICIES  # what --policy all stands for

#: The policy ``wording`` and ``diagnostics`` run when given neither --policy nor --checkpoint.
ONE_POLICY_DEFAULT = "coop"


def stage(args: argparse.Namespace, msg: str) -> None:
    """Print a stage line ``[lantern-jax] msg`` to standard error (not with ``--quiet``), after
    checking for an interrupt."""
    check_interrupt()
    if not getattr(args, "quiet", False):
        print(f"[lantern-jax] {msg}", file=sys.stderr, flush=True)


def option_source(args: argparse.Namespace, key: str) -> str:
    """Where the value of option ``key`` came from: ``--key`` or ``config FILE: key``."""
    return getattr(args, "sources", {}).get(key) or "--" + key.replace("_", "-")


def split_values(values: Iterable[str] | None) -> list[str]:
    """The names of an option's values: each value split at commas, blanks dropped."""
    return [n.strip() for item in values or [] for n in item.split(",") if n.strip()]


def run_record(argv: Sequence[str]) -> dict:
    """What the run record of a result set says about this command (besides the timings)."""
    return {"command": shlex.join(["lantern-jax", *argv])}


# ---------------------------------------------------------------------------------------------
# policies and checkpoints
# ---------------------------------------------------------------------------------------------
def resolve_policies(names: Sequence[str] | None, source: str = "--policy") -> list[str]:
    """Expand ``all`` and comma-separated lists; register every policy named by its code
    (``file.py:NAME`` or ``package.module:attr``, see
    :func:`~lantern_jax.policies.registry.register_policy_source`); check every name against
    the registry.

    Args:
        names: the values given (each a name or comma-separated names).
        source: where they came from, for the messages (an option or a config key).

    Raises:
        UsageError: naming the unknown policy (or the source that cannot be loaded) and where
            it came from, listing the known ones.
    """
    from lantern_jax.policies.external import is_policy_source
    from lantern_jax.policies.registry import get_policy, policy_names, register_policy_source

    out: list[str] = []
    for name in split_values(names or ["all"]):
        for n in list(REFERENCE_POLICIES) if name == "all" else [name]:
            if n.lower().endswith(".py") and os.path.isfile(n):
                raise UsageError(f"{source}: {_file_without_name(n)}")
            if is_policy_source(n):  # a user's code: file.py:NAME or package.module:attr
                try:
                    n = register_policy_source(n)
                except (ValueError, TypeError) as e:
                    raise UsageError(f"{source}: {e}") from None
            try:
                get_policy(n)
            except KeyError:
                raise UsageError(
                    f"{source}: unknown policy {n!r}; known policies: "
                    f"{', '.join(policy_names())} (or 'all' = {', '.join(REFERENCE_POLICIES)})"
                    f"{_path_hint(names)}"
                ) from None
            if n not in out:
                out.append(n)
    if not out:
        raise UsageError(f"{source}: no policy given")
    return out


def _file_without_name(path: str) -> str:
    """What to say about a policy file given without ``:NAME``."""
    from lantern_jax.policies.external import policies_in_file

    try:
        found = policies_in_file(path)
    except ValueError as e:
        return str(e)
    listed = (f"it defines {', '.join(found)} (e.g. {path}:{found[0]})" if found else
              "it defines no Policy object")  # fmt: skip
    return f"a policy file is given as {path}:NAME, NAME the Policy to evaluate; {listed}"


def _path_hint(values: Sequence[str] | None) -> str:
    """A hint when a value looks like a policy file whose path holds ``,`` or ``:`` (commas
    separate policies, the colon separates the file from its NAME)."""
    looks = [v for v in values or () if ".py" in v.lower() or "/" in v]
    if not looks:
        return ""
    return ("; a policy file is given as path/to/file.py:NAME, and its path may hold no ',' or "
            "':' (commas separate policies, the colon ends the path)")  # fmt: skip


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
    from lantern_jax.policies.learned.checkpoint import CheckpointError, CheckpointNameTaken
    from lantern_jax.policies.registry import register_checkpoint

    names = []
    for value in split_values(paths):
        name, path = _checkpoint_item(value)
        try:
            names.append(register_checkpoint(path, name))
        except CheckpointError as e:
            hint = ""
            if name is None and isinstance(e, CheckpointNameTaken):
                hint = f" (name it where you give it: {source} OTHER_NAME={path})"
            raise UsageError(f"{source}: {e}{hint}") from None
    if paths is not None and not names:
        raise UsageError(f"{source}: no checkpoint given (leave the option out for none)")
    return names


def one_policy(args: argparse.Namespace) -> str:
    """The one policy of ``wording`` / ``diagnostics``: ``--checkpoint`` or ``--policy`` (default
    :data:`ONE_POLICY_DEFAULT`), never both.

    Raises:
        UsageError: for both options, an unknown policy or more than one.
    """
    if args.checkpoint is not None:
        if args.policy is not None:
            raise UsageError("--policy and --checkpoint: give one of them (a checkpoint is the "
                             "policy that is run)")  # fmt: skip
        return register_checkpoints([args.checkpoint])[0]
    names = resolve_policies([args.policy or ONE_POLICY_DEFAULT])
    if len(names) != 1:
        raise UsageError(f"--policy: give one policy name, got {', '.join(names)}")
    return names[0]


def add_one_policy(parser: argparse.ArgumentParser) -> None:
    """``--policy`` and ``--checkpoint`` of a command that runs one policy (:func:`one_policy`)."""
    parser.add_argument("--policy", metavar="NAME", help=f"policy (default: {ONE_POLICY_DEFAULT})")
    parser.add_argument(
        "--checkpoint", metavar="PATH", help="a saved learned model (instead of --policy)"
    )


# ---------------------------------------------------------------------------------------------
# the suite
# ---------------------------------------------------------------------------------------------
def load_selected_suite(args: argparse.Namespace):
    """The suite of ``--suite``, cut to ``--pairs`` and ``--pairs-per-family`` where the command
    has them and they are given.

    Raises:
        UsageError: naming the option (or config key) for an unknown or invalid suite, an empty
            or unknown pair selection, a pair count below 1, or a suite left without pairs.
    """
    from lantern_jax.scenarios.suite import SuiteError, load_suite

    try:
        suite = load_suite(args.suite)
    except FileNotFoundError as e:
        raise UsageError(f"{option_source(args, 'suite')}: " + str(e).strip("'\"")) from None
    except SuiteError as e:
        raise UsageError(str(e)) from None
    given = getattr(args, "pairs", None)
    if given is not None:
        suite = _select_pairs(suite, given, option_source(args, "pairs"))
    n = getattr(args, "pairs_per_family", None)
    if n is not None:
        if n < 1:
            raise UsageError(f"{option_source(args, 'pairs_per_family')} must be >= 1 (got {n})")
        suite = suite.subset(n)
    if len(suite) == 0:
        raise UsageError(f"suite {suite.suite_id!r} has no pairs")
    return suite


def _select_pairs(suite, given: Sequence[str], source: str):
    """The pairs of ``suite`` that ``--pairs`` names (``source``: where they came from)."""
    pairs = split_values(given)
    if not pairs:
        raise UsageError(f"{source}: no pair id given (leave the option out for every pair)")
    try:
        return suite.select(pairs)
    except KeyError as e:
        raise UsageError(f"{source}: " + str(e).strip("'\"")) from None
    except ValueError as e:
        raise UsageError(f"{source}: {e}") from None


# ---------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------
def check_out(out: str, source: str = "--out", in_place: bool | None = None,
              owned: Collection[str] = ()) -> None:  # fmt: skip
    """Refuse an output folder that cannot receive the result set, before anything runs.

    Args:
        out: the folder.
        source: where it came from (an option or a config key), for the message.
        in_place: whether the files are written into the folder itself (a dataset or a training
            run, resumed there); default: as the result set's writer decides
            (:func:`lantern_jax.io.files.check_target_folder`).
        owned: the names of the files the command writes there (an entry of one of those
            names that is not a regular file is refused).

    Raises:
        UsageError: naming the option (or config key) and why.
    """
    from lantern_jax.io.files import OutputFolderError, check_target_folder

    try:
        check_target_folder(out, in_place=in_place, owned=owned)
    except OutputFolderError as e:
        raise UsageError(f"{source}: {e}") from None


def write_failed(out: str | os.PathLike, error: OSError) -> int:
    """Report result files that could not be written into ``out``; returns the exit code 1."""
    print(f"lantern-jax: error: cannot write results to {out}: {error}", file=sys.stderr)
    return 1


def files_count(n: int) -> str:
    """``"1 file"``, ``"N files"``."""
    return f"{n} file" if n == 1 else f"{n} files"


def list_written(paths: Iterable[str | os.PathLike]) -> None:
    """Print ``Wrote N files:`` (``Wrote 1 file:``) and the files, one a line."""
    paths = list(paths)
    print(f"Wrote {files_count(len(paths))}:")
    for path in paths:
        print(f"  {path}")


def write_and_list(tables: dict, out: str) -> int:
    """Write ``name.csv`` and ``name.md`` for every ``name: (title, table)`` into ``out`` as one
    set (:func:`lantern_jax.report.write_tables`) and list the files; returns the exit
    code (1 when they cannot be written)."""
    from lantern_jax.report import write_tables

    try:
        paths = write_tables(tables, out)
    except OSError as e:
        return write_failed(out, e)
    list_written(paths)
    return 0


def print_and_write(tables: dict, out: str, note: str) -> int:
    """Print every ``name: (title, table[, display])`` (the display table, when given, instead
    of the table) and the ``note``, then write them as CSV + Markdown into ``out``
    (:func:`write_and_list`); returns the exit code."""
    from tabulate import tabulate

    from lantern_jax.report import MISSING, missing_shown

    for title, df, *display in tables.values():
        print(title)
        print(tabulate(missing_shown(display[0] if display else df), headers="keys",
                       showindex=False, floatfmt=".1f", disable_numparse=bool(display),
                       missingval=MISSING))  # fmt: skip
        print()
    if note:
        print(note)
    return write_and_list(tables, out)
