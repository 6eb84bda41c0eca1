"""XLA compile options for the programs whose compile, not their run, is what a user waits for.

XLA's CPU backend with its earlier fusion emitters (``xla_cpu_use_fusion_emitters=false``)
compiles the simulator's programs in about a quarter less time.  Where a program is compiled
for one piece of work and then run only briefly, that is the better trade:

* **a stress cell's programs** (the surrogate's values and gradients, the hard verification):
  one cell, ``ego`` on the first Pedestrian Emergence pair in the 32-dimensional adversary
  space with random search, CMA-ES and gradient search, compiled in 52.2-56.7 s with XLA's
  defaults and in 39.3-40.3 s with these options, while its 48-rollout search took 31.6-33.6
  and 31.7-32.7 s (2-core CPU, jaxlib 0.10.2, two interleaved rounds, docs/performance.md).
  Whatever a search reports is a hard verification's verdict, and the verification's CUS were
  the same bits as under the default options (six catalogued failures re-evaluated by
  ``evaluate``); the surrogate's gradients only steer the search, and differ from the default
  options' by float rounding carried through the soft ticks, so a gradient search can take
  another path.

The fragility radii's program keeps XLA's defaults: its gradients are its result, and with these
options (5-9 s less of compile) they moved the radii by up to 0.4 % (docs/performance.md).

The evaluation's programs keep XLA's defaults: the world program is compiled once per machine
and kept, and its run is what every evaluation waits for (`coop`'s whole-suite split rollout
with the earlier emitters, three interleaved pairs of runs: 50,700 against 53,800, 48,100
against 46,400 and 43,400 against 57,800 scenario-ticks/s, for 2.5 s less of a 10 s compile
paid once).

The XLA of jaxlib 0.11 (the first jaxlib for Python 3.12 only) no longer has the option, and
XLA refuses an option it does not know; there :func:`fast_compile_options` is None and every
program compiles with XLA's defaults, as it does where ``XLA_FLAGS`` names the option.  This
module imports nothing of JAX (the tests' set-up reads it before JAX starts).
"""

from __future__ import annotations

import importlib.metadata
import os

#: XLA's debug option that chooses the CPU backend's fusion emitters.
EARLIER_EMITTERS_OPTION = "xla_cpu_use_fusion_emitters"
#: The first jaxlib release whose XLA does not know :data:`EARLIER_EMITTERS_OPTION`.
WITHOUT_EARLIER_EMITTERS = (0, 11)


def jaxlib_version() -> tuple[int, ...]:
    """The installed jaxlib's release as numbers, e.g. ``(0, 10, 2)`` (read from its metadata,
    without importing it)."""
    text = importlib.metadata.version("jaxlib")
    return tuple(int(p) for p in text.split("+")[0].split(".")[:3] if p.isdigit())


def has_earlier_emitters() -> bool:
    """Whether the installed jaxlib's XLA knows :data:`EARLIER_EMITTERS_OPTION`."""
    return jaxlib_version() < WITHOUT_EARLIER_EMITTERS


def fast_compile_options() -> dict[str, bool] | None:
    """``compiler_options`` for ``jax.jit`` of a program compiled for one piece of work: the
    earlier fusion emitters where the installed jaxlib has them, else None (XLA's defaults).
    Also None where ``XLA_FLAGS`` names the option: the environment's choice wins (e.g.
    ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=true`` compiles every program with XLA's
    default emitters)."""
    if EARLIER_EMITTERS_OPTION in os.environ.get("XLA_FLAGS", ""):
        return None
    return {EARLIER_EMITTERS_OPTION: False} if has_earlier_emitters() else None
