"""The allocator setting of the training entry points (:mod:`lantern_jax.core.allocator`): what it
changes (the pages a repeated XLA execution touches afresh), what it must not (the bits a
program computes), and who wins when the environment already decides."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

from lantern_jax.core import allocator

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

#: A process that runs one jitted program repeatedly, first as glibc leaves it, then after
#: keep_freed_memory(), dropping each result: a 42.3 MB block per call (its output), past
#: glibc's 32 MB mmap ceiling and within a thread heap's 64 MB, as a training step's temporary
#: buffer is.  Prints the minor page faults of each of a phase's last ten calls and the last
#: result's bytes in hex.
PROBE = r"""
import hashlib, json, resource, sys
import jax, jax.numpy as jnp
from lantern_jax.core.allocator import keep_freed_memory

@jax.jit
def f(a, b):
    return jnp.tanh(a @ b)       # (2300, 4600) float32: 42.3 MB, from a thin product

a = jax.random.normal(jax.random.key(0), (2300, 128), jnp.float32)
b = jax.random.normal(jax.random.key(1), (128, 4600), jnp.float32)
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
def phase():
    for _ in range(8):  # most XLA threads that run it have allocated once
        out = f(a, b).block_until_ready()
    per_call = []
    for _ in range(10):
        before = faults()
        out = f(a, b).block_until_ready()
        per_call.append(faults() - before)
    return per_call, hashlib.sha256(jax.device_get(out).tobytes()).hexdigest()

faults_system, bits_system = phase()
outcome = keep_freed_memory()
faults_kept, bits_kept = phase()
print(json.dumps(dict(outcome=outcome, faults_system=faults_system, faults_kept=faults_kept,
                      bits_system=bits_system, bits_kept=bits_kept)))
"""


def _run(code: str, **env: str) -> dict:
    mine = (allocator.MALLOC_ENV, "GLIBC_TUNABLES", *allocator.GLIBC_VARIABLES)
    base = {k: v for k, v in os.environ.items() if k not in mine}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, check=True,
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not GLIBC, reason="the setting is glibc's; elsewhere it does nothing")
def test_freed_memory_is_reused_and_the_bits_are_the_same():
    r = _run(PROBE)
    assert r["outcome"] == "kept"
    assert r["bits_kept"] == r["bits_system"]
    # glibc's default maps the block afresh on every call: 42.3 MB of new pages, about 10,300
    # faults of 4 KiB each.  Kept, a call reuses the pages of the calls before it.  The thread
    # of XLA's pool that runs a call is the pool's choice, and one that has not run the program
    # yet still faults once (a CI run saw three such calls of six on a busy 2-core machine), so
    # the test counts calls: every call faults afresh as the system leaves it, and most calls
    # reuse their pages once kept.
    fresh = 8_000  # faults of a call that writes most of the 42.3 MB block to new pages
    assert all(n > fresh for n in r["faults_system"]), r["faults_system"]
    reused = [n for n in r["faults_kept"] if n < fresh // 8]
    assert len(reused) >= len(r["faults_kept"]) // 2, r["faults_kept"]


def test_the_choice_is_read_and_a_bad_one_names_the_variable(monkeypatch):
    monkeypatch.delenv(allocator.MALLOC_ENV, raising=False)
    assert allocator.malloc_choice() == "keep"
    monkeypatch.setenv(allocator.MALLOC_ENV, " System ")
    assert allocator.malloc_choice() == "system"
    monkeypatch.setenv(allocator.MALLOC_ENV, "jemalloc")
    with pytest.raises(allocator.AllocatorError, match=r"LANTERN_JAX_MALLOC='jemalloc'.*keep"):
        allocator.malloc_choice()


WHO = r"""
import json
from lantern_jax.core.allocator import keep_freed_memory
first = keep_freed_memory()
print(json.dumps(dict(outcome=first, again=keep_freed_memory())))
"""


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, "kept" if GLIBC else "left to the system (not glibc)"),
        ({allocator.MALLOC_ENV: "system"}, "left to the system (LANTERN_JAX_MALLOC=system)"),
        ({"MALLOC_TRIM_THRESHOLD_": "131072"}, "left as MALLOC_TRIM_THRESHOLD_ sets it"),
        ({"GLIBC_TUNABLES": "glibc.malloc.top_pad=0"}, "left as GLIBC_TUNABLES sets it"),
    ],
)
def test_the_environment_decides_first_and_the_setting_is_made_once(env, expected):
    r = _run(WHO, **env)
    assert r == dict(outcome=expected, again=expected)


def test_the_train_command_refuses_a_bad_choice_before_any_work(tmp_path, monkeypatch, capsys):
    from lantern_jax.cli import main

    monkeypatch.setenv(allocator.MALLOC_ENV, "fast")
    config = tmp_path / "train.toml"
    config.write_text('[train]\nname = "m"\nrecipe = "base"\ndataset = "nowhere"\n')
    rc = main(["train", "--config", str(config), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "LANTERN_JAX_MALLOC='fast'" in err
    assert not (tmp_path / "run").exists()
