"""Renamed modules stay importable under their old names for one release, with a warning."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

import lantern_jax
from lantern_jax.renamed import RENAMED


@pytest.mark.parametrize(("old", "new"), sorted(RENAMED.items()))
def test_an_old_name_imports_the_renamed_module_and_warns(old, new):
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=rf"{old} is renamed {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    sys.modules.pop(old, None)


def test_each_name_says_what_it_is_no_old_file_is_left():
    package = Path(lantern_jax.__file__).parent
    for old, new in RENAMED.items():
        old_file = package.joinpath(*old.split(".")[1:]).with_suffix(".py")
        new_file = package.joinpath(*new.split(".")[1:]).with_suffix(".py")
        assert not old_file.exists() and new_file.exists(), (old, new)
