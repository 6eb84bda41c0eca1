"""Which compiled kernels a tick spends its time in, and which source lines each one computes.

Runs one tick (:func:`lantern_jax.sim.step.step`, jitted and vmapped) over a batch of real
mid-run states of the built-in suite (as ``profile_tick.py`` does), records ``--calls`` calls
with JAX's profiler, and adds up the time of every XLA kernel (fusion, loop, copy) per call.
Each kernel is then traced back to the lines of ``lantern_jax`` whose operations it contains
(the compiled module's stack-frame table), so a kernel that re-derives upstream work (a
producer fused into a much larger consumer and recomputed for every element) shows up with
source lines far from its own.

Usage::

    python benchmarks/profile_kernels.py [--policy coop] [--batch 96] [--top 15] [--scan 40]

``--scan N`` times N ticks scanned in one program, as the evaluation's rollout runs them: work
that does not change from tick to tick (the static scenario's own geometry) is then computed
once before the loop, which a lone tick cannot show, so a rewrite that speeds up the lone tick
can still slow the rollout.  Times are then per tick (the scan's total over N).

Runs on one device; kernel times are wall times inside XLA's runtime and vary with the load
of the machine (compare runs side by side).  A loop's own row covers its whole body; its body
kernels are listed too, with their count per call.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import tempfile

os.environ.setdefault("LANTERN_JAX_CPU_DEVICES", "1")

from lantern_jax.cli import expose_cpu_cores  # noqa: E402

expose_cpu_cores()

import jax  # noqa: E402
from profile_tick import mid_run_states  # noqa: E402  (this folder's tick profiler)

from lantern_jax.sim.step import step  # noqa: E402

_SECTIONS = ("FileNames", "FunctionNames", "FileLocations", "StackFrames")


def source_table(hlo: str) -> dict[int, list[tuple[str, int]]]:
    """Stack frame id -> [(file, line), ...] innermost first, from a compiled module's text."""
    files, locs, frames = {}, {}, {}
    section = None
    for line in hlo.splitlines():
        if line in _SECTIONS:
            section = line
            continue
        if section and not line.strip():
            section = None
            continue
        if section == "FileNames":
            m = re.match(r'(\d+) "(.*)"', line)
            if m:
                files[int(m.group(1))] = m.group(2)
        elif section == "FileLocations":
            m = re.match(r"(\d+) \{file_name_id=(\d+) .*?line=(\d+)", line)
            if m:
                locs[int(m.group(1))] = (files.get(int(m.group(2)), "?"), int(m.group(3)))
        elif section == "StackFrames":
            m = re.match(r"(\d+) \{file_location_id=(\d+) parent_frame_id=(\d+)", line)
            if m:
                frames[int(m.group(1))] = (int(m.group(2)), int(m.group(3)))

    def chain(fid: int) -> list[tuple[str, int]]:
        out, seen = [], set()
        while fid in frames and fid not in seen:
            seen.add(fid)
            loc, parent = frames[fid]
            if loc in locs:
                out.append(locs[loc])
            fid = parent
        return out

    return {fid: chain(fid) for fid in frames}


def kernel_sources(hlo: str, name: str, table, top: int = 3) -> tuple[str, list[str]]:
    """Output shape of kernel ``name`` and its most frequent ``lantern_jax`` source lines."""
    call = next((ln for ln in hlo.splitlines() if re.search(rf"%{re.escape(name)} = ", ln)), "")
    shape = call.split(" = ", 1)[1].split(" ", 1)[0] if " = " in call else "?"
    called = re.search(r"calls=%([\w.\-]+)", call)
    body = call
    if called:
        m = re.search(rf"\n%?{re.escape(called.group(1))} \(.*?\{{\n(.*?)\n\}}", hlo, re.S)
        body = m.group(1) if m else call
    counts = collections.Counter()
    for fid in re.findall(r"stack_frame_id=(\d+)", body):
        inner = [(f, ln) for f, ln in table.get(int(fid), []) if "lantern_jax/" in f]
        if inner:
            f, ln = inner[0]
            counts[f"{f.split('lantern_jax/', 1)[1]}:{ln}"] += 1
    return shape[:40], [k for k, _ in counts.most_common(top)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--batch", type=int, default=96)
    ap.add_argument("--warmup-ticks", type=int, default=160)
    ap.add_argument("--calls", type=int, default=20)
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--scan", type=int, default=0,
                    help="profile a scanned chunk of this many ticks, as the evaluation's "
                         "rollout runs them (0: one tick on its own)")  # fmt: skip
    args = ap.parse_args()

    pol, params, sc, st = mid_run_states(args.policy, args.batch, args.warmup_ticks)
    sc, st = jax.device_put((sc, st), jax.devices()[0])

    def tick(s, x):
        return step(pol, params, s, x)[0]  # the default settings, as the evaluation's

    ticks = max(args.scan, 1)
    program = tick
    if args.scan:
        # as rollout_batch runs them: work that does not change from tick to tick (the static
        # scenario's own geometry) can be hoisted out of the scan by the compiler, which a
        # lone tick cannot show
        def program(s, x):
            return jax.lax.scan(lambda c, _: (tick(s, c), None), x, None, length=ticks)[0]

    compiled = jax.jit(jax.vmap(program)).lower(sc, st).compile()
    hlo = compiled.as_text()
    jax.block_until_ready(compiled(sc, st))
    with tempfile.TemporaryDirectory() as tmp:
        with jax.profiler.trace(tmp, create_perfetto_trace=True):
            for _ in range(args.calls):
                out = compiled(sc, st)
            jax.block_until_ready(out)
        trace_files = glob.glob(os.path.join(tmp, "**", "*.trace.json.gz"), recursive=True)
        if not trace_files:
            raise SystemExit("profile_kernels: the profiler wrote no trace file")
        with gzip.open(trace_files[0]) as fh:
            events = json.load(fh)["traceEvents"]

    names = set(re.findall(r"^\s+%([\w.\-]+) = ", hlo, re.M))
    total_us, calls = collections.Counter(), collections.Counter()
    for e in events:
        if e.get("ph") == "X" and e.get("name") in names:
            total_us[e["name"]] += e.get("dur", 0.0)
            calls[e["name"]] += 1
    kernels_us = sum(v for k, v in total_us.items() if not k.startswith("while"))
    table = source_table(hlo)
    per = 1.0 / (args.calls * ticks)  # per tick
    what = f"{args.calls} calls of {ticks} scanned ticks" if args.scan else f"{args.calls} calls"
    print(f"policy {args.policy}, batch {args.batch} mid-run states, {what}, one "
          f"device: kernels {kernels_us * per:,.0f} us per tick "
          f"({kernels_us * per / args.batch:.1f} us per scenario-tick), "
          f"{len(names)} instructions in the compiled tick")  # fmt: skip
    print(f"{'us/tick':>8} {'share':>6} {'n/tick':>6}  {'kernel':<38} {'shape':<28} source lines")
    for name, us in total_us.most_common(args.top):
        shape, lines = kernel_sources(hlo, name, table)
        share = f"{100 * us / kernels_us:5.1f}%" if not name.startswith("while") else "  loop"
        print(f"{us * per:8.0f} {share:>6} {calls[name] * per:6.1f}  {name:<38} {shape:<28} "
              f"{', '.join(lines)}")  # fmt: skip


if __name__ == "__main__":
    main()
