"""Behaviour cloning of a driving model on the open-loop dataset.

:func:`train` runs one configuration (:class:`~lantern_jax.apps.training.config.TrainConfig`):

* examples from the recipe (:func:`~lantern_jax.apps.training.data.recipe_examples`),
  horizon-crossing frames excluded as ``exclude_crossing`` says (the paper's rule by default), a
  validation split by sequence;
* AdamW with a one-cycle schedule (linear warm-up, cosine decay), an L1 loss on the ten
  waypoints (metres, ego frame), mini-batches shuffled by a seeded generator (``coop`` and
  ``distance`` draw ``base_mix`` of every batch from ordinary-driving frames);
* after every epoch: the validation loss, a row of ``curve.csv``, an orbax checkpoint of the
  parameters and optimiser state (a rerun of the same config resumes from the latest), and,
  when the validation loss is the best so far, the exported model (``<out>/<name>.msgpack`` +
  ``.json``, :func:`~lantern_jax.policies.learned.checkpoint.save_model`);
* ``curve.png`` at the end.

Deterministic for a given seed on a given machine (seeded initialisation and shuffles; XLA on
CPU is deterministic).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from lantern_jax.apps.dataset.store import dataset_provenance, load_frames, read_card
from lantern_jax.apps.training.closed_loop import train_closed_loop
from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.apps.training.data import ranges_width, recipe_examples, split_by_sequence
from lantern_jax.apps.training.fit import Batches, fit, model_config
from lantern_jax.core.allocator import keep_freed_memory
from lantern_jax.policies.learned.checkpoint import load_model, new_model

#: The files a run writes at the top of its folder besides ``<name>.msgpack`` / ``<name>.json``.
RUN_FILES = ("curve.csv", "curve.png", "rounds.json")
#: The folder of the run's orbax checkpoints (its entries are step folders orbax prunes).
CHECKPOINT_FOLDER = "checkpoints"


def run_files(cfg: TrainConfig) -> tuple[str, ...]:
    """The files a run of ``cfg`` writes at the top of its folder (checked up front, so that
    an entry of the user's of one of these names is refused rather than replaced)."""
    return (f"{cfg.name}.msgpack", f"{cfg.name}.json", *RUN_FILES)


def check_checkpoint_folder(out: Path) -> None:
    """Refuse a run folder whose ``checkpoints/`` holds anything but orbax's step folders:
    orbax deletes old steps there, so a user's entry in it could be lost.

    Raises:
        OSError: naming the entry.
    """

    folder = Path(out) / CHECKPOINT_FOLDER
    if not os.path.lexists(folder):
        return
    if folder.is_symlink() or not folder.is_dir():
        raise OSError(f"{folder}: is not the checkpoint folder of a run (a file or a link)")
    for entry in sorted(folder.iterdir()):
        if entry.is_symlink() or not entry.is_dir() or not re.fullmatch(r"\d+(\..+)?", entry.name):
            raise OSError(f"{entry}: not an orbax step of a run (the checkpoint folder's old "
                          "steps are deleted); move it, or choose another --out")  # fmt: skip


def train(cfg: TrainConfig, progress: bool = True) -> dict:
    """Train one model; returns a summary (best epoch and validation loss, frames/s, paths).

    The ``closed_loop`` recipe runs :func:`lantern_jax.apps.training.closed_loop.train_closed_loop`.

    Sets this process's allocator to keep freed memory for reuse first
    (:func:`lantern_jax.core.allocator.keep_freed_memory`: training steps about a third faster on
    a CPU, the same weights; ``LANTERN_JAX_MALLOC=system`` leaves it).

    Raises:
        lantern_jax.core.allocator.AllocatorError: ``$LANTERN_JAX_MALLOC`` is neither ``keep``
            nor ``system``.
    """
    keep_freed_memory()
    if cfg.recipe == "closed_loop":
        return train_closed_loop(cfg, progress)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    card = read_card(Path(cfg.dataset))
    frames = load_frames(cfg.dataset, exclude_crossing=cfg.exclude_crossing)
    ex = recipe_examples(frames, card, cfg)
    train_idx, val_idx = split_by_sequence(ex, cfg.val_fraction, cfg.seed)
    mcfg = model_config(cfg, ranges_width(ex, cfg.rig))
    model = load_model(cfg.init_from, expect=mcfg) if cfg.init_from else new_model(mcfg, cfg.seed)
    batches = Batches(ex, train_idx, cfg)
    data = dataset_provenance(card)
    return dict(fit(cfg, model, ex, batches, val_idx, out, progress, info=data), **data)
