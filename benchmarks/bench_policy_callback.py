"""What a policy called back from inside the world's loop would cost: a measurement of one
design for the split path (``docs/performance.md``, "Compiling the world once").

The split path steps the world and the policy as two programs from a host thread, a call of
each per tick.  A third design would keep the whole rollout inside one compiled loop -- the
world program's own loop, on both CPU devices as the fused program runs -- and reach the
policy through a host callback (``jax.pure_callback``) that runs the policy's own compiled
program.  The world program would still not depend on the policy.  This benchmark measures
the price of that callback in isolation: a scanned loop of ``--ticks`` ticks whose body
calls a two-layer MLP on ``--slots`` observations of ``--width`` numbers,

* *inline*: the MLP inside the loop (what the fused program does);
* *callback, JAX*: the MLP's compiled program called from a ``pure_callback`` (on two
  devices, each device's callback runs the program on its own device);
* *callback, NumPy*: the callback computes the MLP in NumPy (no JAX inside the callback: the
  callback's own cost);

on one device and on two (``shard_map`` over ``--xla_force_host_platform_device_count=2``,
as the fused rollout runs on a 2-core CPU).  Prints microseconds per tick (per device), the
best of ``--rounds``.

Usage::

    python benchmarks/bench_policy_callback.py [--ticks 1000] [--slots 24] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")

import jax  # noqa: E402  (XLA reads the device count when JAX starts)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.sharding import NamedSharding  # noqa: E402
from jax.sharding import PartitionSpec as P  # noqa: E402

HIDDEN = 64  # the MLP's hidden width
OUT = 20  # its output: 10 waypoints x 2


def _mlp(x, w1, w2):
    """(S, width) -> (S, OUT) float32."""
    return jnp.tanh(jnp.tanh(x @ w1) @ w2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=int, default=1000)
    ap.add_argument("--slots", type=int, default=24, help="observations per device and tick")
    ap.add_argument("--width", type=int, default=400, help="numbers per observation")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    s, d, ticks = args.slots, args.width, args.ticks
    devices = jax.devices()
    w1 = np.full((d, HIDDEN), 0.01, np.float32)
    w2 = np.full((HIDDEN, OUT), 0.01, np.float32)
    weights = [(jax.device_put(w1, dev), jax.device_put(w2, dev)) for dev in devices]
    mlp = jax.jit(_mlp)
    for dev in devices:  # compiled for every device before timing
        mlp(jax.device_put(np.zeros((s, d), np.float32), dev), *weights[dev.id])
    out = jax.ShapeDtypeStruct((s, OUT), jnp.float32)

    def via_jax(k, x):
        k = int(np.asarray(k)[0])
        return np.asarray(mlp(jax.device_put(np.asarray(x), devices[k]), *weights[k]))

    def via_numpy(k, x):
        return np.tanh(np.tanh(np.asarray(x) @ w1) @ w2).astype(np.float32)

    def loop(kind, device_index):
        def body(c, _):
            if kind == "inline":
                y = _mlp(c, w1, w2)
            else:
                fn = via_jax if kind == "callback, JAX" else via_numpy
                y = jax.pure_callback(fn, out, device_index, c)
            return c + 1e-3 * jnp.sum(y), None

        return lambda x: jax.lax.scan(body, x, None, length=ticks)[0]

    mesh = jax.make_mesh((len(devices),), ("b",))

    def programs(kind):
        one = jax.jit(lambda x: loop(kind, jnp.zeros(1, jnp.int32))(x))
        both = jax.jit(jax.shard_map(
            lambda x: loop(kind, jax.lax.axis_index("b")[None])(x), mesh=mesh,
            in_specs=P("b"), out_specs=P("b"), check_vma=False,
        ))  # fmt: skip
        return one, both

    x1 = jax.device_put(np.zeros((s, d), np.float32), devices[0])
    x2 = jax.device_put(np.zeros((len(devices) * s, d), np.float32), NamedSharding(mesh, P("b")))
    print(f"{ticks} ticks, {s} slots per device, {len(devices)} devices; µs per tick, best of "
          f"{args.rounds}")  # fmt: skip
    print(f"{'body':<16} {'one device':>12} {'each of two':>12}")
    for kind in ("inline", "callback, JAX", "callback, NumPy"):
        row = []
        for fn, x in zip(programs(kind), (x1, x2), strict=True):
            fn(x).block_until_ready()
            best = float("inf")
            for _ in range(args.rounds):
                t0 = time.perf_counter()
                fn(x).block_until_ready()
                best = min(best, time.perf_counter() - t0)
            row.append(1e6 * best / ticks)
        print(f"{kind:<16} {row[0]:>12.1f} {row[1]:>12.1f}")


if __name__ == "__main__":
    main()
