"""The training loop shared by every recipe: mini-batches, the loss, AdamW with a one-cycle
schedule, validation, per-epoch orbax checkpoints (a rerun resumes), the exported best model and
the learning curve.

:func:`~lantern_jax.apps.training.behaviour_cloning.train` (the dataset recipes) and
:func:`~lantern_jax.apps.training.closed_loop.train_closed_loop` (DAgger rounds) both call
:func:`fit`.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pandas as pd
from flax import nnx

from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.apps.training.data import Examples
from lantern_jax.core.progress import tqdm
from lantern_jax.io.files import atomic_write
from lantern_jax.policies.learned.checkpoint import save_model
from lantern_jax.policies.learned.features import features, nav_token_table
from lantern_jax.policies.learned.model import ModelConfig, modes_loss, reads_word_pairs
from lantern_jax.types.language import load_embedding
from lantern_jax.types.observation import Observation, SurroundView


def model_config(cfg: TrainConfig, ranges: int) -> ModelConfig:
    """The architecture a training config asks for."""
    return ModelConfig(rig=cfg.rig, language=cfg.language, width=cfg.width, heads=cfg.heads,
                       layers=cfg.layers, ranges=ranges, text_encoder=cfg.text_encoder,
                       text_layers=cfg.text_layers, object_pool=cfg.object_pool,
                       modes=cfg.modes)  # fmt: skip


def _observation(batch: dict[str, Any]) -> Observation:
    """An Observation from example columns (``surround_*`` columns form its six-camera view,
    :func:`~lantern_jax.apps.training.data.observation_columns`)."""
    names = {f.name for f in dataclasses.fields(Observation)}
    obs = {k: v for k, v in batch.items() if k in names}
    if "surround_visible" in batch:
        obs["surround"] = SurroundView(
            batch["surround_visible"], batch["surround_ranges"], batch["surround_hit_class"]
        )
    return Observation(**obs)


def text_vocabulary(warning_tokens: np.ndarray, nav_tokens: np.ndarray) -> np.ndarray:
    """(U,) int32 sorted ids of every token a model can read in these examples: their warning
    texts' (``warning_tokens``, (n, L) int32) and the navigation instructions' (``nav_tokens``,
    (3, L) int32), padding included (the vocabulary a bigram reader's
    :meth:`~lantern_jax.policies.learned.model.DrivingModel.word_tables` projects)."""
    ids = np.concatenate([np.asarray(warning_tokens).ravel(), np.asarray(nav_tokens).ravel()])
    return np.unique(ids).astype(np.int32)


def make_loss(graphdef: Any, rig: str, driven: bool = False):
    """``loss(params, obs_batch, targets, embedding, nav, vocabulary=None) -> ()`` over a
    batch: the mean L1 (m) of the model's plan, or for a model with ``modes`` > 1 the mean of
    :func:`~lantern_jax.policies.learned.model.modes_loss` (the nearest plan's L1 plus the
    weighted cross-entropy of the scores), which training minimises.  ``driven``: the mean L1
    of the plan the model drives instead (the validation figure; for one mode the same value).
    With ``vocabulary`` ((U,) int32, :func:`text_vocabulary` of the examples) a bigram reader
    projects the vocabulary's rows once for the batch instead of every token slot of every
    example (:class:`~lantern_jax.policies.learned.model.WordTables`); other models ignore
    it."""

    def loss(params, obs, targets, embedding, nav, vocabulary=None):
        model = nnx.merge(graphdef, params)
        tables = None if vocabulary is None else model.word_tables(embedding, vocabulary)
        if model.config.modes == 1:
            pred = jax.vmap(lambda o: model(features(o, rig, embedding, nav), tables))(
                _observation(obs)
            )
            return jnp.mean(jnp.abs(pred - targets))
        plans, scores = jax.vmap(lambda o: model.plans(features(o, rig, embedding, nav), tables))(
            _observation(obs)
        )
        objective, driven_l1 = jax.vmap(modes_loss)(plans, scores, targets)
        return jnp.mean(driven_l1 if driven else objective)

    return loss


#: Training steps per compiled call.  A group's steps run in order inside one program (a
#: ``lax.scan`` of the step), so the host's work around a call -- dispatching it with the
#: parameters', the optimiser's and the batch's arrays, reading the loss back -- is paid once
#: per group, and the next group's batches are gathered while this one runs.  The weights are
#: the bits one call per step gave (``tests/test_training.py``); a closed-loop round's training
#: loop about a tenth shorter on a 2-core CPU (docs/performance.md, "Eight steps a call").
STEPS_PER_CALL = 8


@dataclasses.dataclass(frozen=True)
class StepGroup:
    """The batches of consecutive training steps run by one call (:func:`step_groups`)."""

    idx: np.ndarray  # (size, batch) int, example indices, one row per step
    valid: np.ndarray  # (size,) bool, False for the rows that pad the epoch's last group

    @property
    def steps(self) -> int:
        """The group's real steps."""
        return int(self.valid.sum())

    @property
    def examples(self) -> int:
        """Examples its real steps train on."""
        return self.steps * int(self.idx.shape[1])


def step_groups(batches: list[np.ndarray], size: int) -> list[StepGroup]:
    """An epoch's batches (equal-sized index arrays, in order) as groups of ``size`` steps; the
    last group is padded with copies of the epoch's last batch, marked not ``valid``.

    Raises:
        ValueError: for batches of different sizes (one compiled program serves every group).
    """
    if len({len(b) for b in batches}) > 1:
        raise ValueError(f"step_groups: batches of sizes {sorted({len(b) for b in batches})}; "
                         "a group's batches must be equal-sized")  # fmt: skip
    groups = []
    for k in range(0, len(batches), size):
        part = list(batches[k : k + size])
        valid = np.arange(size) < len(part)
        part += [part[-1]] * (size - len(part))
        groups.append(StepGroup(np.stack(part), valid))
    return groups


class Batches:
    """Seeded mini-batches of training indices: every batch draws ``base_mix`` of its rows from
    the ordinary-driving frames (coop, distance, closed_loop) and ``pools``' shares from their
    index pools (closed_loop: the relabelled visits), the rest in a shuffled pass."""

    def __init__(self, ex: Examples, train_idx: np.ndarray, cfg: TrainConfig,
                 pools: tuple[tuple[np.ndarray, float], ...] = ()):  # fmt: skip
        self.train_idx, self.cfg = train_idx, cfg
        base_idx = train_idx[ex.base_style[train_idx]]
        mix = cfg.base_mix if cfg.recipe in ("coop", "distance", "closed_loop") else 0.0
        self.pools = tuple((idx, share) for idx, share in ((base_idx, mix), *pools) if len(idx))

    def epoch(self, e: int) -> list[np.ndarray]:
        """The batches of epoch ``e`` (index arrays; the same for the same seed and epoch)."""
        rng = np.random.default_rng([self.cfg.seed, e])
        order = rng.permutation(self.train_idx)
        bs = self.cfg.batch_size
        n_pool = [int(round(share * bs)) for _, share in self.pools]
        main = max(1, bs - sum(n_pool))
        out = []
        for k in range(len(order) // main):
            idx = [order[k * main : (k + 1) * main]]
            idx += [
                rng.choice(pool, n) for (pool, _), n in zip(self.pools, n_pool, strict=True) if n
            ]
            out.append(np.concatenate(idx))
        return out


def _checkpointer(folder: Path):
    # deferred: orbax (heavy) only when checkpoints are written
    import orbax.checkpoint as ocp

    opts = ocp.CheckpointManagerOptions(max_to_keep=2)
    return ocp.CheckpointManager(folder.resolve() / "checkpoints", options=opts)


def fit(cfg: TrainConfig, model: Any, ex: Examples, batches: Batches, val_idx: np.ndarray,
        out: Path, progress: bool = True, info: dict | None = None) -> dict:  # fmt: skip
    """``cfg.epochs`` epochs of ``model`` on the batches of ``ex``, checkpointed in ``out``
    (a rerun resumes from the latest epoch); exports the best model (validation L1 on
    ``val_idx``) as ``out/<name>.msgpack`` with ``info`` added to its description.  Runs
    :data:`STEPS_PER_CALL` steps per compiled call (:func:`step_groups`).

    Returns:
        The run's summary (best validation L1 in m and its epoch, examples, frames/s, path).
    """
    # deferred: orbax (heavy) only when checkpoints are written
    import orbax.checkpoint as ocp

    graphdef, params = nnx.split(model)
    embedding = jnp.asarray(load_embedding(), jnp.float32)
    nav = jnp.asarray(nav_token_table())
    per_epoch = max(1, len(batches.epoch(0)))
    steps = per_epoch * cfg.epochs
    schedule = optax.warmup_cosine_decay_schedule(
        0.0, cfg.lr, max(1, int(cfg.warmup * steps)), steps, cfg.lr * 0.01
    )
    # The schedule stays inside the compiled step, although its step counts then make every
    # run's step (and every closed-loop round's, whose example count grows) a program of its
    # own: learning rates computed apart and passed in (compiled alone or op by op) differ from
    # the in-step values in the last bits on about half the steps, so the same config would no
    # longer retrain the shipped weights bit for bit.
    tx = optax.adamw(schedule, weight_decay=cfg.weight_decay)
    opt_state = tx.init(params)
    loss_fn = make_loss(graphdef, cfg.rig)

    # The embedding table (32,000 x 256 float32, 33 MB) and the navigation tokens are arguments
    # of the compiled programs, not constants closed over: a constant is copied into the
    # compiled program, which JAX's persistent cache then serialises, compresses and writes.
    # Each of the two programs took 6.7-8.1 s to compile that way against 0.7-1.9 s now (2-core
    # CPU, ``benchmarks/bench_fit_compile.py``); the weights are the same bits.
    # A bigram reader reads its words through the projected rows of the examples' vocabulary
    # (a few hundred ids) instead of projecting all B x 48 token slots of every batch
    # (docs/learned.md, "The bigram reader's vocabulary").
    vocab = None
    if reads_word_pairs(model.config):
        vocab = jnp.asarray(text_vocabulary(ex.obs["warning_tokens"], np.asarray(nav)))

    @jax.jit
    def steps_with(params, opt_state, obs, targets, valid, embedding, nav, vocab):
        """``valid.shape[0]`` training steps in order (``obs`` and ``targets`` one batch per
        step along their leading axis); a step whose ``valid`` is False leaves the parameters
        and the optimiser's state as they were.  Returns them and each step's loss."""

        def one(carry, batch):
            p, o = carry
            ob, tg, ok = batch
            value, grads = jax.value_and_grad(loss_fn)(p, ob, tg, embedding, nav, vocab)
            updates, o_next = tx.update(grads, o, p)
            p_next = optax.apply_updates(p, updates)
            kept = (jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, old)
                    for new, old in ((p_next, p), (o_next, o)))  # fmt: skip
            return tuple(kept), value

        (params, opt_state), values = jax.lax.scan(one, (params, opt_state), (obs, targets, valid))
        return params, opt_state, values

    def run_group(params, opt_state, group: StepGroup):  # gathers its batches, sends them
        b = ex.take(group.idx.reshape(-1))
        k = group.idx.shape[0]
        obs = {name: v.reshape(k, -1, *v.shape[1:]) for name, v in b.obs.items()}
        targets = b.targets.reshape(k, -1, *b.targets.shape[1:])
        return steps_with(params, opt_state, obs, targets, group.valid, embedding, nav, vocab)

    val_loss_with = jax.jit(make_loss(graphdef, cfg.rig, driven=True))

    def val_loss_fn(p, o, t):
        return val_loss_with(p, o, t, embedding, nav, vocab)

    mngr = _checkpointer(out)
    start, curve, best = 0, [], (np.inf, -1)
    if mngr.latest_step() is not None:  # resume
        last = mngr.latest_step()
        restored = mngr.restore(last, args=ocp.args.Composite(
            state=ocp.args.StandardRestore(dict(params=params, opt=opt_state)),
            meta=ocp.args.JsonRestore()))  # fmt: skip
        params, opt_state = restored.state["params"], restored.state["opt"]
        curve, best = restored.meta["curve"], tuple(restored.meta["best"])
        start = last + 1
    t_start, seen = time.perf_counter(), 0
    bar = _progress(progress, cfg, start * per_epoch, steps)
    for e in range(start, cfg.epochs):
        losses: list[float] = []
        pending = None  # the group sent last: its losses are read once the next one is sent
        for group in step_groups(batches.epoch(e), STEPS_PER_CALL):
            params, opt_state, values = run_group(params, opt_state, group)
            seen += group.examples
            if pending is not None:
                _read_losses(*pending, losses, bar, e)
            pending = (values, group)
        if pending is not None:
            _read_losses(*pending, losses, bar, e)
        val = _evaluate(val_loss_fn, params, ex, val_idx, cfg.batch_size)
        train_l1 = float(np.mean(losses)) if losses else np.nan
        elapsed = round(time.perf_counter() - t_start, 1)
        curve.append(dict(epoch=e, train_l1_m=train_l1, val_l1_m=val, seconds=elapsed))
        if val < best[0]:
            best = (val, e)
            save_model(nnx.merge(graphdef, params), out / cfg.name,
                       dict(recipe=cfg.recipe, dataset=str(cfg.dataset), epoch=e, val_l1_m=val,
                            train_config=dataclasses.asdict(cfg), **(info or {})))  # fmt: skip
        mngr.save(e, args=ocp.args.Composite(
            state=ocp.args.StandardSave(dict(params=params, opt=opt_state)),
            meta=ocp.args.JsonSave(dict(curve=curve, best=list(best)))))  # fmt: skip
        mngr.wait_until_finished()
        atomic_write(out / "curve.csv", pd.DataFrame(curve).to_csv(index=False))
        if (time.perf_counter() - t_start) / 60.0 > cfg.max_minutes:
            break
    if bar is not None:
        bar.close()
    elapsed = time.perf_counter() - t_start
    _plot_curve(curve, out / "curve.png", cfg.name)
    return dict(name=cfg.name, best_val_l1_m=best[0], best_epoch=best[1], epochs=len(curve),
                train_examples=int(len(batches.train_idx)), val_examples=int(len(val_idx)),
                frames_per_s=seen / max(elapsed, 1e-9), seconds=elapsed,
                model=str(out / f"{cfg.name}.msgpack"))  # fmt: skip


def _read_losses(values: Any, group: StepGroup, losses: list[float], bar, epoch: int) -> None:
    """Append a group's real steps' losses (``values`` (STEPS_PER_CALL,), m) to ``losses`` and
    advance the progress bar by its steps."""
    losses.extend(np.asarray(values)[group.valid].tolist())
    if bar is not None:
        bar.set_postfix_str(f"epoch {epoch} loss {np.mean(losses[-50:]):.3f} m")
        bar.update(group.steps)


def _evaluate(loss_fn, params, ex: Examples, idx: np.ndarray, batch_size: int) -> float:
    if len(idx) == 0:
        return float("nan")
    total, count = 0.0, 0
    for k in range(0, len(idx) - batch_size + 1, batch_size):  # whole batches: one compile
        b = ex.take(idx[k : k + batch_size])
        total += float(loss_fn(params, b.obs, jnp.asarray(b.targets))) * batch_size
        count += batch_size
    return total / max(count, 1) if count else float("nan")


def _progress(on: bool, cfg: TrainConfig, done: int, total: int):
    """A progress bar over every batch of the run (``done`` of them already, when resumed)."""
    if not on:
        return None

    return tqdm(desc=f"train {cfg.name}", unit="batch", initial=done, total=total)


def _plot_curve(curve: list[dict], path: Path, name: str) -> None:
    # deferred: matplotlib only when a curve is drawn
    import matplotlib

    matplotlib.use("Agg")
    # deferred: matplotlib only when a curve is drawn
    from matplotlib.figure import Figure

    df = pd.DataFrame(curve)
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    if len(df):
        ax.plot(df["epoch"], df["train_l1_m"], "o-", label="train")
        ax.plot(df["epoch"], df["val_l1_m"], "s--", label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("waypoint L1 (m)")
    ax.set_title(name)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
