"""What loading a learned model's checkpoint costs a fresh process, in seconds.

Each round starts a new Python process that imports the package, then loads every shipped
checkpoint (:func:`lantern_jax.policies.learned.checkpoint.load_model`) one after another and
prints the seconds of the first load and of all of them.  Two settings of the cache:

* ``cold`` -- an empty cache folder (``LANTERN_JAX_CACHE_DIR``) for the process, as on a new
  machine: every program the load runs is compiled;
* ``warm`` -- the folder an earlier process of the same setting filled.

Prints one line per process with the machine's load; run it once per code version, the
versions interleaved, to compare them::

    python benchmarks/bench_model_load.py --rounds 3
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

CHILD = """
import json, time
t0 = time.perf_counter()
import lantern_jax
from lantern_jax.policies.learned import checkpoint as ck
from lantern_jax.policies.learned.shipped import SHIPPED_MODELS
t1 = time.perf_counter()
times = []
for name in SHIPPED_MODELS:
    t = time.perf_counter()
    ck.load_model(ck.shipped_path(name))
    times.append(time.perf_counter() - t)
print(json.dumps(dict(imports=t1 - t0, first=times[0], all=sum(times), models=len(times))))
"""


def child(cache: str) -> dict:
    """One fresh process's figures, with ``cache`` as its cache folder."""
    env = dict(os.environ, LANTERN_JAX_CACHE_DIR=cache)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True,
                         check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    print(f"Machine: {platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}")
    with tempfile.TemporaryDirectory() as warm:
        child(warm)  # fills the warm folder
        for r in range(args.rounds):
            for setting in ("cold", "warm"):
                load = os.getloadavg()[0]
                if setting == "cold":
                    with tempfile.TemporaryDirectory() as cold:
                        f = child(cold)
                else:
                    f = child(warm)
                print(f"round {r} {setting}: first model {f['first']:.2f} s, all {f['models']} "
                      f"{f['all']:.2f} s (imports {f['imports']:.2f} s; load average "
                      f"{load:.2f})", flush=True)  # fmt: skip
                time.sleep(0.5)


if __name__ == "__main__":
    main()
