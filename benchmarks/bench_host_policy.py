"""Per-tick cost of running a policy on the host (``jax.pure_callback``) instead of in JAX.

The same small MLP (``examples/host_models.py``) runs once as JAX code and once as NumPy code
through :func:`lantern_jax.policies.host.host_policy`, on the 360 executions of the built-in suite
for a fixed number of ticks (one device, :func:`lantern_jax.sim.rollout.rollout_batch`).  The
overhead per tick is the wall-time difference divided by the ticks; the NumPy model's own time
per call (batch 360) is measured separately, so the rest is the callback's transfer and
synchronisation cost.

    python benchmarks/bench_host_policy.py [--ticks 200] [--repeats 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import host_models  # noqa: E402

from lantern_jax.policies.features import observation_vector  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim.engine import build_executions  # noqa: E402
from lantern_jax.sim.observe import observe  # noqa: E402
from lantern_jax.sim.rollout import rollout_batch  # noqa: E402
from lantern_jax.sim.state import init_state  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    scenarios = build_executions(load_suite()).scenarios
    n = jax.tree.leaves(scenarios)[0].shape[0]
    w = host_models.make_weights()
    policies = {"jax": host_models.jax_policy(w), "host (NumPy)": host_models.numpy_policy(w)}
    best = {}
    for name, pol in policies.items():
        run = jax.jit(lambda sc, pol=pol: rollout_batch(sc, pol, {}, args.ticks).done)
        jax.block_until_ready(run(scenarios))  # compile
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(run(scenarios))
            times.append(time.perf_counter() - t0)
        best[name] = min(times)
        print(f"{name:>13}: {best[name]:.3f} s for {args.ticks} ticks x {n} executions "
              f"({1e3 * best[name] / args.ticks:.2f} ms/tick)")  # fmt: skip
    x = np.asarray(jax.jit(jax.vmap(lambda sc: observation_vector(observe(sc, init_state(sc)))))(
        scenarios))  # fmt: skip
    model = host_models.numpy_model(w)
    t0 = time.perf_counter()
    for _ in range(200):
        model(x)
    t_model = (time.perf_counter() - t0) / 200
    over = (best["host (NumPy)"] - best["jax"]) / args.ticks
    print(f"host overhead per tick: {1e3 * over:.2f} ms (batch {n}); of which the NumPy model "
          f"itself {1e3 * t_model:.2f} ms per call")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
