"""The package's public names (``lantern_jax/__init__.py``): each resolves to the object of
the module that defines it, ``import lantern_jax`` does not start JAX, and the README's Python
example runs from ``import lantern_jax``."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import lantern_jax


@pytest.mark.parametrize("name", lantern_jax.__all__)
def test_every_public_name_is_the_defining_modules_object(name):
    module = importlib.import_module(lantern_jax._EXPORTS[name])
    assert getattr(lantern_jax, name) is getattr(module, name)
    assert name in dir(lantern_jax)


def test_the_quickstart_names_are_exported():
    needed = {"evaluate", "load_suite", "Policy", "rollout", "get_policy", "Settings",
              "ScoringSettings", "ProtocolSettings", "TextBank"}  # fmt: skip
    assert needed <= set(lantern_jax.__all__)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'evaluat'"):
        lantern_jax.evaluat  # noqa: B018


def test_importing_the_package_does_not_start_jax():
    code = "import sys, lantern_jax; print('jax' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"
