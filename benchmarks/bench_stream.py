"""Scaling of streamed evaluation: executions/s and peak memory from 1k to 100k executions.

Each count runs in a fresh process (so its peak RSS is its own): the ``ego`` policy on the
stress batch of the built-in suite (:func:`lantern_jax.apps.stream.stress_source`: the suite's 360
executions cycled, hazard speed and trigger perturbed per copy), in chunks of ``--chunk``
executions, with the command line's device setup (one XLA CPU device per core).
Executions/s excludes compilation (reported separately).

    python benchmarks/bench_stream.py                       # 1k, 3k, 10k, 30k, 100k
    python benchmarks/bench_stream.py --counts 1000 10000 --chunk 1000
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

WORKER = r"""
import json, resource, sys, time
from lantern_jax.cli import expose_cpu_cores
expose_cpu_cores()
import jax
from lantern_jax.policies.registry import get_policy
from lantern_jax.apps.stream import stream_executions, stress_source
count, chunk = int(sys.argv[1]), int(sys.argv[2])
source, max_ticks, _ = stress_source()
ego = get_policy("ego")
res = stream_executions(ego, ego.init(jax.random.PRNGKey(0)), source, count, max_ticks,
                        chunk=min(chunk, count), progress=sys.stderr.isatty())
run = res.seconds_total - res.seconds_compile
print(json.dumps(dict(count=count, chunk=min(chunk, count), chunks=res.chunks,
                      devices=jax.device_count(), seconds_compile=round(res.seconds_compile, 1),
                      seconds_run=round(run, 1), executions_per_s=round(count / run, 1),
                      peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
                      completed=float(res.metrics["completed"].mean()))))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args()
    rows = []
    print("| executions | chunks | compile (s) | run (s) | executions/s | peak RSS (MB) |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in args.counts:
        out = subprocess.run(
            [sys.executable, "-c", WORKER, str(n), str(args.chunk)],
            env=os.environ.copy(),
            check=True,
            stdout=subprocess.PIPE,
            text=True,
        )
        row = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append(row)
        print(
            f"| {row['count']:,} | {row['chunks']} | {row['seconds_compile']} | "
            f"{row['seconds_run']} | {row['executions_per_s']:,} | {row['peak_rss_mb']:,} |",
            flush=True,
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
