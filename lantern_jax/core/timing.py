"""Where the seconds of a command go: a small wall-clock breakdown (``lantern-jax evaluate
--profile``).

:class:`Breakdown` collects labelled phases in the order they ran (nested phases are indented
under their parent) and formats them as a table with each phase's share of the total.  The total
is counted from the start of the Python process when the operating system tells it
(:func:`seconds_since_process_start`, Linux), so interpreter start-up and imports are part of the
picture; elsewhere from the first phase.

Example::

    bd = Breakdown()
    with bd.phase("suite load"):
        suite = load_suite()
    bd.add("compile", 7.3, indent=1)
    print(bd.format())
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from collections.abc import Iterator


def seconds_since_process_start() -> float | None:
    """Wall seconds since this process started (Linux ``/proc``, 10 ms resolution), or None
    where the operating system does not say."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            after_name = f.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime", encoding="ascii") as f:
            uptime_s = float(f.read().split()[0])
        start_ticks = int(after_name[19])  # field 22 of stat(5): starttime, clock ticks
        return max(0.0, uptime_s - start_ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return None


@dataclasses.dataclass
class Phase:
    """One line of a :class:`Breakdown`."""

    label: str
    seconds: float
    indent: int = 0  # 0: a top-level phase (counts towards the sum); 1+: a detail of the last


class Breakdown:
    """Wall-clock phases of one command, in the order they ran.

    Top-level phases (``indent=0``) should not overlap, so that their sum is the time the command
    accounted for; detail lines (``indent >= 1``) split the phase above them.
    """

    def __init__(self) -> None:
        self.phases: list[Phase] = []
        self._since_start_at_creation = seconds_since_process_start()
        self._created = time.perf_counter()

    def add(self, label: str, seconds: float, indent: int = 0) -> None:
        """Record a phase measured elsewhere."""
        self.phases.append(Phase(label, float(seconds), indent))

    @contextlib.contextmanager
    def phase(self, label: str, indent: int = 0) -> Iterator[None]:
        """Time the ``with`` block as one phase."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add(label, time.perf_counter() - t0, indent)

    def before_creation(self, label: str) -> None:
        """Record the time from process start to the creation of this breakdown as a phase
        (interpreter start-up and imports); nothing where the start is unknown."""
        if self._since_start_at_creation is not None:
            self.phases.insert(0, Phase(label, self._since_start_at_creation, 0))

    def total(self) -> float:
        """Wall seconds from process start (or from the breakdown's creation) to now."""
        since = time.perf_counter() - self._created
        return since + (self._since_start_at_creation or 0.0)

    def format(self, title: str = "Where the time went") -> str:
        """The phases as a table: seconds and share of the total wall time, then the rest
        (time between phases) and the total."""
        total = self.total()
        top = sum(p.seconds for p in self.phases if p.indent == 0)
        width = max([len("  " * p.indent + p.label) for p in self.phases] + [32])
        lines = [f"{title}  (wall seconds, share of the total)"]
        for p in self.phases:
            name = "  " * p.indent + p.label
            lines.append(f"{name:<{width}}  {p.seconds:8.2f}  {100 * p.seconds / total:5.1f} %")
        rest = max(0.0, total - top)
        label = "other (between phases)"
        lines.append(f"{label:<{width}}  {rest:8.2f}  {100 * rest / total:5.1f} %")
        lines.append(f"{'total':<{width}}  {total:8.2f}  100.0 %")
        return "\n".join(lines)
