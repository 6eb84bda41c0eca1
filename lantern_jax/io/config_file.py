"""Configuration files: one TOML table per file, read and checked key by key.

Both kinds of configuration file are read here, so that they accept the same TOML and name a
problem the same way:

* experiment files of the command line (``lantern-jax evaluate --config FILE``, one
  ``[evaluate]`` table; :func:`lantern_jax.commands.evaluate.load_config`);
* training configs (``lantern-jax train --config FILE``, one ``[train]`` table;
  :func:`lantern_jax.apps.training.config.load_config`).

Every message names the file, and the key where there is one.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Any

from lantern_jax.io.files import read_toml


class ConfigFileError(ValueError):
    """A configuration file that cannot be used; the message names the file (and the key)."""


def read_table(path: str | os.PathLike, table: str) -> dict:
    """The one table of a configuration file.

    Args:
        path: the TOML file (a UTF-8 byte-order mark at its start is accepted).
        table: the name of the table every key belongs under (``evaluate``, ``train``).

    Returns:
        The table as a dict.

    Raises:
        ConfigFileError: naming the file for a file that cannot be read, text that is not TOML,
            keys or tables beside the table, no such table, or a ``table`` key that is not one.
    """
    try:
        raw = read_toml(path)
    except OSError as e:
        raise ConfigFileError(f"cannot read config {path}: {e}") from None
    except ValueError as e:
        raise ConfigFileError(f"config {path}: not valid TOML ({e})") from None
    outside = [k for k in raw if k != table]
    if outside:
        raise ConfigFileError(
            f"config {path}: key(s) {', '.join(map(repr, outside))} outside the [{table}] "
            f"table; every option goes under [{table}]"
        )
    if table not in raw:
        raise ConfigFileError(f"config {path}: no [{table}] table")
    if not isinstance(raw[table], dict):
        raise ConfigFileError(f"config {path}: {table} must be a table ([{table}])")
    return raw[table]


def check_keys(
    path: str | os.PathLike, table: str, keys: Iterable[str], valid: Sequence[str]
) -> None:
    """Refuse a key that the table does not have.

    Args:
        path: the file (for the message).
        table: the table's name (for the message).
        keys: the keys given.
        valid: the keys the table may hold, in the order the message lists them.

    Raises:
        ConfigFileError: naming the file, the first unknown key and the valid ones.
    """
    for key in keys:
        if key not in valid:
            raise ConfigFileError(
                f"config {path}: unknown key {key!r} in [{table}]; valid keys: {', '.join(valid)}"
            )


def typed_value(value: Any, types: Sequence[type], where: str) -> Any:
    """A value of one of ``types``: a whole number where a float is accepted becomes a float; a
    boolean is neither a number nor a string.

    Args:
        value: the value read.
        types: the accepted types.
        where: what the message names the value by (``config FILE: key``, ``--key``).

    Raises:
        ConfigFileError: ``"<where> must be <types>, got <value>"``.
    """
    if not isinstance(value, bool):
        if isinstance(value, tuple(types)):
            return value
        if float in types and isinstance(value, int):
            return float(value)
    want = " or ".join(t.__name__ for t in types)
    raise ConfigFileError(f"{where} must be {want}, got {value!r}")
