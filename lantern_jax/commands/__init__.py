"""Sub-commands of ``lantern-jax`` beyond the core ones in :mod:`lantern_jax.cli`: each module
adds its parser with ``add_parser(sub)`` and raises :class:`CommandError` for a usage error (exit
code 2)."""


class CommandError(Exception):
    """A bad command-line argument of a sub-command (exit code 2)."""
