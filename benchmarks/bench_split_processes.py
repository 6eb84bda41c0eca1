"""The split path's rollout stepped by worker *processes*, each pinned to one core: measured,
not built into the package.

In one process the split rollout is 1.7-2.0x the fused one on a 2-core CPU: each call's
kernels spread over both cores through XLA's shared thread pool, so two stepping threads
contend (``bench_split_workers.py``, ``docs/performance.md``).  This benchmark measures the
alternative: the world program and the policy program, compiled (or loaded) in this process,
are serialised as the program store serialises them; one worker process per core -- pinned
to that core before it imports JAX, so that XLA gives it one device and a one-thread pool --
loads them and steps its share of the executions with the split path's own loop
(:func:`lantern_jax.sim.split._worker`: the same slots, deal and refills as ``run_split``).

Per round, for the benchmark's new MLP policy (``bench_iterate.py``'s ``mlp``) on the built-in
suite: the in-process split rollout (threads), the fused rollout, and the process workers:
their rollout (the slowest worker's own stepping time), the wall time from starting the
processes to having every result (Python's and JAX's start-up, loading the two programs,
stepping), and the largest difference of the final states from the in-process split run's.

Usage::

    python benchmarks/bench_split_processes.py [--rounds 3] [--workers 2] [--slots 48] [--no-pin]
"""

from __future__ import annotations

import argparse
import os
import pickle
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def worker_main(core: int, job_file: str, out_file: str) -> None:
    """One worker process: pinned to ``core``, loads the job, steps its executions, writes
    (final packed states and carries of its rows, stepping seconds, CPU seconds)."""
    if core >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {core})
    t_start = time.perf_counter()
    import jax
    import numpy as np
    from jax.experimental import serialize_executable as se

    from lantern_jax.sim import split

    job = pickle.loads(Path(job_file).read_bytes())
    device = jax.local_devices()[0]
    world = se.deserialize_and_load(*job["world"], execution_devices=[device])
    policy = se.deserialize_and_load(*job["policy"], execution_devices=[device])
    put = lambda tree: tuple(jax.device_put(b, device) for b in tree)  # noqa: E731
    n = job["scenarios"][0].shape[0]
    run = split._Run(
        split.WorldPrograms(job["sig"], world), policy, put(job["params"]), job["carry"],
        put(job["settings"]), jax.device_put(job["switches"], device),
        lambda sc, st: (sc, st) if job["privileged"] else (), job["scenarios"],
        job["starts"], job["first_obs"], [b.copy() for b in job["starts"]],
        [np.zeros((n, size), dt) for dt, size in job["carry"].groups], job["max_ticks"], device,
        job["done"], job["tick"], threading.Event(),
    )  # fmt: skip
    mine = job["deal"][job["index"]]
    t_ready = time.perf_counter()
    c0 = time.process_time()
    ticks = split._worker(run, mine)
    t_end = time.perf_counter()
    out = dict(rows=mine, final=[b[mine] for b in run.final],
               carry=[b[mine] for b in run.final_carry], start_s=t_ready - t_start,
               step_s=t_end - t_ready, cpu_s=time.process_time() - c0,
               ticks=ticks, devices=len(jax.local_devices()))  # fmt: skip
    Path(out_file).write_bytes(pickle.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--slots", type=int, default=None,
                    help="executions each worker steps together (default: the split path's)")
    ap.add_argument("--no-pin", action="store_true",
                    help="leave the worker processes free to run on every core")
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker_main(int(args.worker[0]), args.worker[1], args.worker[2])
        return

    # An empty cache folder: every program below is compiled here, not loaded.  An executable
    # that JAX's persistent cache or the program store gave back cannot be serialised again
    # whole on the CPU (its kernels are missing in the copy: "Function ... not found").
    cache = tempfile.TemporaryDirectory()
    os.environ["LANTERN_JAX_CACHE_DIR"] = cache.name
    os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    sys.path.insert(0, str(HERE))
    from lantern_jax.cli import expose_cpu_cores

    expose_cpu_cores()
    import jax
    import numpy as np
    from bench_iterate import _policy  # this folder's inner-loop benchmark
    from bench_split_workers import fresh_programs
    from jax.experimental import serialize_executable as se

    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.sim import engine, split
    from lantern_jax.sim.settings import default_settings

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
          f"load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    policy = _policy("mlp")
    params = policy.init(jax.random.PRNGKey(0))
    execs = engine.build_executions(load_suite(), bucket=True)
    settings = default_settings()
    host = jax.tree.map(np.asarray, execs.scenarios)
    n = int(host.config.timeout_s.shape[0])
    slots = args.slots or split.split_slots()
    device = jax.local_devices()[0]
    sig = split.world_signature(jax.tree.map(lambda x: x[0], host), settings, slots)
    setp = tuple(jax.device_put(b, device) for b in split._pack_one(sig.settings, settings))
    tick, pol_exe, parp, carry = fresh_programs(policy, params, sig, setp, device)
    world = split.WorldPrograms(sig, tick)
    start = split.start_states(host, slots, settings, {})
    scp = sig.scenario.pack_host(host)
    starts = sig.state.pack_host(start)
    switches = jax.device_put(split.sensor_switches(policy), device)
    first_obs = split._first_observations(world, scp, starts, switches, setp, device)
    job = dict(
        world=se.serialize(world.tick), policy=se.serialize(pol_exe), sig=sig,
        privileged=policy.privileged,
        params=[np.asarray(b) for b in parp], carry=carry,
        settings=[np.asarray(b) for b in setp], switches=np.asarray(switches), scenarios=scp,
        starts=starts, first_obs=first_obs, max_ticks=int(execs.max_ticks),
        done=split._field(sig.state, ".done"), tick=split._field(sig.state, ".tick"),
        deal=split.deal(host.config.timeout_s, args.workers),
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        jobs = []
        for k in range(args.workers):
            path = Path(tmp) / f"job{k}.pkl"
            path.write_bytes(pickle.dumps(dict(job, index=k)))
            jobs.append(path)
        print(f"job files: {sum(p.stat().st_size for p in jobs) / 1e6:.1f} MB")
        for r in range(args.rounds):
            t: dict = {}
            threads_final, _ = split.run_split(policy, execs.scenarios, params, execs.max_ticks,
                                               settings, timings=t, slots=slots)  # fmt: skip
            t_threads = t["rollout"]
            t = {}
            engine.run_executions(policy, execs.scenarios, params, execs.max_ticks, settings,
                                  timings=t, path="fused")  # fmt: skip
            t_fused = t["rollout"]
            t0 = time.perf_counter()
            outs = [Path(tmp) / f"out{k}_{r}.pkl" for k in range(args.workers)]
            cores = [-1 if args.no_pin else k % os.cpu_count() for k in range(args.workers)]
            procs = [subprocess.Popen([sys.executable, __file__, "--worker", str(cores[k]),
                                       str(jobs[k]), str(outs[k])])
                     for k in range(args.workers)]  # fmt: skip
            for p in procs:
                if p.wait() != 0:
                    raise SystemExit(f"a worker process failed (exit {p.returncode})")
            wall = time.perf_counter() - t0
            results = [pickle.loads(o.read_bytes()) for o in outs]
            final = [np.zeros((n, b.shape[1]), b.dtype) for b in starts]
            for res in results:
                for f, b in zip(final, res["final"], strict=True):
                    f[res["rows"]] = b
            want = sig.state.pack_host(threads_final.replace(policy_carry=()))
            diff = max(float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64))))
                       for a, b in zip(final, want, strict=True))  # fmt: skip
            steps = [res["step_s"] for res in results]
            cpu = ", ".join(f"{res['cpu_s']:.2f}" for res in results)
            per_tick = ", ".join(f"{res['step_s'] / res['ticks'] * 1e3:.2f}" for res in results)
            boot = ", ".join(f"{res['start_s']:.2f}" for res in results)
            print(f"round {r}: split in threads {t_threads:.2f} s, fused {t_fused:.2f} s, "
                  f"worker processes: rollout {max(steps):.2f} s (each "
                  f"{', '.join(f'{s:.2f}' for s in steps)} s, CPU "
                  f"{cpu} s, ms per tick {per_tick}, devices "
                  f"{[res['devices'] for res in results]}), start-up and load "
                  f"{boot} s, wall from "
                  f"start {wall:.2f} s; largest difference from the threads' final states "
                  f"{diff:.3g}", flush=True)  # fmt: skip
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
