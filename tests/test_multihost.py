"""Evaluation across processes with JAX's distributed runtime equals one process, row for row.

Two local processes with two CPU devices each (a global mesh of four devices, CPU collectives)
run ``lantern-jax evaluate`` on one pair per family; a single process with one device runs the
same command.  The slot scheduling is forced (``COMPACT_MIN_BATCH = 1``, two slots per device)
so that every device refills its slots with waiting executions inside the program, and the
final states are gathered across processes.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest

from lantern_jax.scoring.table import compare_route_tables, read_route_table
from lantern_jax.sim.distributed import placement, wait_for_every_process

WORKER = (
    "import sys, lantern_jax.apps.evaluation as e; e.COMPACT_MIN_BATCH = 1; "
    "e.compact_slots = lambda backend=None: 2; "
    "from lantern_jax.cli import main; sys.exit(main(sys.argv[1:]))"
)
COMMAND = ["evaluate", "--policy", "ego", "--pairs-per-family", "1", "--quiet"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(devices: int) -> dict[str, str]:
    """The processes' environment: ``devices`` CPU devices, the tests' XLA flags (the earlier
    fusion emitters compile the three processes' programs in less time)."""
    from conftest import TEST_XLA_FLAGS

    env = dict(os.environ)
    env["XLA_FLAGS"] = f"{TEST_XLA_FLAGS} --xla_force_host_platform_device_count={devices}"
    return env


@pytest.mark.slow
def test_two_processes_give_the_single_process_rows(tmp_path):
    # the one-process reference first, not beside the two: less load on a 2-core machine
    # (the processes' barrier before the program, lantern_jax.sim.distributed, is what keeps
    # the two-process run from failing under load)
    single = subprocess.run(
        [sys.executable, "-c", WORKER, *COMMAND, "--out", str(tmp_path / "single")],
        env=_env(1), capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert single.returncode == 0, single.stderr[-2000:]
    port = _free_port()
    multi = [
        subprocess.Popen(
            [
                sys.executable,
                "-c",
                WORKER,
                *COMMAND,
                "--out",
                str(tmp_path / "multi"),
                "--coordinator",
                f"127.0.0.1:{port}",
                "--num-processes",
                "2",
                "--process-id",
                str(i),
            ],
            env=_env(2),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )  # fmt: skip
        for i in range(2)
    ]
    try:
        outs = [p.communicate(timeout=900)[0] for p in multi]
    finally:
        for p in multi:  # one that failed can leave the other waiting for it: end both
            if p.poll() is None:
                p.kill()
                p.communicate()
    for p, out in zip(multi, outs, strict=True):
        assert p.returncode == 0, out[-2000:]
    assert "Per-family CUS" in outs[0] and "Per-family CUS" not in outs[1]  # process 0 writes
    one = read_route_table(tmp_path / "single" / "route_level_results.csv")
    two = read_route_table(tmp_path / "multi" / "route_level_results.csv")
    assert len(one) == 12  # 6 pairs x (warning, no-warning)
    ok, lines = compare_route_tables(one, two)
    assert ok, "\n".join(lines)


def test_one_process_has_nothing_to_wait_for():
    """Without the distributed runtime the barrier before a program returns at once, and the
    placement leaves batches as they are."""
    assert wait_for_every_process("test") is None
    place = placement()
    assert place.processes == 1 and place.multiple == 1
    assert place.align("test") is None
    tree = {"x": [1, 2]}
    assert place.put(tree) is tree and place.get(tree) is tree
