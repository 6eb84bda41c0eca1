"""glibc's allocator set to keep freed memory for reuse: what makes training steps fast on a CPU.

XLA's CPU runtime allocates each execution's temporary buffer afresh (one block, freed when the
execution ends).  A training step of the rig models at batch 256 needs 43.7 MB of it.  glibc's
``malloc`` serves a block that large with a fresh ``mmap`` (past its 32 MB ceiling for the
dynamic threshold) and returns it with ``munmap``; in XLA's worker threads, whose arenas live in
64 MB heaps, it deletes a heap as soon as it is empty.  Every step then writes to new pages, and
the kernel zeroes each one on its first touch: a training run spent about 40 % of its CPU time
in the kernel (the base rig stage, two epochs, alone on a 2-core CPU: 11.7 million page faults,
26-30 s of system time against 43-46 s of user time; ``docs/performance.md``).

:func:`keep_freed_memory` sets three of glibc's ``mallopt`` parameters, so that freed blocks stay
in the process and the next step reuses them:

* ``M_MMAP_MAX = 0``: no block is served by its own ``mmap`` (a block too large for a thread's
  heap still is: glibc falls back to ``mmap`` then);
* ``M_TOP_PAD`` = :data:`TOP_PAD_BYTES`: a heap grows by that much more than it needs, and
  glibc keeps an empty heap rather than deleting it;
* ``M_TRIM_THRESHOLD`` = :data:`TRIM_THRESHOLD_BYTES`: the free memory at a heap's top is never
  given back.

The price is memory the process does not return before it ends: its resident size stays at its
peak, and the peak grows a little (2.34-2.36 GB to 2.64 GB for that stage).  So only the
training entry points set it (:func:`lantern_jax.apps.training.behaviour_cloning.train`, hence
``lantern-jax train``), never ``import lantern_jax``.  The numbers a run computes do not
change (the same weights, bit for bit: ``tests/test_allocator.py``).

Elsewhere than glibc (macOS, musl) it does nothing and says so.  ``LANTERN_JAX_MALLOC=system``
leaves glibc's defaults (and so do glibc's own ``MALLOC_*_`` variables or ``GLIBC_TUNABLES``
when they name one of these parameters: the user's choice wins).
"""

from __future__ import annotations

import ctypes
import functools
import os
import platform

#: Environment variable: ``system`` leaves the allocator's defaults; unset or ``keep`` sets
#: :func:`keep_freed_memory`'s parameters.
MALLOC_ENV = "LANTERN_JAX_MALLOC"
MALLOC_CHOICES = ("keep", "system")

#: glibc's ``mallopt`` parameter numbers (``malloc.h``).
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_MAX = -4

#: bytes a heap grows by beyond a request; also what makes glibc keep an empty thread heap (a
#: heap is deleted only when the heap before it has this much room).  128 MiB: more than a
#: thread heap's 64 MiB, so no thread heap is ever deleted.
TOP_PAD_BYTES = 128 * 1024 * 1024
#: bytes of free memory at a heap's top past which glibc gives it back: the largest value
#: ``mallopt`` takes (an ``int``), i.e. never.
TRIM_THRESHOLD_BYTES = 2**31 - 1

#: glibc's own ways to set these parameters; when the environment uses one, it wins.
GLIBC_VARIABLES = ("MALLOC_MMAP_MAX_", "MALLOC_TOP_PAD_", "MALLOC_TRIM_THRESHOLD_",
                   "MALLOC_MMAP_THRESHOLD_")  # fmt: skip
GLIBC_TUNABLE_NAMES = ("glibc.malloc.mmap_max", "glibc.malloc.top_pad",
                       "glibc.malloc.trim_threshold", "glibc.malloc.mmap_threshold")  # fmt: skip

class AllocatorError(ValueError):
    """``$LANTERN_JAX_MALLOC`` holds a value other than ``keep`` or ``system``."""


def malloc_choice() -> str:
    """``$LANTERN_JAX_MALLOC``: ``keep`` (the default) or ``system``.

    Raises:
        AllocatorError: naming the variable and its value, for any other value.
    """
    value = os.environ.get(MALLOC_ENV, "keep").strip().lower() or "keep"
    if value not in MALLOC_CHOICES:
        raise AllocatorError(f"{MALLOC_ENV}={os.environ[MALLOC_ENV]!r}: expected one of "
                             f"{', '.join(MALLOC_CHOICES)}")  # fmt: skip
    return value


def _user_set() -> str | None:
    """The environment variable through which the user already set glibc's parameters, or
    None."""
    for name in GLIBC_VARIABLES:
        if name in os.environ:
            return name
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    if any(name in tunables for name in GLIBC_TUNABLE_NAMES):
        return "GLIBC_TUNABLES"
    return None


@functools.cache  # once per process (a raised AllocatorError is not cached)
def keep_freed_memory() -> str:
    """Set glibc's allocator to keep freed memory for reuse (the module's docstring says why);
    once per process: later calls return what the first did.

    Returns:
        What was done, in words: ``"kept"``, or why nothing was (``LANTERN_JAX_MALLOC=system``,
        the user's own glibc variables, not glibc, or ``mallopt`` refused).

    Raises:
        AllocatorError: ``$LANTERN_JAX_MALLOC`` holds another value than ``keep`` or ``system``.
    """
    if malloc_choice() == "system":
        return f"left to the system ({MALLOC_ENV}=system)"
    if (name := _user_set()) is not None:
        return f"left as {name} sets it"
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return "left to the system (not glibc)"
    return _mallopt()


def _mallopt() -> str:
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return "left to the system (no mallopt)"
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    for param, value in ((M_MMAP_MAX, 0), (M_TOP_PAD, TOP_PAD_BYTES),
                         (M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)):  # fmt: skip
        if mallopt(param, value) != 1:  # glibc returns 1 on success
            return f"left to the system (mallopt refused parameter {param})"
    return "kept"
