"""Throughput next to a peer simulator, measured in one run: scenario-ticks per second of the
whole-suite evaluation against highway-env's ``highway-v0``.

Ours: every execution of the built-in suite (``lantern-v3``: 3 x 120) for one policy, exactly as
``evaluate`` runs it (:func:`lantern_jax.apps.evaluation.run_executions`), after compile; a tick is
one 20 Hz step of the whole world of one execution (policy, IDM and scripted actors, ray-cast
sensing, the temporal protocol and the score accumulators).  Only the ticks an execution really
lived count (its final ``tick``), not the ticks a finished execution is held.

highway-env (an optional peer, never a project dependency; install it where you like, e.g.
``python -m venv /tmp/peers && /tmp/peers/bin/pip install highway-env``): ``highway-v0`` with
``--vehicles`` other vehicles (default 16, the actor capacity of one of our scenes; the peer's
own default is 50) besides its ego, IDM + MOBIL, 15 Hz simulation, one agent action per second,
no rendering, a constant IDLE action; a tick is one 15 Hz simulation step of one environment.

Two ratios are printed: per scene-tick (one whole world advanced one tick) and per agent-step
(one vehicle, pedestrian or ego advanced one tick: ours counts the ego and every actor slot a
scene fills, whether or not the actor has appeared yet; the peer counts its ego and vehicles).
It runs in ``--peer-python`` (default: this interpreter) as a subprocess, so it may live in its
own environment.  Both per tick and per simulated second are printed (the two tick lengths
differ).

Usage::

    python benchmarks/bench_peers.py [--policy coop] [--peer-python /tmp/peers/bin/python]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

from lantern_jax.cli import expose_cpu_cores
from lantern_jax.core.constants import SUITE_ID  # noqa: E402

expose_cpu_cores()  # one XLA CPU device per core (LANTERN_JAX_CPU_DEVICES=1 to disable)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from lantern_jax.core.constants import DT  # noqa: E402
from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim.engine import build_executions, run_executions  # noqa: E402

#: Runs in the peer's interpreter; prints one JSON line.
HIGHWAY_ENV_SNIPPET = r"""
import json, sys, time
import gymnasium as gym
import highway_env  # noqa: F401  (registers the environments)
seconds = float(sys.argv[1])
env = gym.make("highway-v0", config={"vehicles_count": int(sys.argv[2])})
cfg = env.unwrapped.config
env.reset(seed=0)
idle = 1  # DiscreteMetaAction: IDLE
steps = episodes = 0
t0 = time.perf_counter()
while time.perf_counter() - t0 < seconds:
    _, _, terminated, truncated, _ = env.step(idle)
    steps += 1
    if terminated or truncated:
        env.reset(seed=episodes + 1)
        episodes += 1
wall = time.perf_counter() - t0
ticks_per_step = cfg["simulation_frequency"] // cfg["policy_frequency"]
print(json.dumps(dict(
    version=__import__("importlib.metadata").metadata.version("highway-env"),
    steps=steps, episodes=episodes, wall_s=wall, ticks=steps * ticks_per_step,
    tick_s=1.0 / cfg["simulation_frequency"], vehicles=cfg["vehicles_count"],
)))
"""


def run_peer(python: str, seconds: float, vehicles: int) -> dict | None:
    """Measure highway-env in ``python`` with ``vehicles`` other vehicles; None (with the reason
    printed) when it is missing."""
    proc = subprocess.run(
        [python, "-c", HIGHWAY_ENV_SNIPPET, str(seconds), str(vehicles)],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        print(f"highway-env: not measured ({last})")
        return None
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--suite", default=SUITE_ID)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--peer-python", default=sys.executable, help="interpreter with highway-env")
    ap.add_argument("--peer-seconds", type=float, default=20.0, help="how long to step the peer")
    ap.add_argument("--vehicles", type=int, default=16, help="the peer's other vehicles")
    args = ap.parse_args()

    devices = f"{jax.device_count()} x {jax.default_backend()}"
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
          f"devices {devices}")  # fmt: skip
    execs = build_executions(load_suite(args.suite))
    policy = get_policy(args.policy)
    params = policy.init(jax.random.PRNGKey(0))
    run = {}
    final, _ = run_executions(policy, execs.scenarios, params, execs.max_ticks, **run)
    lived = int(np.sum(np.asarray(final.tick)))
    # agents per scene: the ego and every actor slot the scene fills (padding slots excluded)
    agents = 1.0 + float(np.mean(np.sum(np.asarray(execs.scenarios.actors.valid), axis=-1)))
    walls = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        run_executions(policy, execs.scenarios, params, execs.max_ticks, **run)
        walls.append(time.perf_counter() - t0)
    wall = min(walls)
    ours = lived / wall
    print(f"lantern_jax {args.policy} on {args.suite}: {lived} scenario-ticks lived "
          f"(3 x {execs.num_pairs} executions, {DT * 1e3:.0f} ms ticks, {agents:.1f} agents "
          f"per scene on average) in {wall:.2f} s = {ours:,.0f} scenario-ticks/s, "
          f"{ours * agents:,.0f} agent-steps/s, {ours * DT:,.0f} simulated s per s")  # fmt: skip

    peer = run_peer(args.peer_python, args.peer_seconds, args.vehicles)
    if peer is None:
        return
    theirs = peer["ticks"] / peer["wall_s"]
    sim_rate = theirs * peer["tick_s"]
    peer_agents = 1 + peer["vehicles"]
    print(f"highway-env {peer['version']} highway-v0 ({peer['vehicles']} vehicles and the ego): "
          f"{peer['ticks']} ticks ({peer['tick_s'] * 1e3:.1f} ms) in {peer['wall_s']:.1f} s "
          f"= {theirs:,.0f} scenario-ticks/s, {theirs * peer_agents:,.0f} agent-steps/s, "
          f"{sim_rate:,.1f} simulated s per s")  # fmt: skip
    print(f"ratio per scene-tick: {ours / theirs:,.0f}x; per agent-step: "
          f"{ours * agents / (theirs * peer_agents):,.0f}x; per simulated second: "
          f"{ours * DT / (theirs * peer['tick_s']):,.0f}x")  # fmt: skip


if __name__ == "__main__":
    main()
