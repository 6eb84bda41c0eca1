"""The inner loop: from an edited policy to its table, on the split path and on the fused one.

Three edits, each measured in a fresh process (so nothing of an earlier edit stays in memory):

* ``constant`` -- ``coop`` with one planner constant changed (its parameters, not its code);
* ``mlp`` -- a new two-layer MLP policy (random weights) defined in the process, as a notebook
  or a new file defines one;
* ``template`` -- ``examples/my_policy.py``, loaded from its file as ``--policy FILE:POLICY``
  loads it.

Each edit runs on the 6-pair subset and on the whole suite, with a **cold store** (an empty
compile cache and program store), with the **world program stored** (only the world's:
:func:`lantern_jax.sim.engine.warm_world` run first in another process) and, for ``constant``,
with **coop's program stored** (an earlier process ran the unedited ``coop`` on the same batch
and path: the edited policy has ``coop``'s code, so it shares that program), and, for the new
policies, as a **rerun** (the world program stored, then another new policy -- ``template``,
or ``mlp`` for the template -- ran on the same batch: the loop of editing a policy and running
it again, where only the edited policy's own program is new), on the path that
``"auto"`` chooses and on the fused path.  The time is the wall time of
``lantern_jax.evaluate([policy], suite=..., path=...)`` and the family table's formatting,
inside the process (what a notebook user waits for); the process's own start-up (Python,
imports) is printed apart.

Usage::

    python benchmarks/bench_iterate.py                 # every case (about 15 min on 2 cores)
    python benchmarks/bench_iterate.py --edits mlp --batches subset --stores stored
    python benchmarks/bench_iterate.py --markdown benchmarks/results/bench_iterate.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EDITS = ("constant", "mlp", "template")
BATCHES = ("subset", "suite")
STORES = ("cold", "stored", "coop-stored", "rerun")
PATHS = ("auto", "fused")


def _policy(edit: str):
    """The edited policy (built in this process)."""
    import jax
    import jax.numpy as jnp

    import lantern_jax as lj
    from lantern_jax.commands.common import resolve_policies
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.types.observation import WARNING

    if edit == "coop":  # the unedited policy (what an earlier run left in the store)
        return get_policy("coop")
    if edit == "constant":
        coop = get_policy("coop")

        def init(key):
            params = coop.init(key)
            planner = params.planner
            return params.replace(planner=planner.replace(max_brake=planner.max_brake * 0.9))

        return lj.Policy("coop-edited", init, coop.act, sensors=coop.sensors)
    if edit == "mlp":

        def init(key):
            k1, k2 = jax.random.split(key)
            return dict(w1=jax.random.normal(k1, (8, 32)) * 0.1,
                        w2=jax.random.normal(k2, (32, 1)) * 0.1)  # fmt: skip

        def act(params, obs):
            x = jnp.stack([obs.ego_speed, obs.v_ref, obs.dist_to_stop.clip(0, 50) / 50,
                           obs.visible.any().astype(jnp.float32), obs.route[2, 0], obs.route[2, 1],
                           (obs.warning_tokens > 0).any().astype(jnp.float32), 1.0])  # fmt: skip
            speed = obs.v_ref * jax.nn.sigmoid(jnp.tanh(x @ params["w1"]) @ params["w2"])[0]
            k = jnp.arange(1, 11, dtype=jnp.float32) * 0.25 * speed
            along = jnp.arange(obs.route.shape[0]) * 2.0
            return jnp.stack([jnp.interp(k, along, obs.route[:, 0]),
                              jnp.interp(k, along, obs.route[:, 1])], -1)  # fmt: skip

        return lj.Policy("mlp", init, act, sensors=(WARNING,))
    name = resolve_policies([str(ROOT / "examples" / "my_policy.py") + ":POLICY"], "--policy")[0]
    return get_policy(name)


def one(edit: str, batch: str, path: str) -> dict:
    """One measurement in this process (the cache folder is the environment's)."""
    t_start = time.perf_counter()
    import lantern_jax as lj
    from lantern_jax.report import format_family_table

    t_imports = time.perf_counter() - t_start
    pol = _policy(edit)
    suite = lj.load_suite()
    suite = suite.subset(1) if batch == "subset" else suite
    t0 = time.perf_counter()
    result = lj.evaluate([pol], suite=suite, progress=False, path=path)
    format_family_table(result.family_table)
    seconds = time.perf_counter() - t0
    run = result.runs[0]
    return dict(seconds=seconds, imports=t_imports, program=run.program,
                compile=run.seconds_compile + result.seconds.get("split programs", 0.0),
                rollout=run.timings.get("rollout", float("nan")))  # fmt: skip


def _child(args: list[str], cache: str) -> dict:
    env = dict(os.environ, LANTERN_JAX_CACHE_DIR=cache)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    out = subprocess.run([sys.executable, __file__, *args], env=env, capture_output=True,
                         text=True, check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def _warm(cache: str) -> float:
    env = dict(os.environ, LANTERN_JAX_CACHE_DIR=cache)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    code = "import lantern_jax; from lantern_jax.sim.engine import warm_world; print(warm_world())"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True)  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edits", default=",".join(EDITS))
    ap.add_argument("--batches", default=",".join(BATCHES))
    ap.add_argument("--stores", default=",".join(STORES))
    ap.add_argument("--paths", default=",".join(PATHS))
    ap.add_argument("--markdown", metavar="FILE", help="also write the table there")
    ap.add_argument("--one", nargs=3, metavar=("EDIT", "BATCH", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(*args.one)))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        stored = os.path.join(tmp, "stored")
        t_world = _warm(stored) if "stored" in args.stores.split(",") else float("nan")
        for store in args.stores.split(","):
            for edit in args.edits.split(","):
                if store == "coop-stored" and edit != "constant":
                    continue  # a new policy shares no program with an earlier one
                if store == "rerun" and edit == "constant":
                    continue  # coop-stored is the constant's rerun
                for batch in args.batches.split(","):
                    for path in args.paths.split(","):
                        cache = stored if store == "stored" else os.path.join(
                            tmp, f"{store}-{edit}-{batch}-{path}")  # fmt: skip
                        if store == "stored":  # only the world program: drop what runs added
                            _keep_world_only(stored)
                        if store == "coop-stored":  # an earlier run of the unedited coop
                            _child(["--one", "coop", batch, path], cache)
                        if store == "rerun":  # the world stored, then another new policy ran
                            _warm(cache)
                            other = "template" if edit != "template" else "mlp"
                            _child(["--one", other, batch, path], cache)
                        r = _child(["--one", edit, batch, path], cache)
                        rows.append(dict(store=store, edit=edit, batch=batch, asked=path, **r))
                        print(_row(rows[-1]), flush=True)
    head = ("| store | edit | batch | asked | path taken | to the table s | compile s | "
            "rollout s | imports s |\n|---|---|---|---|---|---|---|---|---|")  # fmt: skip
    text = "\n".join([
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}; "
        f"load average before: {os.getloadavg()[0]:.2f}; world program compiled and stored in "
        f"{t_world:.1f} s.", "", head, *map(_row, rows)])  # fmt: skip
    print()
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")


_WORLD = None


def _keep_world_only(folder: str) -> None:
    """Leave only the world program's stored entries (and JAX's cache of them): the entries
    present right after :func:`_warm`."""
    global _WORLD
    root = Path(folder)
    files = {p for p in root.rglob("*") if p.is_file()}
    if _WORLD is None:
        _WORLD = files
        return
    for p in files - _WORLD:
        p.unlink()


def _row(r: dict) -> str:
    path = r["program"].split(" ")[0]
    return (f"| {r['store']} | {r['edit']} | {r['batch']} | {r['asked']} | {path} | "
            f"{r['seconds']:.1f} | {r['compile']:.1f} | {r['rollout']:.2f} | {r['imports']:.1f} |")


if __name__ == "__main__":
    main()
