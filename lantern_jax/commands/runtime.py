"""How a command runs in its process: Ctrl-C, standard output, the persistent compilation cache
and JAX's distributed runtime.

:func:`lantern_jax.cli.main` installs the Ctrl-C handler (:func:`catch_interrupts`) and guards
standard output (:class:`GuardedStdout`) around every command; the commands call
:func:`check_interrupt` at their stage boundaries and before they write anything.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Callable

from lantern_jax.commands import UsageError, alarms
from lantern_jax.core import jax_setup

#: Exit code of a usage error.
EXIT_USAGE = 2
#: Exit code of an interrupted command (Ctrl-C).
EXIT_INTERRUPTED = 130
#: Exit code when the reader of standard output has gone (128 + SIGPIPE, as a shell reports a
#: command that a closed pipe stopped).
EXIT_STDOUT_CLOSED = 141

# ---------------------------------------------------------------------------------------------
# Ctrl-C
# ---------------------------------------------------------------------------------------------
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


def catch_interrupts() -> Callable[[], None]:
    """Forget an interrupt of an earlier command and, on the main thread, install the Ctrl-C
    handler that :func:`check_interrupt` reads.

    Returns:
        The function that puts the previous handler back.
    """
    global _SIGINT_SEEN
    _SIGINT_SEEN = False
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGINT, _on_sigint)

    def restore() -> None:
        signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)

    return restore


def interrupted(exit_process: bool) -> int:
    """Report an interrupted command; returns its exit code, or ends the process at once with it
    when ``exit_process``."""
    print("lantern-jax: interrupted", file=sys.stderr)
    if exit_process:
        # XLA compiles on its own threads; a Ctrl-C unwinds Python while a compile is still
        # running there, and normal interpreter shutdown then destroys the XLA client under
        # that thread (a segmentation fault).  Leave without the shutdown: nothing of ours is
        # left to flush (a staged result set was already discarded on the way out).
        sys.stdout.flush()
        sys.stderr.flush()
        alarms.close_active()  # what went to standard error reaches it before the end
        os._exit(EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


# ---------------------------------------------------------------------------------------------
# standard output
# ---------------------------------------------------------------------------------------------
class StdoutError(Exception):
    """Standard output could not be written (the ``OSError`` is the cause)."""


class GuardedStdout:
    """Standard output during a command: a failed write or flush raises :class:`StdoutError`,
    so that it is told apart from a failure to write a result file."""

    def __init__(self, stream) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        """Write to the stream; see the class docstring."""
        try:
            return self._stream.write(text)
        except OSError as e:
            raise StdoutError from e

    def flush(self) -> None:
        """Flush the stream; see the class docstring."""
        try:
            self._stream.flush()
        except OSError as e:
            raise StdoutError from e

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


def stdout_failed(error: StdoutError) -> int:
    """Report standard output that could not be written (with the real stream back in
    ``sys.stdout``); returns the exit code: :data:`EXIT_STDOUT_CLOSED` without a word when the
    reader went away (``| head -1``), else 1."""
    _detach_stdout()
    if isinstance(error.__cause__, BrokenPipeError):
        return EXIT_STDOUT_CLOSED
    why = getattr(error.__cause__, "strerror", None) or error.__cause__
    print(f"lantern-jax: error: cannot write to standard output ({why})", file=sys.stderr)
    return 1


# ---------------------------------------------------------------------------------------------
# compilation cache, distributed runtime
# ---------------------------------------------------------------------------------------------
#: Environment variable that moves the persistent compilation cache of the command line.
CACHE_DIR_ENV = jax_setup.CACHE_DIR_ENV
#: Where the command line keeps compiled programs
#: (:func:`lantern_jax.core.jax_setup.compile_cache_dir`).
compile_cache_dir = jax_setup.compile_cache_dir
#: Turn the persistent compilation cache on or off
#: (:func:`lantern_jax.core.jax_setup.configure_compile_cache`).
configure_compile_cache = jax_setup.configure_compile_cache


def warn_line(message: str) -> None:
    """Print ``lantern-jax: warning: MESSAGE`` on standard error: a problem the command works
    around (a compilation cache folder it cannot use), in one line."""
    print(f"lantern-jax: warning: {message}", file=sys.stderr, flush=True)


def add_cache_flag(parser: argparse.ArgumentParser) -> None:
    """Add ``--no-compile-cache`` to a command that compiles (the command line then configures
    the cache, :func:`configure_compile_cache`, before the command runs)."""
    parser.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not keep compiled programs between runs (default: kept in "
        f"$XDG_CACHE_HOME/lantern-jax/jax; ${CACHE_DIR_ENV} moves it)",
    )


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
