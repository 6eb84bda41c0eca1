"""Where the split path's rollout loses to the fused one: its worker threads, measured.

Two parts, each in this one process, on the built-in suite and the benchmark's new MLP policy
(``bench_iterate.py``'s ``mlp`` edit):

* **a tick, stepped by one or two threads**: ``--slots`` executions at their start states, a
  policy call and a world call per tick (the split path's inner loop, no refill), ``--ticks``
  ticks per round; one thread on device 0, then two threads at once (devices 0 and 1, each
  with its own programs).  Printed: wall ms per tick of each thread, the cores the process
  kept busy (its CPU seconds over the wall seconds), and the CPU the stepping thread itself
  spent per tick (Python and JAX's dispatch; the rest of a thread's cores is XLA running the
  call's kernels);
* **the whole suite**: :func:`lantern_jax.sim.split.run_split` with each ``--cases`` entry
  (``workers x slots``), interleaved with the fused rollout, ``--rounds`` rounds; the rollout's
  seconds (programs compiled or loaded before).

Usage::

    python benchmarks/bench_split_workers.py [--slots 48] [--ticks 400] [--rounds 3]
        [--cases 2x48,1x48,1x96,2x24]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from lantern_jax.cli import expose_cpu_cores  # noqa: E402

expose_cpu_cores()

import jax  # noqa: E402
import numpy as np  # noqa: E402
from bench_iterate import _policy  # noqa: E402  (this folder's inner-loop benchmark)

from lantern_jax.core.constants import NUM_WAYPOINTS  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim import engine, split  # noqa: E402
from lantern_jax.sim.settings import default_settings  # noqa: E402


def _cpu_s() -> float:
    """CPU seconds of this process (every thread), user and system."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def fresh_programs(policy, params, sig, setp, device) -> tuple:
    """The world program and ``policy``'s program of ``sig`` compiled here, afresh (neither from
    this process's programs nor from the program store, as
    :func:`~lantern_jax.sim.split.world_programs` and
    :func:`~lantern_jax.sim.split.policy_program` would give them).

    Returns:
        (world tick, policy program, packed parameters on ``device``, the carry's layout).
    """
    s = sig.slots
    world = split._tick_jit.lower(*split._tick_args(sig, setp, device),
                                  signed=split._Signed(sig)).compile()  # fmt: skip
    carry = split.Layout.of(jax.eval_shape(policy.initial_carry, params))
    step = split._PolicyStep(policy, sig.observation, sig.scenario, sig.state,
                             split.Layout.of(params), carry)  # fmt: skip
    parp = tuple(jax.device_put(b, device) for b in split._pack_one(step.params, params))
    flags = jax.device_put(np.zeros(s, bool), device)
    truth = split.ground_truth_inputs(policy, split._blank(sig.scenario, s, device),
                                      split._blank(sig.state, s, device))  # fmt: skip
    pol = split._policy_jit.lower(parp, split._blank(carry, s, device), sig.observations(s, device),
                                  flags, flags, truth, step=step).compile()  # fmt: skip
    return world, pol, parp, carry


def stepper(policy, params, host, settings, sig, device, own: bool):
    """A function ``run(ticks)`` that steps ``sig.slots`` executions (the suite's first) from
    their start states on ``device``, a policy call and a world call per tick, and waits for
    the last.  ``own``: compile this device's own programs (else the process's shared ones,
    as :func:`~lantern_jax.sim.split.run_split` uses them)."""
    s = sig.slots
    setp = tuple(jax.device_put(b, device) for b in split._pack_one(sig.settings, settings))
    if own:
        world, pol, parp, carry_layout = fresh_programs(policy, params, sig, setp, device)
    else:
        world = split.world_programs(sig, setp, device).tick
        pol, parp, carry_layout = split.policy_program(policy, params, sig, device)
    rows = np.arange(s)
    laid = jax.tree.map(lambda x: x[rows], host)
    scp = tuple(jax.device_put(b, device) for b in sig.scenario.pack_host(laid))
    states = sig.state.pack_host(split.start_states(laid, s, settings, {}))
    switches = jax.device_put(split.sensor_switches(policy), device)
    active = jax.device_put(np.ones(s, bool), device)
    no = jax.device_put(np.zeros(s, bool), device)
    still = jax.device_put(np.zeros((s, NUM_WAYPOINTS, 2), np.float32), device)
    first = tuple(jax.device_put(b, device) for b in states)
    _, obs0, _ = world(scp, first, still, no, switches, setp)
    carry0 = split._blank(carry_layout, s, device)

    def run(ticks: int) -> None:
        carry, obs = carry0, obs0
        st = tuple(jax.device_put(b, device) for b in states)
        for _ in range(ticks):
            waypoints, carry = pol(parp, carry, obs, no, no,
                                   split.ground_truth_inputs(policy, scp, st))
            st, obs, _ = world(scp, st, waypoints, active, switches, setp)
        jax.block_until_ready(st)

    run(5)
    return run


def threads(fns, ticks: int) -> tuple[float, float]:
    """Run each of ``fns`` in its own thread at once: (wall ms per tick, cores kept busy)."""
    ts = [threading.Thread(target=f, args=(ticks,)) for f in fns]
    c0, t0 = _cpu_s(), time.perf_counter()
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    wall = time.perf_counter() - t0
    return wall / ticks * 1e3, (_cpu_s() - c0) / wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slots", type=int, default=split.split_slots())
    ap.add_argument("--ticks", type=int, default=400)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cases", default="2x48,1x48,1x96,2x24",
                    help="workers x slots of the whole-suite runs")  # fmt: skip
    args = ap.parse_args()
    cases = [tuple(int(v) for v in c.split("x")) for c in args.cases.split(",") if c]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
          f"devices {len(jax.local_devices())}, load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    policy = _policy("mlp")
    params = policy.init(jax.random.PRNGKey(0))
    execs = engine.build_executions(load_suite())
    settings = default_settings()
    host = jax.tree.map(np.asarray, execs.scenarios)
    sig = split.world_signature(jax.tree.map(lambda x: x[0], host), settings, args.slots)
    devices = jax.local_devices()
    runs = [stepper(policy, params, host, settings, sig, devices[0], own=False)]
    if len(devices) > 1:
        runs.append(stepper(policy, params, host, settings, sig, devices[1], own=True))
    print(f"\na tick of {args.slots} slots, {args.ticks} ticks per round")
    print("round  one thread: ms/tick  cores  its own CPU ms/tick  |  two threads: ms/tick  cores")
    for r in range(args.rounds):
        c0 = time.thread_time()
        runs[0](args.ticks)
        own_cpu = (time.thread_time() - c0) / args.ticks * 1e3
        one_ms, one_cores = threads(runs[:1], args.ticks)
        two = threads(runs, args.ticks) if len(runs) > 1 else (float("nan"), float("nan"))
        print(f"{r:5d}  {one_ms:20.3f}  {one_cores:5.2f}  {own_cpu:19.3f}  |  {two[0]:21.3f}  "
              f"{two[1]:5.2f}", flush=True)  # fmt: skip
    print("\nthe whole suite, rollout seconds (programs compiled or loaded before)")
    for r in range(args.rounds):
        row = []
        for w, s in cases:
            t: dict = {}
            split.run_split(policy, execs.scenarios, params, execs.max_ticks, settings,
                            timings=t, workers=w, slots=s)  # fmt: skip
            row.append(f"split {w}x{s} {t['rollout']:.2f}")
        t = {}
        engine.run_executions(policy, execs.scenarios, params, execs.max_ticks, settings,
                              timings=t, path="fused")  # fmt: skip
        row.append(f"fused {t['rollout']:.2f}")
        print(f"round {r}: " + ", ".join(row), flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
