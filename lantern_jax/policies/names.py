"""What a policy name may be: a name the command line can select and a file can carry.

A name is used as a ``--policy`` value (comma-separated lists, ``all``), as a row label of the
result files and, for a trained model, as the stem of its exported files
(``<out>/<name>.msgpack``).  So it is a short run of letters, digits, ``_``, ``-`` and ``.``
that starts with a letter or digit, and not one of :data:`RESERVED_NAMES`.
"""

from __future__ import annotations

import re

#: The reference policies of the paper's protocol, in the order they are evaluated and tabled:
#: what ``lantern-jax evaluate`` runs by default (and ``--policy all`` stands for).  They share
#: one compiled program (:func:`lantern_jax.sim.switch.shared_program`).
REFERENCE_POLICIES = ("expert", "ego", "coop")

#: Names with a meaning of their own on the command line (``--policy all``).
RESERVED_NAMES = ("all",)
#: Longest policy name.
MAX_NAME_LENGTH = 64
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")


def name_problem(name: object) -> str | None:
    """What makes ``name`` unusable as a policy name, or None when it is a valid one.

    Args:
        name: the proposed name (any value: a file may hold anything).
    """
    if not isinstance(name, str):
        return f"expected a string, got {type(name).__name__} {name!r}"
    if name in RESERVED_NAMES:
        return f"{name!r} is reserved on the command line"
    if len(name) > MAX_NAME_LENGTH:
        return f"{name!r} is longer than {MAX_NAME_LENGTH} characters"
    if not NAME_PATTERN.fullmatch(name):
        return (
            f"{name!r} is not a selectable name (letters, digits, '_', '-' and '.', starting "
            "with a letter or digit)"
        )
    return None
