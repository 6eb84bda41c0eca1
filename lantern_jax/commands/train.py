"""``lantern-jax train``: every way this project trains a driving policy, chosen by the config.

::

    lantern-jax train --config configs/train_base.toml
    lantern-jax train --config configs/train_coop.toml --dataset data/lantern --epochs 4
    lantern-jax train --config configs/train_ppo.toml --minutes 5

A config with a ``[train]`` table trains a learned model on the dataset (its ``recipe``: the
paper's open-loop recipes and this project's own): it writes the run folder (orbax checkpoints —
a rerun resumes —, ``curve.csv``, ``curve.png``) and exports the best model as
``<out>/<name>.msgpack`` + ``.json``, loadable with
``lantern-jax evaluate --policy <name> --checkpoint <out>/<name>.msgpack``.

A config with a ``[ppo]`` table runs brax's PPO on the benchmark environment
(:mod:`lantern_jax.apps.envs.ppo_training`, the ``rl`` extra): the learning curve goes to ``out``,
the policy to ``checkpoint`` after every evaluation (under ``--out`` when that is given);
evaluate it with ``LANTERN_JAX_PPO_CHECKPOINT=<checkpoint> lantern-jax evaluate --policy ppo``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out
from lantern_jax.commands.values import count, number, seed
from lantern_jax.core import allocator

#: Keys of a ``[ppo]`` config and their types (:func:`lantern_jax.apps.envs.ppo_training.train`'s
#: arguments; every key is optional, its default that function's).
PPO_KEYS = {
    "out": (str,),
    "checkpoint": (str,),
    "minutes": (int, float),
    "num_timesteps": (int,),
    "num_evals": (int,),
    "pairs_per_family": (int,),
    "seed": (int,),
}
#: Options of the dataset recipes that a ``[ppo]`` config cannot take.
DATASET_ONLY = ("dataset", "epochs", "init_from")


def _table_of(path: str) -> str:
    """``"ppo"`` for a config with a ``[ppo]`` table, else ``"train"`` (read and checked by the
    loader of that kind)."""
    from lantern_jax.io.files import read_toml

    try:
        raw = read_toml(path)
    except (OSError, ValueError):
        return "train"  # the dataset loader names the problem
    return "ppo" if "ppo" in raw else "train"


def load_ppo_config(path: str, args: argparse.Namespace) -> dict:
    """The ``[ppo]`` table of ``path`` with the command line's ``--out``, ``--seed`` and
    ``--minutes`` applied, as keyword arguments of :func:`lantern_jax.apps.envs.ppo_training.train`.
    ``--out DIR`` moves the whole run: the config's ``checkpoint`` file keeps its name and is
    written under ``DIR``.

    Raises:
        UsageError: naming the file and key for an unknown key, a wrong type or a value out of
            range, and naming the option for ``--dataset`` or ``--epochs`` (dataset recipes only).
    """
    from lantern_jax.io.config_file import ConfigFileError, check_keys, read_table, typed_value

    given = [f"--{o.replace('_', '-')}" for o in DATASET_ONLY if getattr(args, o) is not None]
    if given:
        raise UsageError(f"{', '.join(given)}: config {path} trains with PPO on the "
                         "environment, which reads no dataset, counts no epochs and fine-tunes "
                         "no checkpoint")  # fmt: skip
    try:
        cfg = read_table(path, "ppo")
        check_keys(path, "ppo", list(cfg), tuple(PPO_KEYS))
        for key, value in cfg.items():
            typed_value(value, PPO_KEYS[key], f"config {path}: {key}")
    except ConfigFileError as e:
        raise UsageError(str(e)) from None
    for option in ("out", "seed", "minutes"):
        if getattr(args, option, None) is not None:
            cfg[option] = getattr(args, option)
    if args.out is not None and "checkpoint" in cfg:  # --out moves the whole run
        cfg["checkpoint"] = str(Path(args.out) / Path(cfg["checkpoint"]).name)
    for key in ("minutes", "num_timesteps", "num_evals", "pairs_per_family"):
        if key in cfg and not cfg[key] > 0:
            raise UsageError(f"config {path}: {key} must be > 0 (got {cfg[key]})")
    return cfg


def _train_ppo(args: argparse.Namespace) -> int:
    """Run PPO as the ``[ppo]`` config says."""
    cfg = load_ppo_config(args.config, args)
    out = cfg.setdefault("out", "runs/ppo")
    cfg.setdefault("checkpoint", f"{out.rstrip('/')}/ppo_lantern.msgpack")
    check_out(out, "--out" if args.out is not None else f"config {args.config}: ppo.out",
              in_place=True)  # fmt: skip
    from lantern_jax.apps.envs.ppo_training import train as train_ppo

    curve = train_ppo(**cfg)
    if curve:
        last = curve[-1]
        print(f"{'env_steps':>16}: {last['env_steps']}")
        print(f"{'eval_return':>16}: {last['eval_return']:.4g}")
    print(f"{'checkpoint':>16}: {cfg['checkpoint']}")
    return 0


def cmd_train(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Train one model as the config says; print the summary."""
    del argv
    if _table_of(args.config) == "ppo":
        return _train_ppo(args)
    if args.minutes is not None:
        raise UsageError(f"--minutes: config {args.config} trains on the dataset; its time "
                         "budget is the config's max_minutes")  # fmt: skip
    try:  # a bad LANTERN_JAX_MALLOC is refused before any work
        allocator.malloc_choice()
    except allocator.AllocatorError as e:
        raise UsageError(str(e)) from None
    from lantern_jax.apps.dataset.store import DatasetError
    from lantern_jax.apps.training.behaviour_cloning import train
    from lantern_jax.apps.training.config import load_config
    from lantern_jax.io.config_file import ConfigFileError
    from lantern_jax.policies.learned.checkpoint import CheckpointError

    try:
        cfg = load_config(args.config, dataset=args.dataset, out=args.out, epochs=args.epochs,
                          seed=args.seed, init_from=args.init_from)  # fmt: skip
    except ConfigFileError as e:
        raise UsageError(str(e)) from None
    from lantern_jax.apps.training.behaviour_cloning import check_checkpoint_folder, run_files

    where = "--out" if args.out is not None else f"config {args.config}: train.out"
    check_out(cfg.out, where, in_place=True, owned=run_files(cfg))
    try:
        check_checkpoint_folder(Path(cfg.out))
    except OSError as e:
        raise UsageError(f"{where}: {e}") from None
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
    tr = sub.add_parser("train", help="train a driving policy (dataset recipes or PPO)",
                        description=__doc__.splitlines()[0], allow_abbrev=False)  # fmt: skip
    tr.add_argument("--config", required=True, metavar="TOML",
                    help="training config: a [train] table (dataset recipes, "
                    "configs/train_*.toml) or a [ppo] table (configs/train_ppo.toml)")  # fmt: skip
    tr.add_argument("--dataset", metavar="DIR",
                    help="dataset folder (overrides the config; [train] only)")  # fmt: skip
    tr.add_argument("--out", metavar="DIR",
                    help="run folder (overrides the config; a [ppo] run's checkpoint is "
                         "written there too)")  # fmt: skip
    tr.add_argument("--epochs", type=count(), metavar="N",
                    help="epochs (overrides the config; [train] only)")  # fmt: skip
    tr.add_argument("--minutes", type=number(0.0, 10**6, low_open=True), metavar="M",
                    help="wall-clock budget (overrides the config; [ppo] only)")  # fmt: skip
    tr.add_argument("--seed", type=seed(), help="seed (overrides the config)")
    tr.add_argument("--init-from", metavar="MSGPACK",
                    help="checkpoint to fine-tune from (overrides the config; [train] "
                         "only): a later stage from another seed's earlier one")  # fmt: skip
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=cmd_train)
