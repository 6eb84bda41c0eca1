"""XLA's slow-operation alarms are dropped from standard error while a command runs; every other
byte passes, progress-bar updates at once, and nothing is lost when the filter closes."""

from __future__ import annotations

import subprocess
import sys

ALARM_BLOCK = (
    "E1126 13:27:16.559406    8585 slow_operation_alarm.cc:73] \n"
    "********************************\n"
    "[Compiling module jit_one for CPU] Very slow compile? If you want to file a bug, run with "
    "envvar XLA_FLAGS=--xla_dump_to=/tmp/foo and attach the results.\n"
    "********************************\n"
    "E1126 13:39:31.596044    8583 slow_operation_alarm.cc:140] The operation took 14m15s\n"
    "\n"
    "********************************\n"
    "[Compiling module jit_one for CPU] Very slow compile? If you want to file a bug, run with "
    "envvar XLA_FLAGS=--xla_dump_to=/tmp/foo and attach the results.\n"
    "********************************\n"
)
FOLDING = (
    "E1126 10:00:00.000000    1 slow_operation_alarm.cc:65] Constant folding an instruction "
    "is taking > 1s:\n\n  %reduce.8 = f32[10]{0} reduce(...)\n\nThis isn't necessarily a bug; "
    "constant-folding is inherently a trade-off.\n\nIf you'd like to file a bug, run with envvar "
    "XLA_FLAGS=--xla_dump_to=/tmp/foo and attach the results.\n"
)


def _through_filter(chunks: list[str], env: dict | None = None) -> str:
    code = (
        "import os, sys\n"
        "from lantern_jax.commands.alarms import AlarmFilter\n"
        f"chunks = {chunks!r}\n"
        "with AlarmFilter() as f:\n"
        "    for c in chunks:\n"
        "        os.write(2, c.encode())\n"
        "    print('python warning line', file=sys.stderr)\n"
        "print('after', file=sys.stderr)\n"
    )
    import os

    run_env = dict(os.environ, **(env or {}))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60,
                          env=run_env, check=True)  # fmt: skip
    return done.stderr.decode()  # bytes as written: no newline translation of "\r"


def test_alarm_blocks_are_dropped_and_the_rest_passes():
    err = _through_filter(["before\n", ALARM_BLOCK, "between\n", FOLDING, "W1126 kept\n"])
    assert err == "before\nbetween\nW1126 kept\npython warning line\nafter\n"


def test_blocks_split_across_writes_are_still_dropped():
    text = "a\n" + ALARM_BLOCK + "b\n"
    err = _through_filter([text[i : i + 7] for i in range(0, len(text), 7)])
    assert err.startswith("a\nb\n")


def test_progress_updates_pass_unchanged():
    chunks = ["\rbar 1/3", "\rbar 2/3", "\rbar 3/3", "\n", "Error without a newline"]
    err = _through_filter(chunks)
    assert err.startswith("\rbar 1/3\rbar 2/3\rbar 3/3\nError without a newline")


def test_an_unterminated_alarm_drops_at_most_a_bounded_block():
    lines = "E1126 1 slow_operation_alarm.cc:1] x\n" + "".join(f"l{i}\n" for i in range(60))
    err = _through_filter([lines])
    assert "l39\n" not in err and "l40\n" in err and "l59\n" in err


def test_the_filter_can_be_turned_off():
    err = _through_filter([ALARM_BLOCK], env={"LANTERN_JAX_SHOW_XLA_ALARMS": "1"})
    assert "Very slow compile?" in err
