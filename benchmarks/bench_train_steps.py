"""Training steps one per compiled call against :data:`~lantern_jax.apps.training.fit.
STEPS_PER_CALL` per call, in interleaved rounds.

Each run is a fresh process that sets ``fit.STEPS_PER_CALL`` and then trains as ``lantern-jax
train`` does (the config's recipe, ``--epochs`` overriding it) into a temporary folder.  Printed
per run: the training loop's own seconds and examples per second (the summary's ``seconds`` and
``frames_per_s``; for the closed-loop recipe, every round's, without driving the round's scenes),
the process's wall and user CPU time, its peak resident memory, and the first 12 hex digits of
the exported weights' SHA-256 (the same for every group size: a group's steps are the steps one
call each runs, bit for bit).

Usage (from the project root; needs a dataset, ``lantern-jax dataset --out data/lantern``)::

    python benchmarks/bench_train_steps.py --config configs/train_base_rig_bigram.toml
    python benchmarks/bench_train_steps.py \\
        --config configs/train_distance_onset_only_rig_bigram.toml \\
        --init-from runs/train/.../learned-base-rig-bigram.msgpack --sizes 1,8 --rounds 3
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The child process: train with the group size given, print the summary as JSON.
CHILD = """
import dataclasses, json, sys
from lantern_jax.apps.training import fit
from lantern_jax.apps.training.behaviour_cloning import train
from lantern_jax.apps.training.config import load_config
fit.STEPS_PER_CALL = int(sys.argv[1])
cfg = load_config(sys.argv[2])
over = json.loads(sys.argv[3])
summary = train(dataclasses.replace(cfg, **over), progress=False)
print("SUMMARY " + json.dumps(summary, default=str))
"""


def one_run(size: int, config: str, over: dict) -> dict:
    """One training process with ``size`` steps per call; its figures."""
    with tempfile.TemporaryDirectory() as tmp:
        over = dict(over, out=str(Path(tmp) / "run"))
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", CHILD, str(size), config, json.dumps(over)],
                                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)  # fmt: skip
        out = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own resource usage
        wall = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            sys.exit(f"train failed (steps per call {size}):\n{out[-2000:]}")
        summary = json.loads(out.split("SUMMARY ", 1)[1].splitlines()[0])
        out_dir = Path(over["out"])
        rounds = out_dir / "rounds.json"
        fits = json.loads(rounds.read_text()) if rounds.exists() else [summary]
        digest = hashlib.sha256(Path(summary["model"]).read_bytes()).hexdigest()[:12]
        return dict(size=size, fit_s=[round(float(r["seconds"]), 1) for r in fits],
                    per_s=[round(float(r["frames_per_s"])) for r in fits], wall_s=wall,
                    user_s=usage.ru_utime, peak_gb=usage.ru_maxrss / 2**20, sha=digest)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/train_base_rig_bigram.toml")
    ap.add_argument("--init-from", default=None)
    ap.add_argument("--epochs", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    ap.add_argument("--closed-loop-rounds", type=int, default=None,
                    help="DAgger rounds (closed-loop recipe only; default the config's)")
    ap.add_argument("--sizes", default="1,8", help="steps per call to compare, comma-separated")
    args = ap.parse_args()
    over: dict = dict(epochs=args.epochs, seed=0)
    if args.init_from:
        over["init_from"] = args.init_from
    if args.closed_loop_rounds:
        over["rounds"] = args.closed_loop_rounds
    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; {args.config}, {args.epochs} epoch(s); load average "
          f"{os.getloadavg()[0]:.2f} at the start")  # fmt: skip
    print(f"{'steps/call':>10} {'fit s':>16} {'examples/s':>18} {'wall s':>7} {'user s':>7} "
          f"{'peak GB':>8}  weights")  # fmt: skip
    for _ in range(args.rounds):
        for size in sizes:
            r = one_run(size, args.config, over)
            print(f"{r['size']:>10} {str(r['fit_s']):>16} {str(r['per_s']):>18} "
                  f"{r['wall_s']:7.1f} {r['user_s']:7.1f} {r['peak_gb']:8.2f}  {r['sha']}",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
