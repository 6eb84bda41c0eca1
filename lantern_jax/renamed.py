"""Modules renamed so that each name says what it is, importable under their old names for one
release (with a ``DeprecationWarning``).

``import lantern_jax.generate`` (the old name) gives the module ``lantern_jax.suite_generation``
itself, so code written against the old name keeps working unchanged; the warning names the new
one.  :func:`install` puts the finder on ``sys.meta_path`` (``import lantern_jax`` does it).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: old module name -> new module name
RENAMED = {
    "lantern_jax.ablations": "lantern_jax.ablation_table",  # runs the ablation table
    "lantern_jax.scenarios.ablations": "lantern_jax.scenarios.protocol_variants",  # the variants
    "lantern_jax.generate": "lantern_jax.suite_generation",  # generates suites
    "lantern_jax.dataset.generate": "lantern_jax.dataset.generation",  # generates the dataset
    "lantern_jax.envs.train": "lantern_jax.envs.ppo_training",  # brax PPO
    "lantern_jax.training.train": "lantern_jax.training.behaviour_cloning",  # the BC loop
}


class _Loader(importlib.abc.Loader):
    """Loads an old name as the renamed module itself."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = RENAMED[spec.name]
        warnings.warn(f"{spec.name} is renamed {new}; the old name goes in the next release",
                      DeprecationWarning, stacklevel=2)  # fmt: skip
        return importlib.import_module(new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the module is the renamed one, already executed."""


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`RENAMED`."""

    def find_spec(self, fullname: str, path: object = None, target: object = None):
        if fullname not in RENAMED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader())


def install() -> None:
    """Put the finder of the old names on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
