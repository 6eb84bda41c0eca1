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
:func:`lantern_jax.commands.evaluate.load_config`); an option given on the command line always
wins over the file.  Options must be spelled out in full (no abbreviations).

Each command is a module of :mod:`lantern_jax.commands` with its ``add_parser`` and ``cmd_*``
function; this module assembles them (:func:`build_parser`) and runs one (:func:`main`).

Exit codes: 0 success, 1 failure (a policy that fails, results that cannot be written, a suite
that does not regenerate, standard output that cannot be written), 2 usage errors (unknown
policy, ablation, suite or pair; an invalid suite file, checkpoint or config; an empty
selection; an output folder that cannot be written — all found before anything is compiled),
130 interrupted (Ctrl-C), 141 the reader of standard output went away (``| head``).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import os
import sys
from collections.abc import Sequence

from lantern_jax import __version__
from lantern_jax.commands import (
    UsageError,
    ablations,
    alarms,
    compare,
    dataset,
    diagnostics,
    evaluate,
    families,
    plot,
    policies,
    report,
    runtime,
    stress,
    suite,
    train,
    unseen,
    wording,
)
from lantern_jax.commands.runtime import EXIT_INTERRUPTED, EXIT_STDOUT_CLOSED, EXIT_USAGE
from lantern_jax.core import jax_setup

__all__ = [
    "COMMANDS",
    "CPU_DEVICES_ENV",
    "EXIT_INTERRUPTED",
    "EXIT_STDOUT_CLOSED",
    "EXIT_USAGE",
    "UsageError",
    "build_parser",
    "expose_cpu_cores",
    "main",
]

#: The command modules, in the order ``lantern-jax --help`` lists them.  (Their reprs name
#: this machine's paths, so the documentation leaves the value out.)
#:
#: :meta hide-value:
COMMANDS = (
    evaluate, suite, policies, ablations, stress, compare, report, dataset, train, unseen,
    wording, diagnostics, plot,
)  # fmt: skip

#: Environment variable that sets the number of XLA CPU devices of the command line.
CPU_DEVICES_ENV = jax_setup.CPU_DEVICES_ENV


def expose_cpu_cores() -> None:
    """Expose one XLA CPU device per core, so that the evaluator can split its batch over them
    (:func:`lantern_jax.core.jax_setup.expose_cpu_cores`: only before JAX starts, not where
    ``XLA_FLAGS`` already sets a count; ``LANTERN_JAX_CPU_DEVICES`` sets another, e.g. 1).

    The other count variables (:data:`lantern_jax.core.jax_setup.COUNT_ENVS`) are checked
    here too, so a bad one is refused before any work.

    Raises:
        UsageError: when one of those variables is not a whole number >= 1.
    """
    try:
        jax_setup.expose_cpu_cores()
        jax_setup.check_counts()
    except jax_setup.SetupError as e:
        raise UsageError(str(e)) from None


class HelpFormatter(argparse.HelpFormatter):
    """``--help`` that gives every option's default where its help text does not already say
    it (options that default to nothing or are flags show none)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (not action.option_strings or action.default in (None, False, argparse.SUPPRESS)
                or "default" in text):  # fmt: skip
            return text
        return f"{text} (default: %(default)s)".strip()


class OneLineErrors(argparse.ArgumentParser):
    """A parser whose usage errors are one line (``PROG: error: MESSAGE; PROG --help lists the
    options``), exit code 2: the message names the option and the value, and ``--help`` has
    the rest (argparse's own prints the whole usage block first)."""

    def error(self, message: str):  # noqa: D102  (argparse's hook)
        self.exit(2, f"{self.prog}: error: {message}; {self.prog} --help lists the options\n")


class CommandParser(OneLineErrors):
    """The parser of one command: :class:`HelpFormatter` unless the command asks for another."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lantern-jax``: the top-level ``--families`` option and every
    command of :data:`COMMANDS`."""
    parser = OneLineErrors(
        prog="lantern-jax",
        description="LANTERN cooperative-warning driving benchmark (JAX, batched).",
        allow_abbrev=False,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    families.add_option(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                parser_class=CommandParser)  # fmt: skip
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


#: Options that name files or folders (``--policy`` may be ``file.py:NAME``), checked for a name
#: the file system cannot hold before anything runs (:func:`check_path_lengths`).
PATH_OPTIONS = ("out", "suite", "regenerate", "results", "checkpoint", "config", "dataset",
                "families", "policy")  # fmt: skip


def _shown(path: str) -> str:
    """A long path as a message shows it: its start and its length."""
    return repr(path) if len(path) <= 80 else f"'{path[:60]}...' ({len(path)} characters)"


def _too_long(path: str) -> str | None:
    """Why the file system cannot hold ``path`` (a name over its NAME_MAX, the whole over its
    PATH_MAX), or None."""
    try:
        name_max = os.pathconf("/", "PC_NAME_MAX")
        path_max = os.pathconf("/", "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):
        name_max, path_max = 255, 4096
    longest = max((len(os.fsencode(part)) for part in path.split(os.sep)), default=0)
    if longest > name_max:
        return f"a name in it is {longest} bytes, over the file system's {name_max}"
    if len(os.fsencode(path)) >= path_max:
        return f"it is {len(os.fsencode(path))} bytes, over the file system's {path_max}"
    return None


def check_path_lengths(args: argparse.Namespace) -> None:
    """Refuse, before anything runs, a path option (:data:`PATH_OPTIONS`) that no file system
    name can hold.

    Raises:
        UsageError: naming the option, the path's start and why.
    """
    for dest in PATH_OPTIONS:
        value = getattr(args, dest, None)
        values = value if isinstance(value, list | tuple) else [value]
        for v in values:
            parts = v.split(",") if dest == "policy" and isinstance(v, str) else [v]
            for path in (x for x in parts if isinstance(x, str)):
                why = _too_long(path)
                if why:
                    option = "RESULTS" if dest == "results" else f"--{dest}"
                    raise UsageError(f"{option}: {_shown(path)}: too long a path ({why})")


def _run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Check the path options' lengths, load ``--families``, set up the compilation cache and
    the distributed runtime where the command has those options, then run the command; returns
    its exit code."""
    check_path_lengths(args)
    families.load(args.families)
    if hasattr(args, "no_compile_cache"):
        runtime.configure_compile_cache(not args.no_compile_cache, warn=runtime.warn_line)
    if getattr(args, "coordinator", None) or getattr(args, "num_processes", None):
        runtime.initialize_distributed(args)
    code = args.func(args, argv)
    runtime.check_interrupt()  # an interrupt that was raised but swallowed on the way
    sys.stdout.flush()  # a full disk or a closed pipe is reported here, not at exit
    return code


#: How JAX's error begins when the environment asks for a backend it cannot start
#: (``JAX_PLATFORMS`` naming a platform that is not there, ``XLA_FLAGS`` with a device count of
#: 0): reported in one line naming the variables, exit 2.
BACKEND_FAILURE = "Unable to initialize backend"
BACKEND_ENV = ("JAX_PLATFORMS", "XLA_FLAGS")


class _DropCallbackTraceback(logging.Filter):
    """Drops JAX's log record of a failed host callback (the traceback it logs before raising)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(CALLBACK_FAILED_LOGS)


#: how JAX logs a failed host callback (``jax.pure_callback``, ``jax.debug.callback``) before
#: re-raising its error, and the loggers it logs them with
CALLBACK_FAILED_LOGS = ("jax.pure_callback failed", "jax.debug.callback failed")
CALLBACK_LOGGERS = ("jax._src.callback", "jax._src.debugging")


@contextlib.contextmanager
def _quiet_callback_log():
    """While a command runs, JAX's own log of a failed host callback is dropped: the error
    reaches the command, which names it in one line
    (:func:`lantern_jax.policies.failures.explain_failure`)."""
    loggers, drop = [logging.getLogger(n) for n in CALLBACK_LOGGERS], _DropCallbackTraceback()
    for logger in loggers:
        logger.addFilter(drop)
    try:
        yield
    finally:
        for logger in loggers:
            logger.removeFilter(drop)


def main(argv: Sequence[str] | None = None, exit_on_interrupt: bool | None = None) -> int:
    """Run the command line; returns the exit code.

    Args:
        argv: the arguments (default: ``sys.argv[1:]``).
        exit_on_interrupt: on Ctrl-C, end the process at once with exit code 130 instead of
            returning it (default: when ``argv`` is not given, i.e. when run as the program).
    """
    try:
        expose_cpu_cores()
    except UsageError as e:
        print(f"lantern-jax: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    if exit_on_interrupt is None:
        exit_on_interrupt = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    restore_sigint = runtime.catch_interrupts()
    stdout = sys.stdout
    sys.stdout = runtime.GuardedStdout(stdout)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, or an argparse usage error (already printed)
            return e.code if isinstance(e.code, int) else (0 if e.code is None else EXIT_USAGE)
        try:
            # XLA's slow-compile alarms and JAX's log of a failed host callback stay out of the
            # terminal (the callback's error is reported in one line, with its file and line)
            with alarms.AlarmFilter(), _quiet_callback_log():
                return _run(args, argv)
        except UsageError as e:
            print(f"lantern-jax {args.command}: error: {e}", file=sys.stderr)
            return EXIT_USAGE
        except OSError as e:
            if e.errno != errno.ENAMETOOLONG:
                raise
            print(f"lantern-jax {args.command}: error: {_shown(str(e.filename or ''))}: too "
                  "long a path for the file system", file=sys.stderr)  # fmt: skip
            return EXIT_USAGE
        except RuntimeError as e:
            if not str(e).startswith(BACKEND_FAILURE):
                raise
            where = ", ".join(f"{k}={os.environ[k]!r}" for k in BACKEND_ENV if os.environ.get(k))
            print(f"lantern-jax {args.command}: error: JAX could not start its backend "
                  f"({where or 'no JAX_PLATFORMS or XLA_FLAGS set'}): "
                  f"{str(e).splitlines()[0]}", file=sys.stderr)  # fmt: skip
            return EXIT_USAGE
    except KeyboardInterrupt:
        return runtime.interrupted(exit_on_interrupt)
    except runtime.StdoutError as e:
        sys.stdout = stdout
        return runtime.stdout_failed(e)
    finally:
        sys.stdout = stdout
        restore_sigint()


if __name__ == "__main__":
    sys.exit(main())
