"""A training stage with glibc's allocator as the system leaves it and as ``lantern-jax train``
sets it (:mod:`lantern_jax.core.allocator`), in interleaved rounds.

Each run is a fresh ``lantern-jax train`` process (``LANTERN_JAX_MALLOC=system`` or ``keep``)
into a temporary folder.  Printed per run: the training loop's own seconds (the summary's
``seconds``), the process's wall time, its user and system CPU time, minor page faults and peak
resident memory (``wait4``'s usage of that process), and the first 12 hex digits of the exported
weights' SHA-256 (the same in every run: the allocator does not change what is computed).

Usage (from the project root; needs a dataset, ``lantern-jax dataset --out data/lantern``)::

    python benchmarks/bench_train_allocator.py                     # base rig stage, 2 epochs
    python benchmarks/bench_train_allocator.py --rounds 3 --epochs 1
    python benchmarks/bench_train_allocator.py --config configs/train_closed_loop_rig_bigram.toml \
        --init-from runs/train/.../learned-distance-onset-only-rig-bigram.msgpack --epochs 1
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "lantern_jax"]


def one_run(config: str, epochs: int, choice: str, init_from: str | None) -> dict:
    """One training process with ``LANTERN_JAX_MALLOC=choice``; its figures."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = [*CLI, "train", "--config", config, "--epochs", str(epochs), "--out", str(out),
               "--seed", "0", "--quiet"]  # fmt: skip
        if init_from:
            cmd += ["--init-from", init_from]
        log = Path(tmp) / "stdout.txt"
        t0 = time.perf_counter()
        with open(log, "w") as f:
            proc = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                                    env={**os.environ, "LANTERN_JAX_MALLOC": choice})  # fmt: skip
            _, status, usage = os.wait4(proc.pid, 0)  # this child's own resource usage
            proc.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        text = log.read_text()
        if proc.returncode != 0:
            sys.exit(f"train failed ({choice}):\n{text[-2000:]}")
        summary = dict(line.strip().split(": ", 1) for line in text.splitlines()
                       if ": " in line)  # fmt: skip
        model = Path(summary["model"])
        return dict(
            choice=choice,
            fit_s=float(summary["seconds"]),
            wall_s=wall,
            user_s=usage.ru_utime,
            sys_s=usage.ru_stime,
            faults_m=usage.ru_minflt / 1e6,
            peak_gb=usage.ru_maxrss / 1e6,  # kB
            weights=hashlib.sha256(model.read_bytes()).hexdigest()[:12],
        )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/train_base_rig_bigram.toml")
    ap.add_argument("--epochs", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2, help="interleaved system/keep pairs")
    ap.add_argument("--init-from", default=None)
    args = ap.parse_args(argv)
    print(f"{args.config}, {args.epochs} epoch(s), {args.rounds} interleaved round(s); "
          f"load average at start {os.getloadavg()[0]:.2f}")  # fmt: skip
    print(f"{'allocator':>9} {'fit s':>7} {'wall s':>7} {'user s':>7} {'sys s':>7} "
          f"{'faults M':>9} {'peak GB':>8}  weights")  # fmt: skip
    for _ in range(args.rounds):
        for choice in ("system", "keep"):
            r = one_run(args.config, args.epochs, choice, args.init_from)
            print(f"{r['choice']:>9} {r['fit_s']:7.1f} {r['wall_s']:7.1f} {r['user_s']:7.1f} "
                  f"{r['sys_s']:7.1f} {r['faults_m']:9.2f} {r['peak_gb']:8.2f}  {r['weights']}",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
