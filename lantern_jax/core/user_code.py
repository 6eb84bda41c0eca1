"""User code is a guest: importing or calling a user's file (a policy, a families file, a
config's code) can neither end, silence nor take over the tool.

:func:`as_guest` runs the code and turns what would end or take over the process into a
:class:`UserCodeError` that names the file and what it did:

* ``sys.exit(...)`` / ``raise SystemExit`` (a script's own ``argparse`` usage error ends this
  way too; during the import ``sys.argv`` is the file's own name alone, so a script that parses
  its arguments sees none rather than the tool's);
* ``KeyboardInterrupt`` raised by the code itself (a real Ctrl-C -- the SIGINT signal -- is
  still a Ctrl-C and passes through);
* any other exception, with its type and message;
* anything the code prints to standard output goes to standard error, each line prefixed with
  the file's name, so that the tool's own output (tables, ``--json``) stays clean.
"""

from __future__ import annotations

import contextlib
import io
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any


class UserCodeError(ValueError):
    """User code ended, interrupted or failed while the tool ran it; the message names the file
    (or object) and what it did."""


@contextlib.contextmanager
def _signal_watch() -> Iterator[dict]:
    """Record whether a real SIGINT arrived (main thread only; elsewhere every
    KeyboardInterrupt counts as real)."""
    seen = {"sigint": threading.current_thread() is not threading.main_thread()}
    if seen["sigint"]:
        yield seen
        return
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        if previous is signal.SIG_IGN:
            return
        seen["sigint"] = True
        if callable(previous):
            previous(signum, frame)
        raise KeyboardInterrupt

    try:
        signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main interpreter
        seen["sigint"] = True
        yield seen
        return
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, previous)


class _PrefixedLines(io.TextIOBase):
    """A text stream that writes every line to standard error behind a prefix."""

    def __init__(self, prefix: str) -> None:
        self.prefix, self.pending = prefix, ""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self.pending += text
        *lines, self.pending = self.pending.split("\n")
        for line in lines:
            print(f"{self.prefix}{line}", file=sys.stderr)
        return len(text)

    def flush(self) -> None:
        if self.pending:
            print(f"{self.prefix}{self.pending}", file=sys.stderr)
            self.pending = ""


def as_guest(what: str, fn: Callable[..., Any], *args: Any, argv0: str | None = None) -> Any:
    """``fn(*args)``, run as user code (the module docstring).

    Args:
        what: how a message names the code, e.g. ``"policy file my_policy.py"``.
        fn: the call (an import, a factory).
        argv0: ``sys.argv`` during the call is ``[argv0]`` (default: unchanged).

    Raises:
        UserCodeError: naming ``what`` when the code exits, raises ``KeyboardInterrupt`` itself,
            or raises any other exception (chained).
        KeyboardInterrupt: for a real Ctrl-C.
    """
    out = _PrefixedLines(f"[{what}] ")
    saved_argv = sys.argv
    with _signal_watch() as seen:
        try:
            if argv0 is not None:
                sys.argv = [argv0]
            with contextlib.redirect_stdout(out):
                return fn(*args)
        except SystemExit as e:
            code = e.code
            raise UserCodeError(
                f"{what}: the code called sys.exit({code!r}) while it was loaded; a file given "
                "to lantern-jax must define things, not run as a script (put script code under "
                "`if __name__ == \"__main__\":`)"
            ) from None
        except KeyboardInterrupt:
            if seen["sigint"]:
                raise
            raise UserCodeError(f"{what}: the code raised KeyboardInterrupt itself") from None
        except Exception as e:  # noqa: BLE001  (the user's code: any failure is theirs)
            raise UserCodeError(f"{what}: {type(e).__name__}: {e}") from e
        finally:
            out.flush()
            sys.argv = saved_argv
