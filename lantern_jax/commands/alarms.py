"""XLA's slow-operation alarms kept out of the user's terminal.

XLA's compiler logs, on standard error and from C++ (out of reach of Python's ``logging`` and
``warnings``), an alarm when a compilation or a constant folding takes long::

    E1126 13:27:16.559406    8585 slow_operation_alarm.cc:73]
    ********************************
    [Compiling module jit_one for CPU] Very slow compile? If you want to file a bug, run with
    envvar XLA_FLAGS=--xla_dump_to=/tmp/foo and attach the results.
    ********************************

It asks for a bug report and says nothing a user can act on (the command line prints its own
``compiling`` stage, and ``--profile`` the compile time); XLA has no option to turn it off.
While a command runs, :class:`AlarmFilter` routes file descriptor 2 through a pipe and drops
exactly those blocks — from a line naming ``slow_operation_alarm.cc`` to the line that ends
with XLA's "attach the results." and its closing row of stars, at most :data:`MAX_BLOCK_LINES`
lines — and passes every other byte through at once (progress bars included), so no warning of
this project or of any other package is hidden.  ``LANTERN_JAX_SHOW_XLA_ALARMS=1`` turns the
filter off.
"""

from __future__ import annotations

import os
import re
import sys
import threading

#: What names an alarm's first line.
ALARM = b"slow_operation_alarm.cc"
#: The end of the text of an alarm block.
BLOCK_END = b"attach the results."
#: Most lines one alarm block is allowed to drop (a safety bound: text after it passes).
MAX_BLOCK_LINES = 40
#: Environment variable that turns the filter off (``1``).
SHOW_ENV = "LANTERN_JAX_SHOW_XLA_ALARMS"
#: A partial line that may be the start of an absl log line ("E1126 ...") is held back until
#: its end is known; any other partial output (a progress bar's ``\r`` update) passes at once.
_LOG_PREFIX = re.compile(rb"^[EWIF]\d{0,4}(\s|$)|^[EWIF]\d{4}")

_ACTIVE: AlarmFilter | None = None


class AlarmFilter:
    """Context manager: standard error (file descriptor 2) through a filter that drops XLA's
    slow-operation alarms while the block runs (see the module docstring)."""

    def __init__(self, fd: int = 2) -> None:
        self.fd = fd
        self.dropped = 0  # alarm blocks dropped
        self._saved: int | None = None
        self._thread: threading.Thread | None = None
        self._state = "pass"  # "pass", "block" (inside an alarm) or "tail" (after its end)
        self._block_lines = 0

    def __enter__(self) -> AlarmFilter:
        global _ACTIVE
        if os.environ.get(SHOW_ENV, "").strip() == "1" or _ACTIVE is not None:
            return self
        sys.stderr.flush()
        read_end, write_end = os.pipe()
        self._saved = os.dup(self.fd)
        os.dup2(write_end, self.fd)
        os.close(write_end)
        self._thread = threading.Thread(target=self._pump, args=(read_end,), daemon=True,
                                        name="xla-alarm-filter")  # fmt: skip
        self._thread.start()
        _ACTIVE = self
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Restore standard error and forward everything written before (idempotent)."""
        global _ACTIVE
        if self._saved is None:
            return
        try:
            sys.stderr.flush()
        except (OSError, ValueError):
            pass
        os.dup2(self._saved, self.fd)  # the pipe's last write end closes: the pump sees EOF
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        os.close(self._saved)
        self._saved, self._thread = None, None
        if _ACTIVE is self:
            _ACTIVE = None

    # -- the pump (its own thread) --------------------------------------------------------------
    def _pump(self, read_end: int) -> None:
        held = b""
        try:
            while chunk := os.read(read_end, 1 << 16):
                held = self._feed(held + chunk)
            if held:
                self._line(held)
        finally:
            os.close(read_end)

    def _feed(self, data: bytes) -> bytes:
        """Handle every complete line of ``data`` (ended by ``\\n`` or ``\\r``); returns the
        partial line left, or nothing when it could not start an alarm (written at once)."""
        start = 0
        for m in re.finditer(rb"[\r\n]", data):
            self._line(data[start : m.end()])
            start = m.end()
        rest = data[start:]
        if rest and self._state == "pass" and not _LOG_PREFIX.match(rest):
            self._write(rest)
            return b""
        return rest

    def _line(self, line: bytes) -> None:
        if self._state == "tail":
            self._state = "pass"
            if line.strip() and set(line.strip()) == {ord("*")}:
                return  # the block's closing row of stars
        if ALARM in line:
            if self._state == "pass":
                self.dropped += 1
            self._state, self._block_lines = "block", 0
            return
        if self._state == "block":
            self._block_lines += 1
            if BLOCK_END in line:
                self._state = "tail"
            elif self._block_lines >= MAX_BLOCK_LINES:
                self._state = "pass"
            return
        self._write(line)

    def _write(self, data: bytes) -> None:
        saved = self._saved
        if saved is None:
            return
        try:
            os.write(saved, data)
        except OSError:
            pass


def close_active() -> None:
    """Restore standard error now if a filter is active (before the process ends at once)."""
    if _ACTIVE is not None:
        _ACTIVE.close()
