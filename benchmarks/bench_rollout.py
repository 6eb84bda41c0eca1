"""Rollout throughput: compile time, wall time and scenario-ticks/s at several batch sizes.

Scenes: a straight road with 16 actors (IDM traffic in three lanes, a parked truck, a crossing
pedestrian triggered by the protocol event), front-camera visibility and a range image every
tick, the ``expert`` policy.  Each batch element is shifted slightly so that elements differ.

Usage::

    python benchmarks/bench_rollout.py [--batches 1 64 360 4096] [--ticks 200] [--policy expert]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from lantern_jax.cli import expose_cpu_cores

expose_cpu_cores()  # one XLA CPU device per core (LANTERN_JAX_CPU_DEVICES=1 to disable)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from lantern_jax.core.constants import (  # noqa: E402
    KIND_PEDESTRIAN,
    MOTION_IDM,
    ROLE_HAZARD,
    ROLE_OCCLUDER,
    TRIGGER_EVENT,
)
from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios.handmade import ActorSpec, straight_scene  # noqa: E402
from lantern_jax.sim.rollout import rollout_batch_parallel  # noqa: E402
from lantern_jax.types.world import tree_stack  # noqa: E402


def sixteen_actor_scene(shift: float):
    """A valid 16-actor straight-road scene; ``shift`` (m) moves the traffic along the road."""
    actors = [
        ActorSpec(
            path=np.array([[50.0, -6.0], [50.0, 16.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
            role=ROLE_HAZARD, v_post=3.0, trigger=TRIGGER_EVENT, despawn_at_end=True,
        ),
        ActorSpec(path=np.array([[44.0, -4.5]]), extent=(4.0, 1.25), role=ROLE_OCCLUDER),
    ]  # fmt: skip
    lanes = [(-3.5, 1), (3.5, -1), (0.0, 1)]
    k = 0
    while len(actors) < 16:
        y, direction = lanes[k % 3]
        x0 = 20.0 + 14.0 * (k // 3) + shift if y != 0.0 else -30.0 - 12.0 * (k // 3)
        path = np.array([[-60.0, y], [220.0, y]])[::direction]
        s0 = x0 + 60.0 if direction > 0 else 220.0 - x0
        actors.append(ActorSpec(path=path, motion=MOTION_IDM, s_init=s0, v_pre=8.0 + 0.2 * k))
        k += 1
    return straight_scene(
        actors, length=150.0, speed=8.0, s_warn=32.0, s_event=41.0, s_conflict=50.0,
        hazard_index=0, clear_s=22.0, despawn_on_clear=True,
    )  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 64, 360, 4096])
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--policy", default="expert")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    policy = get_policy(args.policy)
    params = policy.init(jax.random.PRNGKey(0))
    base = [sixteen_actor_scene(float(i % 8)) for i in range(8)]
    cpu = platform.processor() or platform.machine()
    kind = jax.devices()[0].device_kind
    print(f"device: {kind} ({jax.default_backend()}) x {jax.device_count()}, "
          f"{os.cpu_count()} cores, {cpu}; jax {jax.__version__}")  # fmt: skip
    print(f"policy {args.policy}, 16 actors, visibility + range image every tick, "
          f"{args.ticks} ticks per execution")  # fmt: skip
    print(f"{'batch':>6} {'compile s':>10} {'wall s':>9} {'scenario-ticks/s':>17} "
          f"{'CPU s':>8}")  # fmt: skip

    def run(worlds):
        # One chunk of ``ticks`` ticks: a fixed horizon (the routes outlast it), split over the
        # local devices.
        final = rollout_batch_parallel(worlds, policy, params, args.ticks, chunk=args.ticks)
        return final.telemetry

    fn = jax.jit(run)
    for b in args.batches:
        worlds = tree_stack([base[i % len(base)] for i in range(b)])
        t0 = time.perf_counter()
        compiled = fn.lower(worlds).compile()
        t_compile = time.perf_counter() - t0
        jax.block_until_ready(compiled(worlds))
        walls, cpus = [], []
        for _ in range(args.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            jax.block_until_ready(compiled(worlds))
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        wall, cpu_s = float(np.min(walls)), float(np.min(cpus))
        print(
            f"{b:>6} {t_compile:>10.2f} {wall:>9.3f} {b * args.ticks / wall:>17,.0f} {cpu_s:>8.3f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
