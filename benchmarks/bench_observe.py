"""Cost of building the observation (``sim.observe``) per scenario-tick, on its own.

Times ``jit(vmap(observe))`` over a batch of states of the 16-actor bench scene (half of them
with the warning being delivered), which isolates what the observation's fields cost compared
with a whole tick (``bench_rollout.py``).

Usage::

    python benchmarks/bench_observe.py [--batch 360] [--repeats 200]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from bench_rollout import sixteen_actor_scene

from lantern_jax.sim.observe import observe
from lantern_jax.sim.state import init_state
from lantern_jax.types.world import tree_stack


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=360)
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args()
    scenes = [sixteen_actor_scene(float(i % 8)) for i in range(args.batch)]
    states = [init_state(s) for s in scenes]
    # Every other state has passed the warning point: the warning is delivered there.
    states = [
        st.replace(protocol=st.protocol.replace(t_warn_point=jnp.float32(-1.0 if i % 2 else 1e9)))
        for i, st in enumerate(states)
    ]
    sc, st = tree_stack(scenes), tree_stack(states)
    fn = jax.jit(jax.vmap(observe))
    t0 = time.perf_counter()
    jax.block_until_ready(fn(sc, st))
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(sc, st))
        times.append(time.perf_counter() - t0)
    best, med = float(np.min(times)), float(np.median(times))
    print(
        f"batch {args.batch}: compile {compile_s:.2f} s; observe per call best {1e3 * best:.3f} "
        f"ms, median {1e3 * med:.3f} ms = {1e6 * med / args.batch:.3f} us per scenario-tick"
    )


if __name__ == "__main__":
    main()
