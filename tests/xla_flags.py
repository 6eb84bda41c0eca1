"""The XLA flags of every test process, apart from ``conftest.py`` so that ``.ci/run`` can read
them without importing JAX (``python tests/xla_flags.py`` prints them).

XLA's CPU backend with its earlier fusion emitters compiles the world's programs in about 30 %
less time (the split path's world tick 6.3-8.1 s against 9.2-10.1 s on a 2-core CPU) for a
rollout up to about 20 % slower, and the tests' time is mostly compiling
(docs/reproducibility.md).  Results agree with the default emitters' within float rounding
(``REPRODUCIBLE_ATOL``).  The XLA of jaxlib 0.11 (the first jaxlib for Python 3.12 only) no
longer has the flag, and an unknown flag in ``XLA_FLAGS`` ends the process when JAX starts its
backend (seen with jaxlib 0.11.2): there the tests run XLA's default emitters.
"""

from __future__ import annotations

import importlib.metadata

#: The flag, where the installed jaxlib's XLA has it.
EARLIER_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
#: The first jaxlib release whose XLA does not know :data:`EARLIER_EMITTERS`.
WITHOUT_EARLIER_EMITTERS = (0, 11)


def jaxlib_version() -> tuple[int, ...]:
    """The installed jaxlib's release as numbers, e.g. ``(0, 10, 2)`` (read from its metadata,
    without importing it)."""
    text = importlib.metadata.version("jaxlib")
    return tuple(int(p) for p in text.split("+")[0].split(".")[:3] if p.isdigit())


def xla_flags_for_tests() -> str:
    """The tests' XLA flags for the installed jaxlib ("" where it has none of them)."""
    return EARLIER_EMITTERS if jaxlib_version() < WITHOUT_EARLIER_EMITTERS else ""


if __name__ == "__main__":
    print(xla_flags_for_tests())
