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
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from lantern_jax.constants import DT  # noqa: E402
from lantern_jax.dynamics.actors import step_actors  # noqa: E402
from lantern_jax.dynamics.controller import follow_plan  # noqa: E402
from lantern_jax.dynamics.lights import ego_light_state, light_holds_ego, light_states  # noqa: E402
from lantern_jax.evaluate import build_executions, run_executions  # noqa: E402
from lantern_jax.observation import corridor_gaps  # noqa: E402
from lantern_jax.policies.registry import get_policy  # noqa: E402
from lantern_jax.scenarios import protocol  # noqa: E402
from lantern_jax.scenarios.suite import load_suite  # noqa: E402
from lantern_jax.scoring.measure import execution_ended, justified_stop, measure  # noqa: E402
from lantern_jax.scoring.telemetry import update_telemetry  # noqa: E402
from lantern_jax.sim.observe import (  # noqa: E402
    actors_in_ego_frame,
    delivered_warning,
    observe,
    route_ahead,
)
from lantern_jax.sim.sense import locate_on_route, sense  # noqa: E402
from lantern_jax.sim.step import step  # noqa: E402
from lantern_jax.world import present  # noqa: E402


def stages(policy, params):
    """The stages of one tick as functions of (scenario, state, inputs of the stage)."""
    temp = jnp.float32(0.05)

    def inputs(sc, st):
        """Every intermediate of one tick (mirrors ``step``)."""
        cfg, script, h = sc.config, sc.actors, sc.config.hazard_index
        obs = observe(sc, st, policy.sensors)
        wp, _ = policy.step(params, st.policy_carry, obs)
        warned = delivered_warning(sc, st)[0]
        truth = actors_in_ego_frame(sc, st)
        ego, fault, _ = follow_plan(st.ego, wp, cfg.friction)
        t = st.t + DT
        arc, dist, progress = locate_on_route(sc.route, ego.xy, st.percept.progress)
        light = ego_light_state(sc.lights, cfg.ego_light, t)
        gap, lateral = corridor_gaps(
            route_ahead(sc, st)[0], truth["actor_xy"], truth["actor_dir"], truth["actor_extent"]
        )
        pb = present(script, st.actors)
        held = protocol.ego_held(
            light, cfg.ego_stop_s - arc, gap, lateral, pb, script.role, st.actors.speed
        )
        proto = protocol.advance_markers(st.protocol, cfg, t, st.percept.progress, progress, held)
        actors = step_actors(
            st.actors, script, t, proto.t_event, light_states(sc.lights, t), ego.xy, ego.yaw,
            ego.speed,
        )  # fmt: skip
        percept = sense(sc, ego, actors, arc, dist, progress)
        vis = percept.visible[h] & present(script, actors)[h]
        proto = protocol.advance_hazard(proto, cfg, t, vis, actors.s[h], ego.speed)
        proto = protocol.record_onset(proto, st.protocol, cfg, vis, warned)
        justified = justified_stop(
            light_holds_ego(light, cfg.ego_stop_s - arc), gap, lateral, pb,
            sc.route.length - arc,
        )  # fmt: skip
        return dict(obs=obs, wp=wp, ego=ego, fault=fault, t=t, arc=arc, dist=dist,
                    progress=progress, light=light, proto=proto, actors=actors,
                    justified=justified)  # fmt: skip

    def s_observe(sc, st, x):
        return observe(sc, st, policy.sensors)

    def s_policy(sc, st, x):
        return policy.step(params, st.policy_carry, x["obs"])

    def s_controller(sc, st, x):
        return follow_plan(st.ego, x["wp"], sc.config.friction)[:2]

    def s_route(sc, st, x):
        return locate_on_route(sc.route, x["ego"].xy, st.percept.progress)

    def s_actors(sc, st, x):
        e = x["ego"]
        lights = light_states(sc.lights, x["t"])
        return step_actors(
            st.actors, sc.actors, x["t"], x["proto"].t_event, lights, e.xy, e.yaw, e.speed
        )

    def s_sense(sc, st, x):
        return sense(sc, x["ego"], x["actors"], x["arc"], x["dist"], x["progress"])

    def s_score(sc, st, x):
        sample = measure(
            sc, x["ego"], x["actors"], present(sc.actors, x["actors"]), x["proto"], x["t"],
            x["progress"], x["dist"], st.percept.route_arc, x["arc"], x["light"],
            x["justified"], x["fault"],
        )  # fmt: skip
        tel = update_telemetry(st.telemetry, sample, temp)
        done = execution_ended(sc, x["t"], x["progress"], x["dist"], x["proto"].ego_still_time)
        return tel, done

    def s_tick(sc, st, x):
        return step(policy, params, sc, st, temp)[0]

    table = {
        "observation (warning fields, corridor)": s_observe,
        "policy act": s_policy,
        "controller + bicycle": s_controller,
        "route projection": s_route,
        "actors (IDM, scripts, lights)": s_actors,
        "sensing (visibility, range image)": s_sense,
        "measurement + telemetry + end test": s_score,
    }
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
    idx = np.linspace(0, 3 * execs.num_pairs - 1, batch).astype(int)
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
