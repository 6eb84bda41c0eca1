"""``lantern-jax --families FILE.py|MODULE ...``: import the files or modules that register
scenario families (:func:`lantern_jax.scenarios.registry.register_family`) before a command
runs, so that ``evaluate --suite``, ``suite --list``, ``unseen --suite`` and the rest take suite
files of those families.

A ``.py`` path is imported as a module named after the file (once per process); anything else
is imported by module name.  Importing runs the file's code, as ``python FILE.py`` would.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError

MODULE_PREFIX = "lantern_jax_user_families_"  # the module name of a file given by path


def add_option(parser: argparse.ArgumentParser) -> None:
    """Add the top-level ``--families`` option."""
    parser.add_argument(
        "--families",
        action="append",
        metavar="FILE.py|MODULE",
        help="import a file or module that registers scenario families before the command "
        "runs (may be repeated; see docs/families.md)",
    )


def load(specs: Sequence[str] | None) -> list[str]:
    """Import every file or module of ``specs``; return the module names.

    Raises:
        UsageError: naming a file or module that cannot be imported, with the error it raised.
    """
    names = []
    for spec in specs or ():
        path = Path(spec)
        try:
            if path.suffix == ".py":
                if not path.is_file():
                    raise FileNotFoundError(f"no such file {spec}")
                name = MODULE_PREFIX + path.stem
                if name not in sys.modules:
                    found = importlib.util.spec_from_file_location(name, path)
                    module = importlib.util.module_from_spec(found)
                    sys.modules[name] = module
                    try:
                        found.loader.exec_module(module)
                    except BaseException:
                        del sys.modules[name]
                        raise
            else:
                name = importlib.import_module(spec).__name__
        except Exception as e:
            raise UsageError(f"--families {spec}: {type(e).__name__}: {e}") from None
        names.append(name)
    return names
