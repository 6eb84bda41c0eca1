"""The commands of ``lantern-jax``, one module each.

Every command module has ``add_parser(sub)``, which adds the command to the command line's
sub-parsers with its ``cmd_*`` function as the one to run, and raises :class:`UsageError` for a
bad argument (exit code 2).  What several commands share is in :mod:`.common` (options, suite
selection, output folders, stage lines) and :mod:`.runtime` (Ctrl-C, standard output, the
compilation cache, the distributed runtime); :mod:`lantern_jax.cli` assembles the parser and
runs a command.

A command module imports the package's computing modules (JAX, the simulator, pandas) inside
its functions, by rule and without a comment each: every run of ``lantern-jax`` builds every
command's parser first, and that imports neither JAX nor pandas, so ``--help`` and a bad argument
answer in about 0.2 s (``tests/test_cli_help.py``).  Elsewhere in the package an import is
deferred only for a stated reason (an optional or heavy library, JAX's configuration).
"""


class UsageError(Exception):
    """A user error that ends the command with exit code 2; the message names the bad option
    (or file and key)."""
