"""What reading the words in order costs a training step, against the pooled bag of words.

One jitted training step as ``lantern_jax.apps.training.fit`` compiles it (the loss over a batch
of observations, its gradient, an AdamW update), for a model of each text encoder
(``ModelConfig.text_encoder``): ``pooled``, ``attention`` and ``bigram``, and the attention encoder
without its attention layers (``text_layers=0``: the projection, the word positions and the
MLP FiLM; a ``ModelConfig`` only, which no training config accepts), to split its cost.
The batch is the observation of a straight road with a pedestrian emergence's markers (front
camera), repeated with the bank's warning texts; the same batch and targets for every model.
The bigram reader twice: slot by slot, and through the projected rows of the batch's
vocabulary (``DrivingModel.word_tables``), which is how training reads it.
Each round times ``--steps`` steps of every model after its compile, the models interleaved;
prints ms per step and steps per second with the machine's load::

    python benchmarks/bench_text_encoder.py --rounds 3 --steps 50
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from lantern_jax.apps.training.fit import make_loss, text_vocabulary
from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.learned.checkpoint import new_model
from lantern_jax.policies.learned.features import nav_token_table
from lantern_jax.policies.learned.model import ModelConfig
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.warnings import text_tables
from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state
from lantern_jax.types.language import load_embedding
from lantern_jax.types.observation import WARNING


def batch_of(n: int):
    """(n,) observations with the bank's texts delivered in turn, and (n, 10, 2) targets."""
    world = straight_scene([], length=120.0, speed=8.0, s_warn=22.0, s_event=31.0,
                           s_conflict=40.0, hazard_index=0, clear_s=22.0)  # fmt: skip
    obs = jax.jit(lambda w: observe(w, init_state(w), (WARNING,)))(world)
    tokens = text_tables().tokens
    batch = jax.tree.map(lambda x: jnp.stack([x] * n), obs)
    batch = batch.replace(warning_tokens=jnp.asarray(tokens[np.arange(n) % len(tokens)]))
    rng = np.random.default_rng(0)
    targets = rng.normal(size=(n, NUM_WAYPOINTS, 2)).astype(np.float32)
    return batch, jnp.asarray(targets)


def make_step(config: ModelConfig, vocabulary=None):
    """(step, params, opt_state) of one model: ``step(params, opt, obs, targets, emb, nav)``,
    the loss training compiles (``fit.make_loss``); a bigram model given ``vocabulary`` reads
    its words through the projected vocabulary, as training does, else slot by slot."""
    graphdef, params = nnx.split(new_model(config, seed=0))
    tx = optax.adamw(3e-4, weight_decay=1e-4)
    loss = make_loss(graphdef, config.rig)

    @jax.jit
    def step(p, s, obs, targets, emb, nav):
        columns = {k: v for k, v in vars(obs).items() if v is not None}
        v, g = jax.value_and_grad(loss)(p, columns, targets, emb, nav, vocabulary)
        u, s = tx.update(g, s, p)
        return optax.apply_updates(p, u), s, v

    return step, params, tx.init(params)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=50, help="timed steps per model and round")
    ap.add_argument("--batch", type=int, default=256, help="examples per step (training's)")
    args = ap.parse_args()
    emb = jnp.asarray(load_embedding(), jnp.float32)
    nav = jnp.asarray(nav_token_table())
    obs, targets = batch_of(args.batch)
    configs = {
        "pooled": ModelConfig(text_encoder="pooled"),
        "attention": ModelConfig(text_encoder="attention"),
        "attention, 0 layers": ModelConfig(text_encoder="attention", text_layers=0),
        "bigram, per slot": ModelConfig(text_encoder="bigram"),
        "bigram": ModelConfig(text_encoder="bigram"),
    }
    vocabulary = jnp.asarray(text_vocabulary(np.asarray(obs.warning_tokens), np.asarray(nav)))
    models = {}
    for enc, config in configs.items():
        step, p, s = make_step(config, vocabulary if enc == "bigram" else None)
        t = time.perf_counter()
        p, s, v = step(p, s, obs, targets, emb, nav)
        v.block_until_ready()
        print(f"{enc}: compile + first step {time.perf_counter() - t:.2f} s")
        models[enc] = [step, p, s]
    print(f"{platform.machine()} {os.cpu_count()} cores, jax {jax.__version__}, "
          f"batch {args.batch}, {args.steps} steps per model and round")  # fmt: skip
    for r in range(args.rounds):
        for enc, m in models.items():
            step, p, s = m
            t = time.perf_counter()
            for _ in range(args.steps):
                p, s, v = step(p, s, obs, targets, emb, nav)
            v.block_until_ready()
            dt = (time.perf_counter() - t) / args.steps
            m[1], m[2] = p, s
            load = os.getloadavg()[0]
            print(f"round {r} {enc:>19}: {1e3 * dt:6.1f} ms/step  {1 / dt:5.1f} steps/s  "
                  f"(load {load:.1f})")  # fmt: skip


if __name__ == "__main__":
    main()
