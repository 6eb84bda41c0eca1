"""``python -m lantern_jax`` runs the ``lantern-jax`` command line."""

import sys

from lantern_jax.cli import main

if __name__ == "__main__":
    sys.exit(main())
