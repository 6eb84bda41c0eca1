"""The split path's world program, one call at a time: how its packed arguments are unpacked,
and what it computes beside the world's transition.

Builds ``--slots`` mid-run states of the built-in suite (as ``profile_tick.py`` does) and
times, interleaved in rounds (median per call, wall time on one device):

* ``world`` -- :mod:`lantern_jax.sim.split`'s world program as it is (packed arguments
  unpacked behind an optimisation barrier, then the transition and every sensor's
  observation);
* ``world, unpacked in place`` -- the same without the barrier: XLA fuses each leaf's slice of
  the packed buffer into every kernel that reads it;
* ``transition only`` -- packed, behind the barrier, no observation (what the world program
  would cost if every policy program built its own observation);
* ``fused step`` -- the fused path's tick of the benchmark's MLP policy (unpacked arguments,
  one leaf per argument, as a lone call).

Usage::

    python benchmarks/bench_split_tick.py [--slots 48] [--rounds 7] [--calls 50]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("LANTERN_JAX_CPU_DEVICES", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from bench_iterate import _policy  # noqa: E402  (this folder's inner-loop benchmark)
from profile_tick import mid_run_states  # noqa: E402

from lantern_jax.sim import split  # noqa: E402
from lantern_jax.sim.observe import observe_every_sensor  # noqa: E402
from lantern_jax.sim.settings import DEFAULT_SETTINGS  # noqa: E402
from lantern_jax.sim.step import step, transition  # noqa: E402


def _variants(sig, switches):
    """The world-program variants, each ``(scp, stp, waypoints, active, setp) -> outputs``."""

    def unpack(scp, stp, setp, barrier):
        parts = (sig.scenario.unpack(scp), sig.state.unpack(stp), sig.settings.unpack(setp))
        return jax.lax.optimization_barrier(parts) if barrier else parts

    def world_one(barrier):
        def one(scp, stp, wp, on, setp):
            sc, st, settings = unpack(scp, stp, setp, barrier)
            new, _ = transition(sc, st, wp, settings)
            new = jax.tree.map(lambda n, o: jnp.where(on, n, o), new, st)
            obs, _ = observe_every_sensor(sc, new, jnp.asarray(False), switches[0],
                                          settings.bank)  # fmt: skip
            return sig.state.pack(new), sig.observation.pack(obs), new.done | ~on

        return one

    def transition_one(scp, stp, wp, on, setp):
        sc, st, settings = unpack(scp, stp, setp, True)
        new, _ = transition(sc, st, wp, settings)
        new = jax.tree.map(lambda n, o: jnp.where(on, n, o), new, st)
        return sig.state.pack(new), new.done | ~on

    def batched(one):
        return jax.jit(lambda a, b, w, m, s: jax.vmap(lambda *x: one(*x, s))(a, b, w, m))

    return {
        "world": batched(world_one(True)),
        "world, unpacked in place": batched(world_one(False)),
        "transition only": batched(transition_one),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slots", type=int, default=split.split_slots())
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--calls", type=int, default=50)
    args = ap.parse_args()
    b = args.slots
    _, _, sc, st = mid_run_states("coop", b, 160)
    st = st.replace(policy_carry=())
    dev = jax.devices()[0]
    settings = DEFAULT_SETTINGS
    sig = split.world_signature(jax.tree.map(lambda x: x[0], sc), settings, b)
    put = lambda x: jax.device_put(x, dev)  # noqa: E731
    setp = tuple(put(x) for x in split._pack_one(sig.settings, settings))
    scp = tuple(put(x) for x in sig.scenario.pack_host(sc))
    stp = tuple(put(x) for x in sig.state.pack_host(jax.tree.map(np.asarray, st)))
    ahead = np.linspace(0.5, 5.0, 10, dtype=np.float32)
    wp = put(np.stack([np.tile(ahead, (b, 1)), np.zeros((b, 10), np.float32)], -1))
    on = put(np.ones(b, bool))
    switches = put(np.zeros(1, bool))
    mlp = _policy("mlp")
    params = mlp.init(jax.random.PRNGKey(0))
    calls = {name: (fn.lower(scp, stp, wp, on, setp).compile(), (scp, stp, wp, on, setp))
             for name, fn in _variants(sig, switches).items()}  # fmt: skip
    fused = jax.jit(jax.vmap(lambda s, x: step(mlp, params, s, x, settings)[0]))
    calls["fused step (mlp)"] = (fused.lower(sc, st).compile(), (put(sc), put(st)))
    times: dict[str, list[float]] = {k: [] for k in calls}
    for _ in range(args.rounds):
        for name, (exe, a) in calls.items():
            jax.block_until_ready(exe(*a))
            t0 = time.perf_counter()
            for _ in range(args.calls):
                out = exe(*a)
            jax.block_until_ready(out)
            times[name].append((time.perf_counter() - t0) / args.calls)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}; "
          f"{b} mid-run states, {args.rounds} interleaved rounds of {args.calls} calls; "
          f"load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    print(f"{'program':<28} {'ms per call (median)':>21} {'min':>7} {'max':>7}")
    for name, ts in times.items():
        ms = [t * 1e3 for t in ts]
        print(f"{name:<28} {statistics.median(ms):21.3f} {min(ms):7.3f} {max(ms):7.3f}")


if __name__ == "__main__":
    main()
