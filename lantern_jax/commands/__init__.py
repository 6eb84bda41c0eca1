"""Sub-commands of ``lantern-jax`` beyond the core ones in :mod:`lantern_jax.cli`: each module
adds its parser with ``add_parser(sub)`` and raises :class:`CommandError` for a usage error (exit
code 2)."""


class CommandError(Exception):
    """A bad command-line argument of a sub-command (exit code 2)."""


def write_and_list(tables: dict, out: str) -> int:
    """Write ``name.csv`` and ``name.md`` for every ``name: (title, table)`` into ``out`` as one
    set (:func:`lantern_jax.diagnostics.write_tables`) and list the files; returns the exit
    code (1 when they cannot be written)."""
    import sys

    from lantern_jax.diagnostics import write_tables

    try:
        paths = write_tables(tables, out)
    except OSError as e:
        print(f"lantern-jax: error: cannot write results to {out}: {e}", file=sys.stderr)
        return 1
    print(f"Wrote {len(paths)} files:")
    for path in paths:
        print(f"  {path}")
    return 0
