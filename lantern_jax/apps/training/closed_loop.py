"""Closed-loop training (DAgger) of a learned driving model: the ``closed_loop`` recipe.

Open-loop behaviour cloning only ever sees the expert's states; in closed loop the model's own
small errors take it to states the expert never visited, where it has no label. DAgger closes
that gap. From an open-loop model (``init_from``), each of ``rounds`` rounds:

1. **collect** — the current model drives ``scenes_per_round`` training scene pairs (Route A
   with its warning and Route B; drawn from the dataset's plan, whose scenes already pass the
   near-duplicate rule against the suite — never the suite's pairs), the expert taking over a
   segment with probability ``beta * beta_decay**round``; every ``visit_every_s`` the visited
   state is kept with the model's observation. With ``no_warning > 0``, that share of the
   pairs also drives Route A *without* its warning, the model alone (``beta`` 0: the
   privileged expert would anticipate the hazard it cannot see), with a visit every
   ``no_warning_every_s``; of those only the visits at which the hazard actor is in the
   model's view are kept (:func:`hazard_in_view`). They are the states of its own reaction to
   the camera, which the warning executions never reach (they brake earlier) and where the
   expert's label is one the observation can explain; before the hazard is seen the
   privileged expert anticipates it from the warning point on, a label no camera could
   justify. With ``distractor_drives > 0``, that share of the pairs also drives Route A told
   a training distractor sentence in place of its warning, the model alone, a visit every
   ``distractor_drive_every_s`` while the sentence is in its observation, each labelled with
   the model's own plan without the sentence
   (:mod:`lantern_jax.apps.training.distractor_drives`);
2. **relabel** — the privileged ``expert`` drives on from each visited state for the 2.5-s
   label horizon; its positions are the label (:mod:`lantern_jax.apps.training.relabel`: the
   dataset's labeller on the expert's continuation). Visits whose horizon crosses a warning
   mark are left out as ``exclude_crossing`` says, like dataset frames;
3. **aggregate and train** — ``epochs`` epochs on the distance recipe's examples, the
   counterfactual warnings (:mod:`lantern_jax.apps.training.counterfactual`) and every relabelled
   visit so far, ``closed_loop_mix`` of every batch drawn from the visits.

Run folder: ``round-<r>/`` per round (``visits.npz``, the round's orbax checkpoints and exported
model, ``done.json`` once finished), and the latest round's model exported as
``<out>/<name>.msgpack`` + ``.json``. A rerun skips finished rounds, reuses a round's saved
visits and resumes its training from the latest epoch.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from pathlib import Path

import jax
import numpy as np

from lantern_jax.apps.dataset.record import data_settings
from lantern_jax.apps.dataset.scenes import PLAN_JSON, SceneSpec
from lantern_jax.apps.dataset.store import dataset_provenance, load_frames, read_card
from lantern_jax.apps.training.config import TrainConfig, parse_family_weights
from lantern_jax.apps.training.counterfactual import frame_counterfactuals
from lantern_jax.apps.training.data import (
    Examples,
    concat,
    observation_field,
    ranges_width,
    recipe_examples,
    split_by_sequence,
)
from lantern_jax.apps.training.distractor_drives import (
    SEQUENCE_SUFFIX,
    distractor_scenarios,
    own_plans,
    text_in_view,
)
from lantern_jax.apps.training.fit import Batches, fit, model_config
from lantern_jax.apps.training.relabel import Visits, relabel_batch
from lantern_jax.core.constants import FAMILIES
from lantern_jax.core.progress import tqdm
from lantern_jax.dynamics.actors import ActorSettings
from lantern_jax.io.files import atomic_write
from lantern_jax.policies.learned.checkpoint import load_model, model_policy, save_model
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import build_pair
from lantern_jax.sim.rollout import horizon_ticks
from lantern_jax.sim.settings import Settings
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.world import tree_stack

CHUNK_PAIRS = 24  # scene pairs per batched collection call (48 executions)
VISITS_NPZ = "visits.npz"
DONE_JSON = "done.json"


def plan_specs(dataset: str | Path) -> list[SceneSpec]:
    """The scene plan of a dataset folder (``plan.json``): its training scenes."""
    path = Path(dataset) / PLAN_JSON
    try:
        body = json.loads(path.read_text())
        return [SceneSpec(**d) for d in body["specs"]]
    except (OSError, ValueError, TypeError, KeyError) as e:
        raise ValueError(f"{path}: no readable scene plan ({e!r})") from None


def round_specs(
    specs: list[SceneSpec], n: int, seed: int, r: int, weights: dict[str, float] | None = None
) -> list[SceneSpec]:
    """``n`` scene pairs for round ``r`` (seeded draw), spread over the families in proportion
    to ``weights`` (family -> weight; a family not named weighs 1; ``None`` or every weight
    equal: evenly, the first ``n % families`` families taking one more).

    Shares are ``n * weight / total`` rounded down, the pairs left over going to the largest
    remainders (ties to the earlier family of :data:`~lantern_jax.core.constants.FAMILIES`); a
    family never gives more pairs than its pool holds."""
    rng = np.random.default_rng([seed, 7, r])
    by_family = {f: [s for s in specs if s.family == f] for f in FAMILIES}
    by_family = {f: v for f, v in by_family.items() if v}
    takes = family_shares(n, [(weights or {}).get(f, 1.0) for f in by_family])
    out: list[SceneSpec] = []
    for take, pool in zip(takes, by_family.values(), strict=True):
        idx = rng.choice(len(pool), min(take, len(pool)), replace=False)
        out += [pool[i] for i in sorted(idx)]
    return out


def family_shares(n: int, weights: list[float]) -> list[int]:
    """``n`` split over families of ``weights`` (> 0): each ``n * w / sum`` rounded down, the
    rest one each to the largest remainders, ties to the earlier family.  Equal weights give
    ``n // k`` each and one more to the first ``n % k``."""
    total = float(sum(weights))
    exact = [n * w / total for w in weights]
    takes = [int(np.floor(e + 1e-9)) for e in exact]
    order = sorted(range(len(weights)), key=lambda k: (-(exact[k] - takes[k]), k))
    for k in order[: n - sum(takes)]:
        takes[k] += 1
    return takes


def _scene_batch(specs: list[SceneSpec]):
    """Route A (warning condition) then Route B scenarios of ``specs``, stacked, as the suite
    runs them (closed loop: the anti-deadlock event rule on)."""

    pairs = [build_pair(s.params, validate=False) for s in specs]
    return tree_stack([p[0] for p in pairs] + [p[1] for p in pairs])


def _route_a_batch(specs: list[SceneSpec]):
    """Route A of ``specs``, stacked, in the warning condition (as the suite runs it)."""

    return tree_stack([build_pair(s.params, validate=False)[0] for s in specs])


def _no_warning_batch(specs: list[SceneSpec]):
    """Route A of ``specs`` in the no-warning condition, stacked (the evaluator's flip of
    ``warning_enabled``)."""

    a = _route_a_batch(specs)
    return a.replace(config=a.config.replace(warning_enabled=np.zeros_like(a.config.is_route_a)))


def hazard_in_view(v: Visits, hazard_index: np.ndarray) -> np.ndarray:
    """(B, V) bool: the visits at which each execution's hazard actor (``hazard_index``: (B,)
    int, actor slot) is in the learner's view (``obs.visible``: the front camera, with the rig
    for a rig learner)."""
    h = np.asarray(hazard_index, np.int64)
    return np.asarray(v.obs.visible, bool)[np.arange(len(h)), :, h]  # (B, V, A) -> (B, V)


def _keep(v: Visits, exclude_crossing: str) -> np.ndarray:
    """(B, V) bool: valid visits the exclusion rule keeps."""
    keep = np.array(v.valid, bool)
    if exclude_crossing in ("both", "onset"):
        keep &= ~np.asarray(v.crosses_onset, bool)
    if exclude_crossing == "both":
        keep &= ~np.asarray(v.crosses_termination, bool)
    return keep


def _chosen(v: Visits, ratio: int, window_s: float) -> np.ndarray:
    """(B, V) bool: the visits of the ordinary grid (every ``ratio``-th) and those within
    ``window_s`` before their execution's first collision."""
    t, t_coll = np.asarray(v.t), np.asarray(v.t_collision)
    grid = (np.arange(t.shape[-1]) % ratio == 0)[None, :]
    return grid | ((t >= t_coll - window_s) & (t < t_coll))


def visits_to_examples(v: Visits, seq_ids: list[str], like: Examples, keep: np.ndarray
                       ) -> Examples:  # fmt: skip
    """The kept visits (``keep``: (B, V) bool) as examples with ``like``'s observation fields
    and dtypes; each carries its execution's sequence id (``seq_ids``: (B,))."""
    b, vv = np.nonzero(keep)
    obs = {k: np.asarray(observation_field(v.obs, k))[b, vv].astype(a.dtype)
           for k, a in like.obs.items()}  # fmt: skip
    base = np.all(obs["warning_tokens"] == PAD_ID, axis=-1)
    targets = np.asarray(v.waypoints)[b, vv].astype(np.float32)
    return Examples(obs, targets, np.asarray(seq_ids)[b].astype(str), base)


def drive_settings(cfg: TrainConfig) -> Settings:
    """The settings every drive of ``cfg``'s rounds runs under: the dataset's
    (:func:`~lantern_jax.apps.dataset.record.data_settings`), with ``cfg.ego_leader``'s actors'
    rule where it names one."""
    settings = data_settings()
    if cfg.ego_leader:
        settings = settings.replace(actors=ActorSettings(ego_leader=cfg.ego_leader))
    return settings


def collect(cfg: TrainConfig, model, like: Examples, specs: list[SceneSpec], r: int,
            progress: bool = False) -> tuple[Examples, dict]:  # fmt: skip
    """Round ``r``'s visits of ``model`` on ``specs``, relabelled by the expert (a progress bar
    over the batched calls when ``progress``); returns (examples, counts: executions, valid
    visits, kept visits, kept visits off the ordinary grid -- those before a collision --, kept
    visits of the no-warning executions and of the distractor drives, the latter labelled with
    the learner's own plan)."""

    learner = model_policy(cfg.name, model)
    lp = learner.init(jax.random.PRNGKey(0))
    expert = get_policy("expert")
    ep = expert.init(jax.random.PRNGKey(0))
    every = horizon_ticks(cfg.visit_every_s)
    phase = int(every * ((r * 0.618) % 1.0))  # a different offset every round
    beta = cfg.beta * cfg.beta_decay**r
    # with failure visits the grid is finer (ratio visits per ordinary one, the beta segments
    # as long as before, so the driven executions are the same); the host keeps the
    # ordinary grid and the visits just before each collision
    ratio = round(cfg.visit_every_s / cfg.failure_every_s) if cfg.failure_window_s > 0 else 1
    num_visits = max(1, int(cfg.max_seconds / cfg.visit_every_s)) * ratio
    parts = []
    counts = dict(executions=0, valid_visits=0, kept_visits=0, failure_visits=0,
                  no_warning_visits=0, distractor_drive_visits=0)  # fmt: skip
    starts = range(0, len(specs), CHUNK_PAIRS)
    if progress:
        starts = tqdm(starts, desc=f"round {r}: drive + relabel", unit="batch")
    for k in starts:
        chunk = specs[k : k + CHUNK_PAIRS]
        ids = [f"{s.family.lower()}_{s.index:05d}_{rt}" for rt in "AB" for s in chunk]
        key = jax.random.PRNGKey(hash((cfg.seed, r, k)) % (2**31))
        v = jax.device_get(relabel_batch(
            _scene_batch(chunk), learner, lp, expert, ep, key, beta=beta,
            num_visits=num_visits, every=every // ratio, phase=phase,
            segment=ratio, settings=drive_settings(cfg)))  # fmt: skip
        chosen = _chosen(v, ratio, cfg.failure_window_s)
        keep = _keep(v, cfg.exclude_crossing) & chosen
        parts.append(visits_to_examples(v, ids, like, keep))
        counts["executions"] += len(ids)
        counts["valid_visits"] += int((np.asarray(v.valid) & chosen).sum())
        counts["kept_visits"] += int(keep.sum())
        counts["failure_visits"] += int((keep & ~_chosen(v, ratio, 0.0)).sum())
    drive = functools.partial(_second_drives, cfg, learner, lp, expert, ep, like, specs, r,
                              counts, progress)  # fmt: skip
    parts += drive(cfg.no_warning, cfg.no_warning_every_s, "no warning", "_A-no-warning",
                   "no_warning_visits",
                   lambda chunk, k: (_no_warning_batch(chunk), drive_settings(cfg)),
                   keep=lambda v, sc: hazard_in_view(v, sc.config.hazard_index))  # fmt: skip
    parts += drive(cfg.distractor_drives, cfg.distractor_drive_every_s, "distractor drives",
                   SEQUENCE_SUFFIX, "distractor_drive_visits",
                   lambda chunk, k: distractor_scenarios(_route_a_batch(chunk),
                                                         cfg.distractor_texts, cfg.seed,
                                                         r * 1000 + k,
                                                         drive_settings(cfg))[:2],
                   keep=lambda v, sc: text_in_view(v.obs),
                   label=lambda v: v.replace(waypoints=np.asarray(jax.device_get(
                       own_plans(lp, v.obs)))))  # fmt: skip
    return concat(parts), counts


def _second_drives(cfg: TrainConfig, learner, lp, expert, ep, like: Examples,
                   specs: list[SceneSpec], r: int, counts: dict, progress: bool, share: float,
                   every_s: float, desc: str, suffix: str, count: str, build, keep,
                   label=None) -> list[Examples]:  # fmt: skip
    """Round ``r``'s second drives of Route A: ``share`` of ``specs`` (spread evenly: specs come
    family by family), the learner alone (beta 0), a visit every ``every_s``.

    ``build(chunk, k)`` gives a chunk's scenarios and settings, ``keep(v,
    scenarios)`` the (B, V) visits kept beside the exclusion rule, ``label(v)`` the visits
    relabelled (default: the expert's label). The kept visits carry the sequence ids
    ``<family>_<index><suffix>`` and are added to ``counts`` (``count`` among them).
    """
    n = round(share * len(specs))
    chosen = [specs[int(i * len(specs) / n)] for i in range(n)]
    every = horizon_ticks(every_s)
    num_visits = max(1, int(cfg.max_seconds / every_s))
    starts = range(0, len(chosen), 2 * CHUNK_PAIRS)  # as many executions as a pair chunk
    if progress and chosen:
        starts = tqdm(starts, desc=f"round {r}: {desc}", unit="batch")
    parts = []
    for k in starts:
        chunk = chosen[k : k + 2 * CHUNK_PAIRS]
        scenarios, settings = build(chunk, k)
        key = jax.random.PRNGKey(0)  # no draw: beta is 0
        v = jax.device_get(relabel_batch(
            scenarios, learner, lp, expert, ep, key, beta=0.0, num_visits=num_visits,
            every=every, phase=int(every * ((r * 0.618) % 1.0)), settings=settings))  # fmt: skip
        kept = _keep(v, cfg.exclude_crossing) & keep(v, scenarios)
        v = v if label is None else label(v)
        ids = [f"{s.family.lower()}_{s.index:05d}{suffix}" for s in chunk]
        parts.append(visits_to_examples(v, ids, like, kept))
        counts["executions"] += len(ids)
        counts["valid_visits"] += int(np.asarray(v.valid).sum())
        counts["kept_visits"] += int(kept.sum())
        counts[count] += int(kept.sum())
    return parts


def _save_examples(path: Path, ex: Examples) -> None:
    arrays = {f"obs.{k}": v for k, v in ex.obs.items()}
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, targets=ex.targets, sequence=ex.sequence, base_style=ex.base_style, **arrays)
    tmp.replace(path)


def _load_examples(path: Path) -> Examples:
    with np.load(path) as z:
        obs = {k[4:]: z[k] for k in z.files if k.startswith("obs.")}
        return Examples(obs, z["targets"], z["sequence"], z["base_style"])


def _dataset_examples(cfg: TrainConfig, card: dict) -> Examples:
    """The distance recipe's examples plus the counterfactual warnings (``card``: the
    dataset's card)."""
    frames = load_frames(cfg.dataset, exclude_crossing=cfg.exclude_crossing)
    ex = recipe_examples(frames, card, dataclasses.replace(cfg, recipe="distance"))
    plain = ex.take(np.arange(len(frames)))  # the frames themselves, before the far copies
    cf = frame_counterfactuals(
        plain, frames, cfg.counterfactual, cfg.seed, cfg.distractors, cfg.distractor_texts,
        cfg.counterfactual_positions, cfg.counterfactual_stated_share,
    )
    return concat([ex, cf])


def train_closed_loop(cfg: TrainConfig, progress: bool = True) -> dict:
    """Run (or resume) the ``closed_loop`` recipe; returns the last round's summary with the
    collection counts and times (s) of every round."""

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    specs = plan_specs(cfg.dataset)
    card = read_card(Path(cfg.dataset))
    data = _dataset_examples(cfg, card)  # (load_frames refuses a folder without a whole card)
    provenance = dataset_provenance(card)
    mcfg = model_config(cfg, ranges_width(data, cfg.rig))
    model = load_model(cfg.init_from, expect=mcfg)
    visits: list[Examples] = []
    rounds, summary = [], {}
    for r in range(cfg.rounds):
        folder = out / f"round-{r}"
        folder.mkdir(exist_ok=True)
        t0 = time.perf_counter()
        if (folder / VISITS_NPZ).exists():
            new, counts = _load_examples(folder / VISITS_NPZ), {}
        else:
            chosen = round_specs(specs, cfg.scenes_per_round, cfg.seed, r,
                                 parse_family_weights(cfg.family_weights))
            new, counts = collect(cfg, model, data, chosen, r, progress)
            _save_examples(folder / VISITS_NPZ, new)
        visits.append(new)
        t_collect = time.perf_counter() - t0
        done = folder / DONE_JSON
        if done.exists():
            summary = json.loads(done.read_text())
        else:
            ex = concat([data, *visits])
            train_idx, val_idx = split_by_sequence(ex, cfg.val_fraction, cfg.seed)
            cl = train_idx[train_idx >= len(data)]
            batches = Batches(ex, train_idx, cfg, pools=((cl, cfg.closed_loop_mix),))
            summary = fit(cfg, model, ex, batches, val_idx, folder, progress,
                          info=dict(round=r, visits=int(sum(len(v) for v in visits)),
                                    **provenance))  # fmt: skip
            summary.update(round=r, visits=len(new), collect_seconds=round(t_collect, 1), **counts)
            atomic_write(done, json.dumps(summary, indent=1, default=str) + "\n")
        model = load_model(folder / f"{cfg.name}.msgpack", expect=mcfg)
        rounds.append(summary)
    save_model(model, out / cfg.name, dict(recipe=cfg.recipe, dataset=str(cfg.dataset),
                                           train_config=dataclasses.asdict(cfg),
                                           rounds=len(rounds), **provenance))  # fmt: skip
    atomic_write(out / "rounds.json", json.dumps(rounds, indent=1, default=str) + "\n")
    return dict(summary, rounds=len(rounds), model=str(out / f"{cfg.name}.msgpack"),
                **provenance)  # fmt: skip
