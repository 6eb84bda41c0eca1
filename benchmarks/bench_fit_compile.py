"""Compile time of the training step and the validation loss: the embedding table as an argument
of the compiled programs (as :func:`lantern_jax.apps.training.fit.fit` passes it) against the
same table closed over, i.e. a constant copied into the program.

The table is 32,000 x 256 float32 (33 MB); the navigation tokens are a small table beside it.
Each program is lowered and compiled afresh (JAX's in-memory caches cleared), for the tiny model
of ``tests/test_training.py`` (width 16, two heads) on a batch of 32 examples of a small recorded
dataset (one pair per family, recorded here into a temporary folder first; not timed).  JAX's
persistent compilation cache is on, in an empty temporary folder, as ``lantern-jax train`` and
the tests run (``--no-cache``: off): most of what a constant costs is the cache's handling of
the compiled program that holds it (serialised, compressed and written), not XLA's compile.
Rounds after the first find every program in that cache: they time its load.

Usage (from the project root)::

    python benchmarks/bench_fit_compile.py [--rounds 2] [--width 16] [--batch 32] [--no-cache]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from lantern_jax.apps.dataset.generation import generate_dataset
from lantern_jax.apps.dataset.store import load_frames, read_card
from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.apps.training.data import ranges_width, recipe_examples
from lantern_jax.apps.training.fit import make_loss, model_config
from lantern_jax.policies.learned.checkpoint import new_model
from lantern_jax.policies.learned.features import nav_token_table
from lantern_jax.types.language import load_embedding


def programs(cfg: TrainConfig, ex, batch: int):
    """The two programs' functions and example arguments, both ways."""
    model = new_model(model_config(cfg, ranges_width(ex, cfg.rig)), cfg.seed)
    graphdef, params = nnx.split(model)
    embedding = jnp.asarray(load_embedding(), jnp.float32)
    nav = jnp.asarray(nav_token_table())
    tx = optax.adamw(1e-3)
    opt_state = tx.init(params)
    loss_fn = make_loss(graphdef, cfg.rig)
    b = ex.take(np.arange(batch))
    obs, targets = b.obs, jnp.asarray(b.targets)

    def step_with(params, opt_state, obs, targets, embedding, nav):
        value, grads = jax.value_and_grad(loss_fn)(params, obs, targets, embedding, nav)
        updates, opt_state = tx.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    def step_closed(params, opt_state, obs, targets):
        return step_with(params, opt_state, obs, targets, embedding, nav)

    def val_closed(p, o, t):
        return loss_fn(p, o, t, embedding, nav)

    return {
        ("step", "argument"): (step_with, (params, opt_state, obs, targets, embedding, nav)),
        ("step", "constant"): (step_closed, (params, opt_state, obs, targets)),
        ("validation loss", "argument"): (loss_fn, (params, obs, targets, embedding, nav)),
        ("validation loss", "constant"): (val_closed, (params, obs, targets)),
    }


def compile_seconds(fn, args) -> tuple[float, float]:
    """(trace + lower, compile) seconds of a fresh ``jax.jit`` of ``fn`` (compile: XLA's and,
    with the persistent cache on, the cache's write)."""
    jax.clear_caches()
    t0 = time.perf_counter()
    lowered = jax.jit(fn).lower(*args)
    t1 = time.perf_counter()
    lowered.compile()
    return t1 - t0, time.perf_counter() - t1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds (default 2)")
    ap.add_argument("--width", type=int, default=16, help="model width (default 16)")
    ap.add_argument("--batch", type=int, default=32, help="examples per batch (default 32)")
    ap.add_argument("--no-cache", action="store_true", help="JAX's persistent cache off")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        jax.config.update("jax_enable_compilation_cache", not args.no_cache)
        jax.config.update("jax_compilation_cache_dir", str(Path(tmp) / "cache"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        ds = Path(tmp) / "ds"
        generate_dataset(ds, pairs_per_family=1, seed=5, chunk_pairs=3, progress=False)
        cfg = TrainConfig(name="bench", recipe="base", dataset=str(ds), out=str(Path(tmp) / "o"),
                          width=args.width, heads=2, epochs=1, batch_size=args.batch)  # fmt: skip
        frames = load_frames(cfg.dataset, exclude_crossing=cfg.exclude_crossing)
        ex = recipe_examples(frames, read_card(ds), cfg)
        progs = programs(cfg, ex, args.batch)
        print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
              f"load average at start {os.getloadavg()[0]:.1f}, persistent cache "
              f"{'off' if args.no_cache else 'on'}")  # fmt: skip
        print(f"{'program':<16} {'embedding':<9} {'round':>5} {'trace+lower s':>14} "
              f"{'compile s':>10}")  # fmt: skip
        for r in range(args.rounds):
            for (name, way), (fn, fargs) in progs.items():
                lower, xla = compile_seconds(fn, fargs)
                print(f"{name:<16} {way:<9} {r:>5} {lower:>14.2f} {xla:>10.2f}", flush=True)


if __name__ == "__main__":
    main()
