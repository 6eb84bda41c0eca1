"""The XLA flags of every test process, apart from ``conftest.py`` so that ``.ci/run`` can read
them without importing JAX (``python tests/xla_flags.py`` prints them).

XLA's CPU backend with its earlier fusion emitters compiles the world's programs in about 30 %
less time (the split path's world tick 6.3-8.1 s against 9.2-10.1 s on a 2-core CPU) for a
rollout up to about 20 % slower, and the tests' time is mostly compiling
(docs/reproducibility.md).  Results agree with the default emitters' within float rounding
(``REPRODUCIBLE_ATOL``).  The XLA of jaxlib 0.11 (the first jaxlib for Python 3.12 only) no
longer has the flag, and an unknown flag in ``XLA_FLAGS`` ends the process when JAX starts its
backend (seen with jaxlib 0.11.2): there the tests run XLA's default emitters.

The option's name and the jaxlib that dropped it have one home,
:mod:`lantern_jax.core.xla_options` (which the package's stress programs also compile with); it
is loaded here from its file, since importing the package would set JAX up before the tests'
flags are in place.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

_SPEC = importlib.util.spec_from_file_location(
    "_lantern_xla_options",
    Path(__file__).resolve().parents[1] / "lantern_jax" / "core" / "xla_options.py",
)
xla_options = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(xla_options)

#: The flag, where the installed jaxlib's XLA has it.
EARLIER_EMITTERS = f"--{xla_options.EARLIER_EMITTERS_OPTION}=false"


def xla_flags_for_tests() -> str:
    """The tests' XLA flags for the installed jaxlib ("" where it has none of them)."""
    return EARLIER_EMITTERS if xla_options.has_earlier_emitters() else ""


if __name__ == "__main__":
    print(xla_flags_for_tests())
