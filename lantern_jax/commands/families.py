"""``lantern-jax --families FILE.py|MODULE ...``: import the files or modules that register
scenario families (:func:`lantern_jax.scenarios.registry.register_family`) before a command
runs, so that ``evaluate --suite``, ``suite --list``, ``unseen --suite`` and the rest take suite
files of those families.

A ``.py`` path is imported as a module named after the file, its folder and its content (once
per process: two files of one name in different folders are two modules); anything else is
imported by module name.  Importing runs the file's code as a guest
(:func:`lantern_jax.core.user_code.as_guest`): it cannot end the tool or print into its output.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import importlib.util
import sys
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError
from lantern_jax.core.user_code import UserCodeError, as_guest

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


def module_name(path: Path) -> str:
    """The module name of a families file: its stem, then a hash of its absolute path and its
    bytes (a file of the same name elsewhere, or the same file edited, is another module)."""
    resolved = path.expanduser().resolve()
    digest = hashlib.sha256(str(resolved).encode() + b"\0" + resolved.read_bytes()).hexdigest()
    stem = "".join(c if c.isalnum() else "_" for c in path.stem)
    return f"{MODULE_PREFIX}{stem}_{digest[:12]}"


def _import_file(path: Path, spec: str) -> str:
    """Import a families file once per process; returns its module name."""
    if not path.is_file():
        raise FileNotFoundError(f"no such file {spec}")
    name = module_name(path)
    if name in sys.modules:
        return name
    found = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(found)
    sys.modules[name] = module
    try:
        as_guest(f"families file {path.name}", found.loader.exec_module, module,
                 argv0=str(path))  # fmt: skip
    except BaseException:
        del sys.modules[name]
        raise
    return name


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
                name = _import_file(path, spec)
            else:
                name = as_guest(f"families module {spec}", importlib.import_module, spec).__name__
        except UserCodeError as e:
            raise UsageError(f"--families {spec}: {e}") from None
        except Exception as e:
            raise UsageError(f"--families {spec}: {type(e).__name__}: {e}") from None
        names.append(name)
    return names
