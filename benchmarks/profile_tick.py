"""Where a tick goes: each stage of :func:`lantern_jax.sim.step.step` timed on its own, jitted
and vmapped over a batch of real mid-run states of the built-in suite, next to the whole tick.

The batch: the first ``--batch`` executions of the suite (Route A with warning, Route A without,
Route B, in suite order), rolled out ``--warmup-ticks`` ticks with the policy, so that actors
move, events have fired and warnings are shown.  Every stage then runs ``--repeats`` times on
the same inputs (its own compiled program, so XLA cannot fuse it with its neighbours: the sum of
the stages is an upper bound of the whole tick).  Also prints XLA's FLOP count of each stage and
its cost analysis of the whole tick (FLOPs and bytes per scenario-tick) with the achieved rate.
XLA counts the body of a loop once, so a stage with a loop (sensing tests one target actor per
loop step) is undercounted by about the loop's trip count.

Usage::

    python benchmarks/profile_tick.py [--policy coop] [--batch 96] [--warmup-ticks 160]
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

from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.sim.engine import build_executions, run_executions  # noqa: E402
from lantern_jax.sim.observe import observe  # noqa: E402
from lantern_jax.sim.settings import DEFAULT_SETTINGS  # noqa: E402
from lantern_jax.sim.step import TRANSITION_STAGES, step, transition_outputs  # noqa: E402


def stages(policy, params, settings=DEFAULT_SETTINGS):
    """The stages of one tick as functions of (scenario, state, inputs of the stage): the
    observation and the policy's answer, then :data:`lantern_jax.sim.step.TRANSITION_STAGES`."""

    def inputs(sc, st):
        """Every intermediate of one tick (the same code as ``step``)."""
        obs = observe(sc, st, policy.sensors, settings.bank)
        wp, _ = policy.step(params, st.policy_carry, obs)
        return obs, transition_outputs(sc, st, wp, settings)

    def s_observe(sc, st, x):
        return observe(sc, st, policy.sensors, settings.bank)

    def s_policy(sc, st, x):
        return policy.step(params, st.policy_carry, x[0])

    def staged(stage):
        return lambda sc, st, x: stage(sc, st, x[1], settings)

    def s_tick(sc, st, x):
        return step(policy, params, sc, st, settings)[0]

    table = {"observation (warning text, corridor)": s_observe, "policy act": s_policy}
    table.update({label: staged(stage) for label, stage in TRANSITION_STAGES})
    return inputs, table, s_tick


def flops_of(fn, args) -> float:
    """XLA's FLOP count of the compiled ``fn`` for ``args``."""
    cost = fn.lower(*args).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return float(cost.get("flops", 0.0))


def timed(fn, args, repeats: int) -> float:
    """Best-of-3 mean seconds of one call of a compiled ``fn``."""
    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeats):
            out = fn(*args)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - t0) / repeats)
    return best


def mid_run_states(policy: str, batch: int, warmup_ticks: int):
    """``batch`` executions spread over the built-in suite (Route A with warning, Route A
    without, Route B, in suite order), rolled out ``warmup_ticks`` ticks with ``policy``.

    Returns:
        (policy, params, scenarios, states): the registered policy, its parameters, and the
        batched scenarios and mid-run states (host arrays).
    """
    execs = build_executions(load_suite())
    pol = get_policy(policy)
    params = pol.init(jax.random.PRNGKey(0))
    idx = np.linspace(0, execs.num_executions - 1, batch).astype(int)
    sc = jax.tree.map(lambda x: np.asarray(x)[idx], execs.scenarios)
    st, _ = run_executions(pol, sc, params, warmup_ticks, compact=False)
    return pol, params, sc, st


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--batch", type=int, default=96)
    ap.add_argument("--warmup-ticks", type=int, default=160)
    ap.add_argument("--repeats", type=int, default=50)
    args = ap.parse_args()

    pol, params, sc, st = mid_run_states(args.policy, args.batch, args.warmup_ticks)
    inputs, table, tick = stages(pol, params)
    x = jax.jit(jax.vmap(inputs))(sc, st)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}, "
          f"{jax.device_count()} device(s) (stages run on one); batch {args.batch} "
          f"mid-run states of {args.policy}")  # fmt: skip
    tick_fn = jax.jit(jax.vmap(tick, in_axes=(0, 0, None)))
    whole = timed(tick_fn, (sc, st, None), args.repeats)
    rows = []
    for label, fn in table.items():
        jfn = jax.jit(jax.vmap(fn))
        stage_args = (sc, st, x)
        rows.append((label, timed(jfn, stage_args, args.repeats), flops_of(jfn, stage_args)))
    total = sum(s for _, s, _ in rows)
    per = 1e6 / args.batch
    print(f"{'stage':<40} {'us/scenario-tick':>17} {'share of stages':>16} {'kFLOP':>8}")
    for label, s, f in sorted(rows, key=lambda r: -r[1]):
        print(f"{label:<40} {s * per:17.1f} {100 * s / total:15.1f} % "
              f"{f / args.batch / 1e3:8.1f}")  # fmt: skip
    print(f"{'sum of the stages':<40} {total * per:17.1f}")
    print(f"{'whole tick (one program)':<40} {whole * per:17.1f}")
    cost = tick_fn.lower(sc, st, None).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    flops, nbytes = cost.get("flops", 0.0), cost.get("bytes accessed", 0.0)
    print(f"XLA cost analysis of the whole tick: {flops / args.batch / 1e3:,.0f} kFLOP and "
          f"{nbytes / args.batch / 1e3:,.0f} kB per scenario-tick; achieved "
          f"{flops / whole / 1e9:,.1f} GFLOP/s and {nbytes / whole / 1e9:,.1f} GB/s "
          "on one device")  # fmt: skip


if __name__ == "__main__":
    main()
