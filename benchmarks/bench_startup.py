"""What a new process pays before it does anything: importing NumPy's dtype extensions, JAX and
the command line's first command.

Every process of the tool imports JAX: each command, each test that starts one, each worker of
the test runner, each notebook kernel.  This prints, per step, the median wall and CPU seconds
over fresh processes (``--runs`` each), and the versions imported:

* ``import ml_dtypes`` -- after NumPy (JAX imports it: NumPy's bfloat16, float8 and int4
  types); its 0.7.0 release registers its casts and ufunc loops in 0.57 s of CPU on a 2-core
  x86 CPU against 0.004 s for 0.6.0 (each new loop is compared with every loop already
  registered), which is why ``pyproject.toml`` leaves that release out;
* ``import jax``;
* ``lantern-jax policies`` -- a whole command (start-up, JAX, the registry), as a test or a
  user runs one.

``--extra-path DIR`` (repeatable) puts folders in front of the import path of every process
(``pip install --target DIR ml_dtypes==X`` there compares another release in the same run).

Usage::

    python benchmarks/bench_startup.py [--runs 7]
    python benchmarks/bench_startup.py --extra-path /tmp/ml_dtypes_070 --runs 7
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

STEPS = {
    "import ml_dtypes (after numpy)": "import numpy, ml_dtypes",
    "import jax": "import jax",
    "lantern-jax policies": "import sys; sys.argv = ['lantern-jax', 'policies']; "
                            "from lantern_jax.cli import main; main()",
}  # fmt: skip


def _run(code: str, env: dict) -> tuple[float, float]:
    """(wall s, CPU s of the child) of ``python -c code`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=7, help="fresh processes per step (median)")
    ap.add_argument("--extra-path", action="append", default=[],
                    help="folder put in front of every process's import path")  # fmt: skip
    args = ap.parse_args()
    env = dict(os.environ)
    if args.extra_path:
        env["PYTHONPATH"] = os.pathsep.join(args.extra_path + [env.get("PYTHONPATH", "")])
    versions = subprocess.run(
        [sys.executable, "-c", "import numpy, ml_dtypes, jax; "
         "print(numpy.__version__, ml_dtypes.__version__, jax.__version__)"],
        env=env, check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    print(f"{platform.machine()} {os.cpu_count()} CPUs, Python {platform.python_version()}, "
          f"numpy {versions[0]}, ml_dtypes {versions[1]}, jax {versions[2]}, "
          f"load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    print(f"{'step':34s} {'wall s':>8s} {'CPU s':>8s}   (median of {args.runs} processes)")
    for name, code in STEPS.items():
        runs = [_run(code, env) for _ in range(args.runs)]
        wall = statistics.median(r[0] for r in runs)
        cpu = statistics.median(r[1] for r in runs)
        print(f"{name:34s} {wall:8.3f} {cpu:8.3f}")


if __name__ == "__main__":
    main()
