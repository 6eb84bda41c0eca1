"""Third-party import noise kept out of the user's terminal.

Importing brax imports MuJoCo's MJX, which prints ``Failed to import warp: ...`` and ``Failed
to import mujoco_warp: ...`` to standard output when the optional NVIDIA Warp package is not
installed (it is not needed here: the environment runs on JAX).  :func:`filtered_stdout` drops
exactly those lines and passes everything else through, so nothing of this project's or of any
other package's output is hidden.
"""

from __future__ import annotations

import contextlib
import io
import sys
from collections.abc import Iterator

#: Beginnings of the lines of standard output that :func:`filtered_stdout` drops.
KNOWN_NOISE = ("Failed to import warp:", "Failed to import mujoco_warp:")


@contextlib.contextmanager
def filtered_stdout(noise: tuple[str, ...] = KNOWN_NOISE) -> Iterator[None]:
    """Run the block with standard output captured, then print every captured line that does
    not start with one of ``noise``."""
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            yield
    finally:
        kept = [line for line in buf.getvalue().splitlines(keepends=True)
                if not line.startswith(noise)]  # fmt: skip
        if kept:
            sys.stdout.write("".join(kept))
