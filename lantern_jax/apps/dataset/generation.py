"""Generate the open-loop dataset: plan scenes, record the expert chunk by chunk, write shards.

:func:`generate_dataset` is what ``lantern-jax dataset`` runs.  Scenes are planned once from the
seed (:func:`~lantern_jax.apps.dataset.scenes.plan_scenes`); chunk ``k`` holds the next
``chunk_pairs`` pairs, whose Route A and Route B executions are recorded in one batched call
(:mod:`~lantern_jax.apps.dataset.record`), turned into frames and accepted or rejected
(:mod:`~lantern_jax.apps.dataset.frames`) and written as two shards plus an updated card
(:mod:`~lantern_jax.apps.dataset.store`).  A folder that already holds some chunks of the same plan
is resumed from the next chunk, from the scenes kept in its ``plan.json`` (they are not sampled and
checked again); a folder of another plan (seed, size, chunking, format) is refused.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.apps.dataset import frames as fr
from lantern_jax.apps.dataset.record import FRAME_TICKS, RIG_FIELDS, batched_recorder
from lantern_jax.apps.dataset.scenes import (
    DATASET_SEED,
    PAIRS_PER_FAMILY,
    PLAN_JSON,
    SceneSpec,
    build_scenes,
    plan_scenes,
    read_plan,
    write_plan,
)
from lantern_jax.apps.dataset.store import (
    FORMAT_VERSION,
    DatasetError,
    file_sha256,
    read_card,
    shard_names,
    write_card,
    write_shard,
)
from lantern_jax.apps.evaluation import package_versions
from lantern_jax.core import family_codes
from lantern_jax.core.constants import DT, FAMILIES, WEATHERS
from lantern_jax.core.progress import tqdm
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.metrics import finalize
from lantern_jax.types.world import tree_stack

CHUNK_PAIRS = 96  # pairs per chunk: 192 recorded sequences per batched call
MAX_SECONDS = 80.0  # s, recording cap (>= the longest route timeout, 20 s + 164 m / 3 m/s)
#: Frames of a recorded execution: :data:`MAX_SECONDS` at one frame per ``FRAME_TICKS`` ticks.
NUM_FRAMES = int(np.ceil(MAX_SECONDS / (FRAME_TICKS * DT)))


def _plan_key(seed: int, pairs_per_family: int, chunk_pairs: int,
              families: Sequence[str] = FAMILIES) -> dict:  # fmt: skip
    key = dict(seed=seed, pairs_per_family=pairs_per_family, chunk_pairs=chunk_pairs,
               format_version=FORMAT_VERSION)  # fmt: skip
    if tuple(families) != FAMILIES:  # the six's key is what it was before other families
        key["families"] = list(families)
    return key


def _new_card(key: dict, n_chunks: int) -> dict:
    return dict(**key, chunks=n_chunks, chunks_done=0, shards=[], frames=0,
                sequences_recorded=0, sequences_accepted=0, route_a=0, route_b=0,
                counts=[], rejected={}, weathers={}, frame_columns={}, seconds=0.0,
                packages=package_versions())  # fmt: skip


def _sequence_columns(seq_id: str, spec: SceneSpec, route: str, rec: Any, idx: np.ndarray,
                      protocol: Any) -> dict[str, np.ndarray]:  # fmt: skip
    """The frame columns of one accepted sequence (see :mod:`lantern_jax.apps.dataset.store`)."""
    n = len(idx)
    t = np.asarray(rec.t)[idx]
    ego_xy, ego_yaw = np.asarray(rec.ego_xy), np.asarray(rec.ego_yaw)
    wps = np.stack([fr.future_waypoints(ego_xy, ego_yaw, int(f)) for f in idx]).astype(np.float32)
    cols: dict[str, np.ndarray] = dict(
        sequence_id=np.full(n, seq_id), family=np.full(n, spec.family),
        route=np.full(n, route), weather=np.full(n, spec.weather),
        frame=idx.astype(np.int32), t_s=t.astype(np.float32),
    )  # fmt: skip
    for f in dataclasses.fields(rec.obs):
        value = getattr(rec.obs, f.name)
        if value is not None:
            cols[f"obs.{f.name}"] = np.asarray(value)[idx]
    for f in dataclasses.fields(rec.rig.surround):
        cols[f"surround.{f.name}"] = np.asarray(getattr(rec.rig.surround, f.name))[idx]
    for name in RIG_FIELDS:
        cols[f"rig.{name}"] = np.asarray(getattr(rec.rig, name))[idx]
    cols["waypoints"] = wps
    on = float(protocol.t_warn_on) if route == "A" else float("nan")
    off = float(protocol.t_warn_off) if route == "A" else float("nan")
    cols["horizon_crossing"] = fr.horizon_crossing(t, on, off)
    return cols


def _record_chunk(specs: list[SceneSpec], recorder: Any, params: Any) -> tuple[dict, list, dict]:
    """Record a chunk; returns (frame columns, sequence rows, rejects by reason)."""
    a_list, b_list = build_scenes(specs)
    batch = tree_stack(a_list + b_list)
    recs, final = recorder(batch, params)
    recs, final = jax.device_get((recs, final))
    metrics = jax.device_get(finalize(final.telemetry))
    roles, valid = np.asarray(batch.actors.role), np.asarray(batch.actors.valid)
    coincident = np.asarray(batch.config.s_event <= batch.config.s_warn)
    parts, rows, rejects = [], [], {}
    n = len(specs)
    for j in range(2 * n):
        spec, route = specs[j % n], ("A" if j < n else "B")
        one = jax.tree.map(lambda x, j=j: x[j], recs)
        proto = jax.tree.map(lambda x, j=j: x[j], final.protocol)
        m = jax.tree.map(lambda x, j=j: x[j], metrics)
        why = fr.rejection(route == "A", one, proto, m, roles[j], valid[j], bool(coincident[j]))
        seq_id = f"{spec.family.lower()}_{spec.index:05d}_{route}"
        idx = fr.frame_indices(one)
        if why is None:
            parts.append(_sequence_columns(seq_id, spec, route, one, idx, proto))
        else:
            rejects[why] = rejects.get(why, 0) + 1
        rows.append(dict(
            sequence_id=seq_id, family=spec.family, route=route, weather=spec.weather,
            pair_sha256=spec.sha256, accepted=why is None, reason=why or "",
            frames=len(idx) if why is None else 0, params=json.dumps(spec.params, sort_keys=True),
            **{k: float(getattr(proto, k)) for k in ("t_warn_on", "t_event", "t_warn_off",
                                                      "t_clear")},
        ))  # fmt: skip
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}
    return cols, rows, rejects


def _update_card(card: dict, k: int, names: tuple, rows: list, rejects: dict, n_frames: int,
                 shapes: dict, folder: Path) -> None:  # fmt: skip
    card["shards"].append(dict(chunk=k, frames=names[0], sequences=names[1], rows=n_frames,
                               frames_sha256=file_sha256(folder / names[0]),
                               sequences_sha256=file_sha256(folder / names[1])))  # fmt: skip
    card["chunks_done"] = k + 1
    card["frames"] += n_frames
    card["sequences_recorded"] += len(rows)
    acc = [r for r in rows if r["accepted"]]
    card["sequences_accepted"] += len(acc)
    card["route_a"] += sum(r["route"] == "A" for r in acc)
    card["route_b"] += sum(r["route"] == "B" for r in acc)
    for why, c in rejects.items():
        card["rejected"][why] = card["rejected"].get(why, 0) + c
    counts = {(c["family"], c["route"]): c for c in card["counts"]}
    for r in acc:
        c = counts.setdefault(
            (r["family"], r["route"]),
            dict(family=r["family"], route=r["route"], sequences=0, frames=0),
        )
        c["sequences"] += 1
        c["frames"] += r["frames"]
        card["weathers"][r["weather"]] = card["weathers"].get(r["weather"], 0) + 1
    card["counts"] = sorted(
        counts.values(), key=lambda c: (family_codes.index(c["family"]), c["route"])
    )
    if shapes:
        card["frame_columns"] = shapes


def generate_dataset(
    out: str | Path,
    pairs_per_family: int = PAIRS_PER_FAMILY,
    seed: int = DATASET_SEED,
    chunk_pairs: int = CHUNK_PAIRS,
    progress: bool = True,
    families: Sequence[str] = FAMILIES,
) -> dict:
    """Generate (or resume) a dataset in ``out``; returns the final card.

    ``families`` are the scene families to record (default: the six of the training data; a
    registered family, :mod:`lantern_jax.scenarios.registry`, is recorded like them).

    Raises:
        DatasetError: when ``out`` holds a dataset of another plan.
        ValueError: for non-positive sizes.
    """
    if pairs_per_family < 1 or chunk_pairs < 1:
        raise ValueError(f"pairs_per_family and chunk_pairs must be >= 1, got "
                         f"{pairs_per_family}, {chunk_pairs}")  # fmt: skip
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    key = _plan_key(seed, pairs_per_family, chunk_pairs, families)
    card = read_card(folder)
    if card is not None and any(card.get(k) != v for k, v in key.items()):
        raise DatasetError(f"{folder / 'dataset_card.json'}: written for another plan "
                           f"{ {k: card.get(k) for k in key} }, not {key}")  # fmt: skip
    suite = load_suite()
    kept = read_plan(folder, key, suite.suite_sha256)
    if kept is None and card is not None and (folder / PLAN_JSON).exists():
        raise DatasetError(f"{folder / PLAN_JSON}: made for another plan or suite than "
                           "this folder's recorded chunks; start a new folder")  # fmt: skip
    if kept is None:
        near_duplicates: dict[str, int] = {}
        t_plan = time.perf_counter()
        specs = plan_scenes(
            pairs_per_family, seed, suite, rejected=near_duplicates, progress=progress,
            families=families,
        )  # fmt: skip
        info = dict(suite_near_duplicates_skipped=near_duplicates,
                    plan_seconds=round(time.perf_counter() - t_plan, 1))  # fmt: skip
        write_plan(folder, key, suite.suite_sha256, specs, info)
    else:
        specs, info = kept
    if card is None:
        card = _new_card(key, 0)
    card.update(info)
    chunks = [specs[i : i + chunk_pairs] for i in range(0, len(specs), chunk_pairs)]
    card["chunks"] = len(chunks)
    expert = get_policy("expert")
    params = expert.init(jax.random.PRNGKey(0))
    recorder = batched_recorder(expert, NUM_FRAMES)
    bar = None
    if progress:
        bar = tqdm(total=len(chunks), initial=card["chunks_done"], desc="dataset", unit="chunk")
    t0 = time.perf_counter()
    for k in range(card["chunks_done"], len(chunks)):
        cols, rows, rejects = _record_chunk(chunks[k], recorder, params)
        names = shard_names(k)
        n_frames, shapes = write_shard(folder / names[0], cols) if cols else (0, {})
        write_shard(folder / names[1], {c: np.asarray(pd.DataFrame(rows)[c]) for c in rows[0]})
        _update_card(card, k, names, rows, rejects, n_frames, shapes, folder)
        card["seconds"] = round(card["seconds"] + time.perf_counter() - t0, 1)
        t0 = time.perf_counter()
        write_card(folder, card)
        if bar is not None:
            bar.set_postfix_str(f"A {card['route_a']} B {card['route_b']} frames {card['frames']}")
            bar.update(1)
    if bar is not None:
        bar.close()
    card["weathers"] = {w: card["weathers"].get(w, 0) for w in WEATHERS}
    write_card(folder, card)
    return card
