"""Dataset files: sharded Parquet, a dataset card, resumable writing, validation and a loader.

A dataset folder holds, per generation chunk ``k``:

* ``frames-k.parquet`` — one row per training frame: identity (``sequence_id``, ``family``,
  ``route``, ``weather``, ``frame``, ``t_s``), every field of the policy observation under the
  front camera and the warning sensor as ``obs.<field>`` (front camera: visible objects, range
  image; ego state; navigation; the warning as its token ids and value channel;
  ``obs.range_class`` is the semantic class of each front ray, ``constants.RAY_CLASS_NAMES``:
  actor kinds, then static occluder kinds), the six-camera rig's own view as
  ``surround.visible``, ``surround.ranges``, ``surround.hit_class``, and the fields the rig
  changes in the observation (the actors seen by front camera or rig) as ``rig.visible``,
  ``rig.actor_xy``, ... (``dataset.record``), the ten expert ``waypoints`` (ego frame, x
  forward, y right, 0.25 s apart) and the ``horizon_crossing`` flag;
* ``sequences-k.parquet`` — one row per recorded sequence, accepted or not (with the reason),
  with its event timeline and parameters;

and ``dataset_card.json`` / ``dataset_card.md``: counts per family and route type, frames,
weathers, the acceptance report, the generation seed, package versions, and every shard with
its row count and SHA-256.  Arrays are stored as fixed-size lists (flattened; the card records
each column's shape).

Every shard is written atomically (temporary file + rename) and the card is rewritten after
each chunk, so an interrupted generation resumes from the next chunk and never leaves a half
shard that loads.  :func:`load_frames` refuses a missing or corrupted shard, a schema mismatch, a
folder written by an incompatible version or one whose generation did not finish, naming the
file.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.apps.dataset.frames import horizon_crossing
from lantern_jax.core.constants import FAMILIES
from lantern_jax.io.files import atomic_write

# 2: scenes disjoint from the suite by the near-duplicate rule; 3: static occluders block the
# six-camera rig, rays that hit one are classed as building, wall or parked vehicle, and the
# front rays' classes are an observation field (obs.range_class, was front_class); 4: the
# observation holds only what the declared sensors deliver (unseen actors zero, the warning as
# token ids and value channel only), and the rig's variant of the actor fields (rig.*)
FORMAT_VERSION = 4
PAPER_ROUTE_A = 1631  # sequences in the paper's release
PAPER_ROUTE_B = 1641
PAPER_FRAMES = 236_309  # frames in the paper's release (4 Hz)
CARD_JSON = "dataset_card.json"
CARD_MD = "dataset_card.md"


class DatasetError(ValueError):
    """A dataset folder that cannot be read as written; the message names the file."""


def file_sha256(path: Path) -> str:
    """SHA-256 hex digest of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def dataset_sha256(card: dict) -> str:
    """SHA-256 hex digest naming a dataset's content: over the SHA-256 of every frame and
    sequence shard the card lists, in its order.  Two folders with the same digest hold the
    same recorded frames, whatever their path; a rebuild that records one frame more or less
    (another simulator version) has another.  Training writes it into every exported model's
    description (``dataset_sha256``), so a result names the data it was trained on."""
    parts = [f"{shard['frames_sha256']}:{shard['sequences_sha256']}" for shard in card["shards"]]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def dataset_provenance(card: dict) -> dict:
    """What a trained model's description records of its dataset: ``dataset_sha256``
    (:func:`dataset_sha256`) and ``dataset_frames`` (the card's frame count)."""
    return dict(dataset_sha256=dataset_sha256(card), dataset_frames=int(card["frames"]))


def to_table(columns: dict[str, np.ndarray]) -> tuple[Any, dict[str, list[int]]]:
    """A pyarrow table of the columns (arrays with more than one axis become fixed-size lists
    of their flattened trailing axes) and each column's per-row shape."""
    # deferred: pyarrow (heavy) only when a table is written
    import pyarrow as pa

    arrays, shapes = {}, {}
    for name, col in columns.items():
        col = np.asarray(col)
        shapes[name] = list(col.shape[1:])
        if col.ndim == 1:
            arrays[name] = pa.array(col)
        else:
            flat = col.reshape(col.shape[0], -1)
            arrays[name] = pa.FixedSizeListArray.from_arrays(
                pa.array(flat.reshape(-1)), flat.shape[1]
            )
    return pa.table(arrays), shapes


def write_shard(path: Path, columns: dict[str, np.ndarray]) -> tuple[int, dict]:
    """Write one Parquet shard atomically; returns (rows, column shapes)."""
    # deferred: pyarrow (heavy) only when shards are read or written
    import pyarrow.parquet as pq

    table, shapes = to_table(columns)
    buf = io.BytesIO()
    pq.write_table(table, buf, compression="zstd")
    atomic_write(path, buf.getvalue())
    return table.num_rows, shapes


def read_card(folder: Path) -> dict | None:
    """The dataset card of ``folder`` (None when there is none yet)."""
    path = Path(folder) / CARD_JSON
    if not path.exists():
        return None
    try:
        card = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: not a readable dataset card ({e})") from None
    if card.get("format_version") != FORMAT_VERSION:
        raise DatasetError(
            f"{path}: format_version {card.get('format_version')!r}, this version reads "
            f"{FORMAT_VERSION}"
        )
    return card


def write_card(folder: Path, card: dict) -> None:
    """Write the card (JSON and a Markdown summary) atomically."""
    atomic_write(Path(folder) / CARD_JSON, json.dumps(card, indent=1, sort_keys=True) + "\n")
    atomic_write(Path(folder) / CARD_MD, card_markdown(card))


def card_markdown(card: dict) -> str:
    """A human-readable summary of a dataset card (with the paper's release beside it)."""
    counts = pd.DataFrame(card.get("counts", [])) if card.get("counts") else pd.DataFrame()
    if not counts.empty:  # a card read back from JSON has its keys sorted: fix the order
        counts = counts[["family", "route", "sequences", "frames"]]
    lines = [
        "# LANTERN open-loop dataset",
        "",
        f"Generated by lantern-jax {card.get('packages', {}).get('lantern-jax', '?')} from seed "
        f"{card.get('seed')} ({card.get('pairs_per_family')} candidate pairs per family), "
        f"{card.get('chunks_done')} of {card.get('chunks')} chunks.",
        "",
        f"Sequences: {card.get('sequences_accepted', 0)} accepted "
        f"(Route A {card.get('route_a', 0)}, Route B {card.get('route_b', 0)}), "
        f"{card.get('frames', 0)} frames at 4 Hz.",
        "",
        f"The paper's release: {PAPER_ROUTE_A + PAPER_ROUTE_B} sequences (Route A "
        f"{PAPER_ROUTE_A}, Route B {PAPER_ROUTE_B}), {PAPER_FRAMES} frames.",
        "",
    ]
    if "plan_seconds" in card:
        lines += [f"Time: planning scenes {card['plan_seconds']:.0f} s, recording "
                  f"{card.get('seconds', 0.0):.0f} s.", ""]  # fmt: skip
    if not counts.empty:
        lines += ["## Accepted sequences and frames per family and route", "",
                  counts.to_markdown(index=False), ""]  # fmt: skip
    dup = card.get("suite_near_duplicates_skipped", {})
    if dup:
        lines += [
            "## Candidates skipped as near duplicates of a suite route",
            "",
            "Sampled pairs whose route repeats a route of the frozen suite's same family "
            "(the paper's near-duplicate rule); new candidates were drawn instead.",
            "",
        ]
        order = sorted(dup, key=lambda f: (FAMILIES.index(f) if f in FAMILIES else 99, f))
        lines += [f"* {k}: {dup[k]}" for k in order] + [""]
    rej = card.get("rejected", {})
    if rej:
        lines += ["## Rejected sequences by reason", ""]
        lines += [f"* {k}: {v}" for k, v in sorted(rej.items())] + [""]
    return "\n".join(lines)


def shard_names(k: int) -> tuple[str, str]:
    """File names of chunk ``k``'s frame and sequence shards."""
    return f"frames-{k:05d}.parquet", f"sequences-{k:05d}.parquet"


#: Which frames :func:`load_frames` drops for a waypoint horizon ``(t, t + 2.5 s]`` that
#: crosses a warning mark:
#:
#: * ``"both"`` — onset or termination (the paper: "frames whose prediction horizon crosses
#:   warning onset or termination are excluded"; the default, and what training uses unless
#:   its config says otherwise);
#: * ``"onset"`` — onset only: a frame whose horizon crosses termination keeps its label (the
#:   warning was active at the frame, and its label is the driving that followed it).  With the
#:   short warnings of this protocol (onset to event <= 2 s, termination when the hazard is first
#:   seen) the paper's rule leaves no warning-active frame at all in four of six families; this
#:   variant measures what that costs (README, "Learned policies");
#: * ``"none"`` — every frame.
EXCLUDE_CROSSING = ("both", "onset", "none")


def _read_shards(folder: Path, card: dict, kind: str, columns: list[str] | None) -> pd.DataFrame:
    """Every ``kind`` (``"frames"`` / ``"sequences"``) shard listed in the card, hash-checked."""
    # deferred: pyarrow (heavy) only when shards are read or written
    import pyarrow.parquet as pq

    schema = card["frame_columns"] if kind == "frames" else None
    parts = []
    for shard in card["shards"]:
        path = folder / shard[kind]
        if not path.exists():
            raise DatasetError(f"{path}: missing shard listed in {CARD_JSON}")
        if file_sha256(path) != shard[f"{kind}_sha256"]:
            raise DatasetError(f"{path}: content does not match its SHA-256 in {CARD_JSON}")
        try:
            table = pq.read_table(path, columns=columns)
        except Exception as e:  # noqa: BLE001 - any read failure is a corrupted shard
            raise DatasetError(f"{path}: not a readable Parquet shard ({e})") from None
        if schema is not None:
            names, want = table.column_names, columns or list(schema)
            if sorted(names) != sorted(want):
                raise DatasetError(f"{path}: columns {sorted(set(names) ^ set(want))} differ "
                                   f"from the card's schema")  # fmt: skip
        parts.append(table.to_pandas())
    if parts:
        return pd.concat(parts, ignore_index=True)
    return pd.DataFrame(columns=list(schema) if schema is not None else columns)


def _open_card(folder: Path) -> dict:
    """The card of a dataset folder whose generation finished (an interrupted one would give a
    part of the dataset as if it were the whole)."""
    card = read_card(folder)
    if card is None:
        raise DatasetError(f"{folder / CARD_JSON}: missing (not a dataset folder?)")
    if card.get("chunks_done") != card.get("chunks"):
        raise DatasetError(
            f"{folder / CARD_JSON}: {card.get('chunks_done')} of {card.get('chunks')} chunks "
            f"recorded (the generation was interrupted); run the same 'lantern-jax dataset "
            f"--out {folder}' command again to finish it"
        )
    return card


def load_sequences(folder: str | Path, columns: list[str] | None = None) -> pd.DataFrame:
    """Every recorded sequence of a dataset folder (accepted or not), validated against its card:
    identity, acceptance and reason, frame count, parameters and the event timeline
    (``t_warn_on``, ``t_event``, ``t_warn_off``, ``t_clear``, s; ``NEVER`` = did not happen).

    Raises:
        DatasetError: as :func:`load_frames`.
    """
    folder = Path(folder)
    return _read_shards(folder, _open_card(folder), "sequences", columns)


def load_frames(
    folder: str | Path,
    include_crossing: bool = False,
    columns: list[str] | None = None,
    exclude_crossing: str = "both",
) -> pd.DataFrame:
    """Every frame of a dataset folder, validated against its card.

    Args:
        folder: the dataset folder.
        include_crossing: keep every frame (same as ``exclude_crossing="none"``).
        columns: only these columns (default: all).
        exclude_crossing: which horizon-crossing frames to drop, one of
            :data:`EXCLUDE_CROSSING` (default ``"both"``, the paper's rule).

    Raises:
        DatasetError: naming the card or shard that is missing, corrupted (hash mismatch), of
            another format version, or whose columns differ from the card's schema.
        ValueError: an unknown ``exclude_crossing``.
    """
    if exclude_crossing not in EXCLUDE_CROSSING:
        raise ValueError(
            f"exclude_crossing: {exclude_crossing!r} is not one of {', '.join(EXCLUDE_CROSSING)}"
        )
    folder = Path(folder)
    card = _open_card(folder)
    rule = "none" if include_crossing else exclude_crossing
    need = {
        "both": ["horizon_crossing"], "onset": ["sequence_id", "route", "t_s"], "none": []
    }[rule]  # fmt: skip
    read = None if columns is None else list(dict.fromkeys([*columns, *need]))
    frames = _read_shards(folder, card, "frames", read)
    if rule == "both" and "horizon_crossing" in frames:
        keep = ~frames["horizon_crossing"].astype(bool).to_numpy()
    elif rule == "onset" and len(frames):
        seq = load_sequences(folder, ["sequence_id", "t_warn_on"]).set_index("sequence_id")
        onset = seq["t_warn_on"].reindex(frames["sequence_id"]).to_numpy()
        # as in generation, a Route B sequence has no warning marks
        onset = np.where(frames["route"].to_numpy() == "A", onset, np.nan)
        t = frames["t_s"].to_numpy(np.float32)
        keep = ~horizon_crossing(t, onset)
    else:
        keep = np.ones(len(frames), bool)
    frames = frames[keep].reset_index(drop=True)
    return frames if columns is None else frames[list(columns)]


def column_array(frames: pd.DataFrame, name: str, shape: list[int]) -> np.ndarray:
    """A stored column as an array of shape ``(rows, *shape)``."""
    col = frames[name].to_numpy()
    if not shape:
        return np.asarray(col)
    return np.stack(col).reshape(len(frames), *shape)


def batches(
    frames: pd.DataFrame, card: dict, batch_size: int, seed: int, columns: list[str]
) -> Any:
    """A seeded, shuffled stream of batches (dicts of arrays) over ``frames``: a
    ``grain.MapDataset`` (one pass; re-create it with another seed for the next epoch)."""
    # deferred: grain (heavy) only when batches are drawn
    import grain

    arrays = {c: column_array(frames, c, card["frame_columns"][c]) for c in columns}
    n = len(frames)
    ds = grain.MapDataset.source(np.arange(n)).shuffle(seed=seed).batch(batch_size)
    return ds.map(lambda idx: {c: a[np.asarray(idx)] for c, a in arrays.items()})
