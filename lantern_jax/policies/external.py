"""A user's policy named by its code: ``path/to/file.py:NAME`` or ``package.module:attr``.

This is the submission format of the command line (``lantern-jax evaluate --policy
my_policy.py:POLICY``) and of experiment files: the object named is a
:class:`~lantern_jax.policies.base.Policy`, or a callable taking no argument that returns one
(a factory).  The policy is evaluated under its own ``Policy.name``; the result's manifest
records where it came from and the SHA-256 of its source file (:func:`load_policy_source`), so a
result folder says which code produced its rows.

A file is imported as a fresh module named after its content hash, not added to
``sys.path``: two files with the same name in different folders do not collide, and editing a
file between runs gives another module (and another hash in the manifest).

    from lantern_jax.policies.external import load_policy_source
    policy, source = load_policy_source("examples/my_brake.py:POLICY")
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.util
import inspect
import os
import re
import sys
from pathlib import Path
from typing import Any

from lantern_jax.core.user_code import UserCodeError, as_guest
from lantern_jax.policies.base import Policy

#: ``package.module`` (dotted Python identifiers).
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
#: ``attr`` after the colon.
_ATTR = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def is_policy_source(spec: str) -> bool:
    """``spec`` names code (``file.py:NAME`` or ``package.module:attr``) rather than a registered
    policy name (registered names hold no colon, :mod:`lantern_jax.policies.names`)."""
    if not isinstance(spec, str) or spec.count(":") != 1:
        return False
    where, _ = spec.split(":")
    return where.lower().endswith(".py") or bool(_MODULE.match(where))


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _import_file(path: Path, digest: str) -> Any:
    """Import ``path`` as a module of its own (named after its hash; cached by that name)."""
    name = f"lantern_jax_user_{path.stem.replace('-', '_')}_{digest[:12]}"
    if name in sys.modules:
        return sys.modules[name]
    module_spec = importlib.util.spec_from_file_location(name, path)
    if module_spec is None or module_spec.loader is None:
        raise ValueError(f"policy file {path}: not importable as a Python module")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    try:
        as_guest(f"policy file {path.name}", module_spec.loader.exec_module, module,
                 argv0=str(path))  # fmt: skip
    except BaseException:
        del sys.modules[name]
        raise
    return module


@contextlib.contextmanager
def _working_folder_importable():
    """The working folder on ``sys.path`` while a ``package.module`` is imported, as under
    ``python -m`` (an installed ``lantern-jax`` script starts without it)."""
    cwd = os.getcwd()
    added = cwd not in sys.path and "" not in sys.path
    if added:
        sys.path.insert(0, cwd)
    try:
        yield
    finally:
        if added and cwd in sys.path:
            sys.path.remove(cwd)


def _required_parameters(fn: Any) -> str:
    """The names of ``fn``'s parameters without defaults, comma-separated ("" for none, or when
    its signature cannot be read)."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return ""
    return ", ".join(p.name for p in params if p.default is p.empty
                     and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD))  # fmt: skip


def _defined(module: Any) -> str:
    """"; the file defines Policy objects: A, B" (or that it defines none)."""
    names = sorted(k for k, v in vars(module).items() if isinstance(v, Policy))
    if not names:
        return "; the file defines no Policy object"
    return f"; the file defines Policy object(s): {', '.join(names)}"


def policies_in_file(path: str | os.PathLike) -> list[str]:
    """The names of the Policy objects a policy file defines (the file is imported as a guest).

    Raises:
        ValueError: when the file cannot be imported.
    """
    file = Path(path).expanduser().resolve()
    try:
        module = _import_file(file, _sha256(file))
    except UserCodeError as e:
        raise ValueError(f"policy file {path}: importing it failed: {e}") from e
    return sorted(k for k, v in vars(module).items() if isinstance(v, Policy))


def load_policy_source(spec: str) -> tuple[Policy, dict]:
    """The policy that ``spec`` names, and the record of its source.

    Args:
        spec: ``path/to/file.py:NAME`` (a file, relative to the working directory or absolute)
            or ``package.module:attr`` (an importable module); ``NAME`` / ``attr`` is a
            :class:`~lantern_jax.policies.base.Policy` or a callable with no argument that
            returns one.

    Returns:
        ``(policy, source)``: ``source`` has ``kind`` (``"file"`` or ``"module"``), ``file``
        (the file's name), ``source_sha256`` (SHA-256 of its bytes) — what a result's manifest
        keeps — and ``source_spec`` (``spec``) and ``source_path`` (the file's absolute path),
        which name this machine's folders and go to the run record
        (:data:`lantern_jax.report.RUN_RECORD_KEYS`).  A module without a file has None for
        the file, path and hash.

    Raises:
        ValueError: for a malformed spec, a missing file or attribute, or an import that fails
            (the exception's message is kept).
        TypeError: when the object is neither a Policy nor a factory returning one.
    """
    if not is_policy_source(spec):
        raise ValueError(
            f"policy source {spec!r}: expected path/to/file.py:NAME or package.module:attr"
        )
    where, attr = spec.split(":")
    if not _ATTR.match(attr):
        raise ValueError(f"policy source {spec!r}: {attr!r} is not a Python identifier")
    if where.lower().endswith(".py") and not where.endswith(".py"):
        raise ValueError(f"policy source {spec!r}: a policy file's name ends in '.py' (lower "
                         f"case), got {Path(where).suffix!r}")  # fmt: skip
    if where.endswith(".py"):
        path = Path(where).expanduser().resolve()
        if not path.is_file():
            raise ValueError(f"policy source {spec!r}: no file {path}")
        digest = _sha256(path)
        kind = "file"
        try:
            module = _import_file(path, digest)
        except UserCodeError as e:
            raise ValueError(f"policy source {spec!r}: importing {path} failed: {e}") from e
    else:
        kind = "module"
        try:
            with _working_folder_importable():
                module = as_guest(f"module {where}", importlib.import_module, where)
        except UserCodeError as e:
            raise ValueError(f"policy source {spec!r}: importing module {where!r} failed: "
                             f"{e}") from e  # fmt: skip
        file = getattr(module, "__file__", None)
        path = Path(file).resolve() if file else None
        digest = _sha256(path) if path is not None and path.is_file() else None
    if not hasattr(module, attr):
        raise ValueError(f"policy source {spec!r}: {where} defines no {attr!r}{_defined(module)}")
    obj = getattr(module, attr)
    policy = obj
    if not isinstance(obj, Policy):
        if callable(obj) and _required_parameters(obj):
            raise TypeError(
                f"policy source {spec!r}: {attr} is a function of ({_required_parameters(obj)}); "
                "NAME must be a Policy, or a function with no argument returning one (wrap an "
                f"act function in lantern_jax.Policy(...)){_defined(module)}"
            )
        if not callable(obj):
            raise TypeError(f"policy source {spec!r}: {attr} is a {type(obj).__name__}, "
                            "expected a Policy or a function returning one")  # fmt: skip
        try:
            policy = as_guest(f"{where}:{attr}", obj)
        except UserCodeError as e:
            raise ValueError(f"policy source {spec!r}: calling {attr}() failed: {e}") from e
        if not isinstance(policy, Policy):
            raise TypeError(f"policy source {spec!r}: {attr}() returned a "
                            f"{type(policy).__name__}, expected a Policy")  # fmt: skip
    source = dict(
        kind=kind,
        file=None if path is None else path.name,
        source_sha256=digest,
        source_spec=spec,
        source_path=None if path is None else str(path),
    )
    return policy, source
