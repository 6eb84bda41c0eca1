"""The scenario-family codes the package knows: the paper's six and those registered from user
code.

The six built-in families (:data:`lantern_jax.core.constants.FAMILIES`, the paper's order) always
hold indices 0-5; a family registered from user code
(:func:`lantern_jax.scenarios.registry.register_family`) gets the next free index, in
registration order.  This module keeps only the codes, names and indices, so that the lowest
layers (the scenario types' validation, the scoring tables) can check a family code without
knowing how families are built.  It is written only by the family registry
(:data:`lantern_jax.scenarios.family_registry.FAMILY_REGISTRY`, where every family's data
lives).

Tables list the six families first, in the paper's order, then the registered families that
the table's rows hold (:func:`table_codes`), so a table of the six alone is what it was before
any registration.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable

from lantern_jax.core.constants import FAMILIES, FAMILY_NAMES

#: What a registered family code may look like: 1-8 upper-case letters or digits, starting with a
#: letter (it names the family in tables, suite files and pair ids).
CODE_PATTERN = re.compile(r"[A-Z][A-Z0-9]{0,7}")

_REGISTERED: dict[str, str] = {}  # code -> long name, in registration order


def codes() -> tuple[str, ...]:
    """Every known family code: the six built-in ones, then the registered ones (index order)."""
    return FAMILIES + tuple(_REGISTERED)


def registered() -> tuple[str, ...]:
    """The codes registered from user code, in registration order."""
    return tuple(_REGISTERED)


def is_known(code: object) -> bool:
    """Whether ``code`` is a known family code (a string of :func:`codes`)."""
    return isinstance(code, str) and (code in FAMILIES or code in _REGISTERED)


def index(code: str) -> int:
    """The family index of a code (0-5 for the six, then registration order).

    Raises:
        ValueError: naming the known codes.
    """
    if not is_known(code):
        raise ValueError(f"family: {code!r} not one of {{{', '.join(codes())}}}")
    return codes().index(code)


def code(family_index: int) -> str:
    """The code of a family index.

    Raises:
        ValueError: for an index outside ``0 .. len(codes()) - 1``.
    """
    i = int(family_index)
    all_codes = codes()
    if not 0 <= i < len(all_codes):
        raise ValueError(f"family: {i} outside 0..{len(all_codes) - 1}")
    return all_codes[i]


def name(code_: str) -> str:
    """The long name of a family (``"Pedestrian Emergence"``, or the registered name)."""
    i = index(code_)
    return FAMILY_NAMES[i] if i < len(FAMILIES) else _REGISTERED[code_]


def check_new(code_: str, name_: str) -> None:
    """Refuse a code and name that :func:`register` would refuse (ValueError naming why)."""
    if not isinstance(code_, str) or not CODE_PATTERN.fullmatch(code_):
        raise ValueError(
            f"family code: {code_!r} must be 1-8 upper-case letters or digits, starting with a "
            "letter"
        )
    if code_ in FAMILIES:
        raise ValueError(f"family code: {code_!r} is a built-in family")
    if not isinstance(name_, str) or not name_.strip():
        raise ValueError(f"family name: expected a non-empty string, got {name_!r}")
    if code_ in _REGISTERED and _REGISTERED[code_] != name_:
        raise ValueError(f"family code: {code_!r} is already registered as {_REGISTERED[code_]!r}")


def register(code_: str, name_: str) -> int:
    """Register a family code and its long name; return its index (called by the family
    registry, :meth:`lantern_jax.scenarios.family_registry.FamilyRegistry.register`).

    Registering the same code with the same name again returns its index (a module imported
    twice registers nothing new).

    Args:
        code_: the family code (:data:`CODE_PATTERN`).
        name_: its long name, for listings.

    Raises:
        ValueError: for a built-in code, a code that breaks :data:`CODE_PATTERN`, an empty name,
            or a code already registered under another name.
    """
    check_new(code_, name_)
    _REGISTERED[code_] = name_
    return index(code_)


def reset(registered_codes: dict[str, str]) -> None:
    """Set the registered codes to ``registered_codes`` (code -> long name, in index order):
    how :meth:`lantern_jax.scenarios.family_registry.FamilyRegistry.restore` forgets families.

    Raises:
        ValueError: for a built-in or malformed code.
    """
    for code_ in registered_codes:
        if code_ in FAMILIES or not CODE_PATTERN.fullmatch(str(code_)):
            raise ValueError(f"family code: {code_!r} cannot be registered")
    _REGISTERED.clear()
    _REGISTERED.update(registered_codes)


def stream(code_: str) -> int:
    """The number that seeds a family's random streams (suite candidates, dataset scenes): its
    index for the six built-in families (as ``lantern-v3`` and the dataset were generated), else
    the first four bytes of the SHA-256 of its code, so that a registered family's draws do not
    depend on what else is registered.

    Args:
        code_: a known family code.
    """
    if code_ in FAMILIES:
        return FAMILIES.index(code_)
    index(code_)  # raises for an unknown code
    return int.from_bytes(hashlib.sha256(code_.encode()).digest()[:4], "big")


def table_codes(present: Iterable[str]) -> list[str]:
    """The family columns of a table: the six built-in codes, then the registered codes among
    ``present`` (in index order).

    Args:
        present: the family codes the table's rows (or columns) hold; unknown ones are ignored.
    """
    seen = set(present)
    return list(FAMILIES) + [c for c in _REGISTERED if c in seen]
