"""Training examples from the open-loop dataset: observations, targets and recipes.

Every example is a policy :class:`~lantern_jax.types.observation.Observation` rebuilt from a dataset
frame's ``obs.<field>`` columns — for the six-camera rig with the ``rig.<field>`` and
``surround.<field>`` columns in their place (:mod:`lantern_jax.apps.dataset.record`) — so training
and the closed loop feed the model exactly the observation its sensors deliver, through the
same feature code; and the frame's ten expert waypoints.  :func:`recipe_examples` selects and edits
frames as the training recipe says (:mod:`lantern_jax.apps.training.config`); the validation split
holds out whole sequences.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.apps.dataset.record import RIG_FIELDS
from lantern_jax.apps.dataset.store import column_array
from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.core.constants import FAMILIES, NUM_WAYPOINTS
from lantern_jax.scenarios.warnings import text_tables
from lantern_jax.types.language import PAD_ID, round_number
from lantern_jax.types.observation import Observation

OBS_PREFIX = "obs."


@dataclasses.dataclass
class Examples:
    """Training examples as NumPy arrays with a leading example axis."""

    obs: dict[str, np.ndarray]  # Observation field -> (n, ...) array
    targets: np.ndarray  # (n, 10, 2) float32, m, ego frame
    sequence: np.ndarray  # (n,) str, sequence id
    base_style: np.ndarray  # (n,) bool, ordinary driving (no active warning in the text channel)

    def __len__(self) -> int:
        return len(self.targets)

    def take(self, idx: np.ndarray) -> Examples:
        """The examples at ``idx``."""
        return Examples({k: v[idx] for k, v in self.obs.items()}, self.targets[idx],
                        self.sequence[idx], self.base_style[idx])  # fmt: skip


# the six-camera rig's own view, as surround_<field> (Observation.surround)
SURROUND_COLUMNS = ("surround.visible", "surround.ranges", "surround.hit_class")


def observation_columns(
    frames: pd.DataFrame, card: dict, rig: str = "front"
) -> dict[str, np.ndarray]:
    """Observation fields from a dataset's ``obs.<field>`` columns; for ``rig="surround"`` the
    fields the six-camera rig changes come from its ``rig.<field>`` columns and its own view
    from the ``surround.<field>`` columns (as ``surround_<field>``).

    Raises:
        ValueError: naming a column the dataset does not store (a dataset recorded by another
            version of the simulator).
    """
    shapes = card["frame_columns"]
    out = {}
    for f in dataclasses.fields(Observation):
        col = OBS_PREFIX + f.name
        if col not in shapes:
            if f.default is not dataclasses.MISSING:
                continue  # an optional field (e.g. privileged data) the dataset does not carry
            raise ValueError(f"dataset: column {col!r} missing (recorded by another version?)")
        out[f.name] = column_array(frames, col, shapes[col])
    if rig == "surround":
        for name in (*SURROUND_COLUMNS, *(f"rig.{k}" for k in RIG_FIELDS)):
            if name not in shapes:
                raise ValueError(f"dataset: column {name!r} missing (recorded by another version?)")
            value = column_array(frames, name, shapes[name])
            out[name[len("rig.") :] if name.startswith("rig.") else name.replace(".", "_")] = value
    return out


def ranges_width(ex: Examples, rig: str) -> int:
    """N, the width of the range image a model of ``rig`` reads in these examples."""
    return ex.obs["surround_ranges" if rig == "surround" else "range_image"].shape[1]


def observation_field(obs: Observation, name: str) -> Any:
    """An example column's values from a (batched) observation: ``surround_<field>`` from its
    six-camera view, any other name from the field itself."""
    if name.startswith("surround_"):
        return getattr(obs.surround, name[len("surround_") :])
    return getattr(obs, name)


def examples_from_frames(frames: pd.DataFrame, card: dict, rig: str = "front") -> Examples:
    """Every frame as an example (observations as ``rig`` sees them)."""
    obs = observation_columns(frames, card, rig)
    targets = column_array(frames, "waypoints", [NUM_WAYPOINTS, 2]).astype(np.float32)
    no_text = np.all(obs["warning_tokens"] == PAD_ID, axis=-1)
    return Examples(obs, targets, frames["sequence_id"].to_numpy(str), no_text)


def _far_counterexamples(ex: Examples, frames: pd.DataFrame, far_m: float) -> Examples:
    """Route B frames told of their family's hazard far ahead (its canonical text, grounded at
    ``(far_m, 0.5)`` m), with the ordinary trajectory."""

    is_b = frames["route"].to_numpy(str) == "B"
    sel = ex.take(np.flatnonzero(is_b))
    tables = text_tables()
    fam = np.asarray([FAMILIES.index(f) for f in frames["family"].to_numpy(str)[is_b]])
    obs = dict(sel.obs)
    values = np.zeros(obs["warning_values"].shape, np.float32)
    rows = np.arange(len(sel))
    values[rows, tables.x_slot[fam]] = float(round_number(far_m))
    values[rows, tables.y_slot[fam]] = float(round_number(0.5))
    obs["warning_tokens"] = tables.tokens[fam]
    obs["warning_values"] = values
    return Examples(obs, sel.targets, sel.sequence, np.zeros(len(sel), bool))


def concat(parts: list[Examples]) -> Examples:
    """Examples of several sets, in order."""
    return Examples({k: np.concatenate([p.obs[k] for p in parts]) for k in parts[0].obs},
                    np.concatenate([p.targets for p in parts]),
                    np.concatenate([p.sequence for p in parts]),
                    np.concatenate([p.base_style for p in parts]))  # fmt: skip


def recipe_examples(frames: pd.DataFrame, card: dict, cfg: TrainConfig) -> Examples:
    """The examples of a recipe (see :mod:`lantern_jax.apps.training.config`)."""
    ex = examples_from_frames(frames, card, cfg.rig)
    if cfg.recipe == "base":
        return ex.take(np.flatnonzero(ex.base_style))
    if cfg.recipe == "distance":
        return concat([ex, _far_counterexamples(ex, frames, cfg.far_m)])
    return ex


def split_by_sequence(ex: Examples, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(train indices, validation indices): whole sequences held out, never single frames.

    Sequences are ranked by a seeded SHA-256 of their id and the first ``round(fraction * n)``
    (at least one when ``fraction > 0`` and there are two or more sequences) are held out, so the
    split is exact in size, independent of frame order, and the same for the same seed.
    """

    def rank(seq: str) -> int:
        return int.from_bytes(hashlib.sha256(f"{seed}:{seq}".encode()).digest()[:8], "big")

    seqs = sorted(np.unique(ex.sequence), key=rank)
    n_val = int(round(fraction * len(seqs)))
    if fraction > 0 and len(seqs) > 1:
        n_val = min(max(n_val, 1), len(seqs) - 1)
    val_seq = set(seqs[:n_val])
    is_val = np.asarray([s in val_seq for s in ex.sequence])
    return np.flatnonzero(~is_val), np.flatnonzero(is_val)
