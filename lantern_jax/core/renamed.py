"""Modules renamed or moved, importable under their old names for one release (with a
``DeprecationWarning``).

Two kinds of old names are kept:

* :data:`RENAMED` -- modules renamed so that each name says what it is
  (``lantern_jax.generate`` is ``lantern_jax.apps.suite_generation``);
* :data:`MOVED` -- modules and packages moved from the package's top level into the folder of
  their layer (``lantern_jax.world`` is ``lantern_jax.types.world``,
  ``lantern_jax.stress.search`` is ``lantern_jax.apps.stress.search``); every module under a
  moved package is found under its old name too.

``import lantern_jax.world`` (an old name) gives the module ``lantern_jax.types.world`` itself,
so code written against the old name keeps working unchanged and sees the same objects; the
warning names the new one.  :func:`install` puts the finder first on ``sys.meta_path``
(``import lantern_jax`` does it), so that an old name is never loaded a second time from the
moved file under another name.
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
    "lantern_jax.ablations": "lantern_jax.apps.ablation_table",  # runs the ablation table
    "lantern_jax.scenarios.ablations": "lantern_jax.scenarios.protocol_variants",  # the variants
    "lantern_jax.generate": "lantern_jax.apps.suite_generation",  # generates suites
    # the per-tick protocol state machine sits next to the tick (its delivery reads, which the
    # warning sensor takes, in lantern_jax.sensors.warning_delivery, are importable from it)
    "lantern_jax.scenarios.protocol": "lantern_jax.sim.protocol",
    "lantern_jax.dataset.generate": "lantern_jax.apps.dataset.generation",  # the dataset
    "lantern_jax.envs.train": "lantern_jax.apps.envs.ppo_training",  # brax PPO
    "lantern_jax.training.train": "lantern_jax.apps.training.behaviour_cloning",  # the BC loop
}

#: Folder of each layer (``docs/design.md``) -> the modules and packages moved into it from the
#: package's top level.
_LAYER_FOLDERS = {
    "core": ("constants", "times", "timing", "family_codes", "checks", "actor_track",
             "jax_setup", "user_code", "renamed", "named_registry"),  # fmt: skip
    "maths": ("geometry", "polyline", "split_map"),
    "types": ("world", "observation", "language"),
    "io": ("files", "config_file", "program_store"),
    "apps": ("evaluation", "suite_generation", "diagnostics", "ablation_table", "stream",
             "transfer", "stress", "dataset", "envs", "training"),  # fmt: skip
    "report": ("compare",),
}

#: old name of a moved module or package -> its new name (a package's modules follow it)
MOVED = {
    f"lantern_jax.{name}": f"lantern_jax.{folder}.{name}"
    for folder, names in _LAYER_FOLDERS.items()
    for name in names
}


def new_name(old: str) -> str | None:
    """The module an old name stands for, or ``None`` when ``old`` is not an old name."""
    if old in RENAMED:
        return RENAMED[old]
    parts = old.split(".")
    for i in range(len(parts), 1, -1):
        head = ".".join(parts[:i])
        if head in MOVED:
            return ".".join([MOVED[head], *parts[i:]])
    return None


class _Loader(importlib.abc.Loader):
    """Loads an old name as the module it stands for."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = new_name(spec.name)
        verb = "is renamed" if spec.name in RENAMED else "moved to"
        warnings.warn(f"{spec.name} {verb} {new}; the old name goes in the next release",
                      DeprecationWarning, stacklevel=2)  # fmt: skip
        return importlib.import_module(new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the module is the new one, already executed."""


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`RENAMED` and :data:`MOVED`."""

    def find_spec(self, fullname: str, path: object = None, target: object = None):
        if not fullname.startswith("lantern_jax.") or new_name(fullname) is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader())


def install() -> None:
    """Put the finder of the old names first on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
