"""``lantern-jax train``: behaviour cloning of a learned driving policy on the dataset.

::

    lantern-jax train --config configs/train_base.toml
    lantern-jax train --config configs/train_coop.toml --dataset data/lantern --epochs 4

Writes the run folder (orbax checkpoints — a rerun resumes —, ``curve.csv``, ``curve.png``) and
exports the best model as ``<out>/<name>.msgpack`` + ``.json``, loadable with
``lantern-jax evaluate --policy <name> --checkpoint <out>/<name>.msgpack``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out


def cmd_train(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Train one model as the config says; print the summary."""
    del argv
    from lantern_jax.config_file import ConfigFileError
    from lantern_jax.dataset.store import DatasetError
    from lantern_jax.policies.learned.checkpoint import CheckpointError
    from lantern_jax.training.config import load_config
    from lantern_jax.training.train import train

    try:
        cfg = load_config(args.config, dataset=args.dataset, out=args.out, epochs=args.epochs,
                          seed=args.seed)  # fmt: skip
    except ConfigFileError as e:
        raise UsageError(str(e)) from None
    where = "--out" if args.out is not None else f"config {args.config}: train.out"
    check_out(cfg.out, where, in_place=True)
    try:
        summary = train(cfg, progress=not args.quiet)
    except DatasetError as e:  # names the dataset's file
        raise UsageError(str(e)) from None
    except CheckpointError as e:  # the model it fine-tunes
        raise UsageError(f"config {args.config}: train.init_from: {e}") from None
    for k, v in summary.items():
        print(f"{k:>16}: {v:.4g}" if isinstance(v, float) else f"{k:>16}: {v}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``train`` on the command line's sub-parsers."""
    tr = sub.add_parser("train", help="train a learned driving policy on the dataset",
                        description=__doc__.splitlines()[0], allow_abbrev=False)  # fmt: skip
    tr.add_argument("--config", required=True, metavar="TOML", help="training config")
    tr.add_argument("--dataset", metavar="DIR", help="dataset folder (overrides the config)")
    tr.add_argument("--out", metavar="DIR", help="run folder (overrides the config)")
    tr.add_argument("--epochs", type=int, metavar="N", help="epochs (overrides the config)")
    tr.add_argument("--seed", type=int, help="seed (overrides the config)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=cmd_train)
