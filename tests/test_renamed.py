"""Renamed and moved modules stay importable under their old names for one release, with a
warning, and an old name is the new module itself (never a second copy of it)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

import lantern_jax
from lantern_jax.core.renamed import MOVED, RENAMED, new_name

#: A module under a moved package, and one under a package that did not move.
UNDER_MOVED = ("lantern_jax.stress.search", "lantern_jax.apps.stress.search")


@pytest.mark.parametrize(("old", "new"), sorted(RENAMED.items()))
def test_an_old_name_imports_the_renamed_module_and_warns(old, new):
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=rf"{old} is renamed {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    sys.modules.pop(old, None)


@pytest.mark.parametrize(("old", "new"), [*sorted(MOVED.items()), UNDER_MOVED])
def test_a_moved_module_imports_under_its_old_name_as_itself_and_warns(old, new):
    module = importlib.import_module(new)
    saved = {k: v for k, v in sys.modules.items() if k == old or k.startswith(old + ".")}
    for k in saved:
        del sys.modules[k]
    try:
        with pytest.warns(DeprecationWarning, match=rf"{old} moved to {new}"):
            assert importlib.import_module(old) is module
    finally:
        for k in [k for k in sys.modules if k == old or k.startswith(old + ".")]:
            del sys.modules[k]
        sys.modules.update(saved)


def test_names_that_are_not_old_are_left_to_the_import_system():
    assert new_name("lantern_jax.sim.rollout") is None
    assert new_name("lantern_jax.worlds") is None
    assert new_name("lantern_jax.world.x") == "lantern_jax.types.world.x"


def test_each_name_says_what_it_is_no_old_file_is_left():
    package = Path(lantern_jax.__file__).parent
    for old, new in [*RENAMED.items(), *MOVED.items()]:
        old_path = package.joinpath(*old.split(".")[1:])
        new_path = package.joinpath(*new.split(".")[1:])
        assert not old_path.with_suffix(".py").exists() and not old_path.is_dir(), old
        assert new_path.with_suffix(".py").exists() or (new_path / "__init__.py").exists(), new
