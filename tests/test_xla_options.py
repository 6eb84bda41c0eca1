"""The compile options of the programs compiled for one piece of work
(:mod:`lantern_jax.core.xla_options`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from xla_flags import xla_flags_for_tests

from lantern_jax.core import xla_options


@pytest.mark.parametrize(
    ("release", "expected"),
    [("0.10.2", {"xla_cpu_use_fusion_emitters": False}), ("0.10.0+cuda12", {
        "xla_cpu_use_fusion_emitters": False}), ("0.11.0", None), ("0.11.2", None), ("1.0", None)],
)  # fmt: skip
def test_the_earlier_emitters_only_where_jaxlib_has_them(monkeypatch, release, expected):
    """The option is asked for below jaxlib 0.11, whose XLA refuses it, and never from 0.11 on;
    the tests' XLA flags follow the same rule from the same module."""
    monkeypatch.setattr(xla_options.importlib.metadata, "version", lambda name: release)
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    assert xla_options.fast_compile_options() == expected
    assert xla_flags_for_tests() == ("--xla_cpu_use_fusion_emitters=false" if expected else "")


@pytest.mark.parametrize("value", ["true", "false"])
def test_xla_flags_naming_the_option_win(monkeypatch, value):
    """An ``XLA_FLAGS`` that chooses the emitters itself decides for every program: no
    program asks for its own (as the tests' own flag is set, a user's wins there too)."""
    monkeypatch.setattr(xla_options.importlib.metadata, "version", lambda name: "0.10.2")
    monkeypatch.setenv("XLA_FLAGS", f"--xla_cpu_use_fusion_emitters={value} --xla_dump_to=/x")
    assert xla_options.fast_compile_options() is None


def test_a_program_compiled_with_the_options_gives_the_default_programs_values(monkeypatch):
    """Where the installed jaxlib has the option, XLA accepts it per program, and the program
    computes what the same function compiled with XLA's defaults computes (float rounding)."""
    monkeypatch.delenv("XLA_FLAGS", raising=False)  # the tests' own flag names the option
    options = xla_options.fast_compile_options()
    if options is None:
        pytest.skip("this jaxlib has no earlier fusion emitters: every program uses the defaults")

    def f(x):
        return jnp.cumsum(jnp.sin(x) * jnp.exp(-x), axis=-1) + jnp.tanh(x).sum()

    x = jnp.linspace(-2.0, 2.0, 257, dtype=jnp.float32).reshape(1, -1)
    fast = jax.jit(f, compiler_options=options)(x)
    default = jax.jit(f, compiler_options={"xla_cpu_use_fusion_emitters": True})(x)
    np.testing.assert_allclose(np.asarray(fast), np.asarray(default), rtol=1e-5, atol=1e-5)
