"""JAX's set-up for the Python API (:mod:`lantern_jax.core.jax_setup`): ``import lantern_jax``
before JAX gives one XLA CPU device per core and the persistent compilation cache, as the command
line has them; it can be turned off; JAX imported first keeps its own device count (and
:func:`lantern_jax.setup` says why) but still gets the cache, unless the process decided its
own; a bad device count is a warning naming the variable.

Each case runs in a fresh Python process (the set-up is only possible before JAX starts).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from lantern_jax.core.jax_setup import (
    XLA_CACHES_CPU,
    XLA_CACHES_ENV,
    SetupError,
    cpu_device_request,
)

PROBE = """
import json, os, sys, warnings
warnings.simplefilter("always")
{first}
import jax
out = {{"devices": jax.device_count(), "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "cache": jax.config.jax_compilation_cache_dir,
        "cache_on": bool(jax.config.jax_enable_compilation_cache),
        "xla_caches": jax.config.jax_persistent_cache_enable_xla_caches}}
{after}
print(json.dumps(out))
"""


def _probe(tmp_path, first: str, after: str = "", **env: str) -> dict:
    base = {k: v for k, v in os.environ.items()
            if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR", "LANTERN_JAX_CACHE_DIR",
                         "LANTERN_JAX_CPU_DEVICES", "LANTERN_JAX_AUTO_SETUP",
                         XLA_CACHES_ENV)}  # fmt: skip
    base.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), JAX_PLATFORMS="cpu", **env)
    code = PROBE.format(first=first, after=after)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=base, timeout=120, check=True)  # fmt: skip
    out = json.loads(done.stdout.strip().splitlines()[-1])
    out["stderr"] = done.stderr
    return out


def test_import_before_jax_gives_cores_and_cache(tmp_path):
    out = _probe(tmp_path, "import lantern_jax", LANTERN_JAX_CPU_DEVICES="3")
    assert out["devices"] == 3
    assert out["cache"] == str(tmp_path / "xdg" / "lantern-jax" / "jax")
    assert out["cache_on"]


def test_auto_setup_can_be_turned_off(tmp_path):
    out = _probe(tmp_path, "import lantern_jax", LANTERN_JAX_AUTO_SETUP="0",
                 LANTERN_JAX_CPU_DEVICES="3")  # fmt: skip
    assert out["devices"] == 1
    assert "device_count" not in out["xla_flags"]
    assert out["cache"] is None


def test_xla_flags_given_by_the_user_win(tmp_path):
    out = _probe(tmp_path, "import lantern_jax", LANTERN_JAX_CPU_DEVICES="3",
                 XLA_FLAGS="--xla_force_host_platform_device_count=2")  # fmt: skip
    assert out["devices"] == 2


def test_jax_first_keeps_one_device_and_setup_says_why(tmp_path):
    after = "r = __import__('lantern_jax').setup(); out['note'] = r.cpu_devices_note; " \
            "out['cache_after'] = r.compile_cache"  # fmt: skip
    out = _probe(tmp_path, "import jax", after, LANTERN_JAX_CPU_DEVICES="3")
    assert out["devices"] == 1
    assert "JAX was imported before lantern_jax" in out["note"]
    assert out["cache_after"] == str(tmp_path / "xdg" / "lantern-jax" / "jax")


def test_jax_first_still_gets_the_cache_at_import(tmp_path):
    """``import jax`` before ``lantern_jax`` (as most scripts begin): the device count stays,
    the compilation cache is turned on all the same."""
    out = _probe(tmp_path, "import jax; import lantern_jax", LANTERN_JAX_CPU_DEVICES="3")
    assert out["devices"] == 1
    assert out["cache"] == str(tmp_path / "xdg" / "lantern-jax" / "jax")
    assert out["cache_on"] and out["xla_caches"] == XLA_CACHES_CPU


@pytest.mark.parametrize(
    "mine, cache, on",
    [
        ("jax.config.update('jax_compilation_cache_dir', {mine!r})", "mine", True),
        ("jax.config.update('jax_enable_compilation_cache', False)", None, False),
    ],
    ids=["own-folder", "turned-off"],
)
def test_jax_first_keeps_the_processes_own_cache_decision(tmp_path, mine, cache, on):
    folder = str(tmp_path / "mine")
    first = f"import jax; {mine.format(mine=folder)}; import lantern_jax"
    out = _probe(tmp_path, first)
    assert out["cache"] == (folder if cache else None)
    assert out["cache_on"] is on


def test_jax_first_with_auto_setup_off_leaves_the_cache_off(tmp_path):
    out = _probe(tmp_path, "import jax; import lantern_jax", LANTERN_JAX_AUTO_SETUP="0")
    assert out["cache"] is None


@pytest.mark.parametrize("first", ["import lantern_jax", "import jax; import lantern_jax"],
                         ids=["lantern-first", "jax-first"])  # fmt: skip
def test_a_cache_folder_that_cannot_be_used_is_one_warning_and_the_cache_stays_off(
    tmp_path, first
):
    """A file where the folder should be: no cache (nothing would be kept; every compile would
    fail to write), one warning on first use naming the folder and the variable."""
    (tmp_path / "a-file").write_text("")
    folder = tmp_path / "a-file" / "cache"
    out = _probe(tmp_path, f"{first}; lantern_jax.load_suite",
                 LANTERN_JAX_CACHE_DIR=str(folder))  # fmt: skip
    assert out["cache"] is None
    warned = [line for line in out["stderr"].splitlines() if "UserWarning" in line]
    assert len(warned) == 1, out["stderr"]
    assert str(folder) in warned[0] and "is not a folder" in warned[0]
    assert "LANTERN_JAX_CACHE_DIR" in warned[0]


def test_the_command_line_says_so_in_one_line(tmp_path):
    (tmp_path / "a-file").write_text("")
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env.update(LANTERN_JAX_CACHE_DIR=str(tmp_path / "a-file" / "cache"), JAX_PLATFORMS="cpu")
    done = subprocess.run([sys.executable, "-m", "lantern_jax", "evaluate", "--pairs", "nope"],
                          capture_output=True, text=True, env=env, timeout=120)  # fmt: skip
    assert done.returncode == 2  # the bad pair id, after the set-up
    lines = [line for line in done.stderr.splitlines() if "cache" in line]
    assert len(lines) == 1 and lines[0].startswith("lantern-jax: warning: "), done.stderr
    assert "LANTERN_JAX_CACHE_DIR" in lines[0] and "Warning" not in done.stderr


@pytest.mark.parametrize("make, problem", [
    (lambda p: p, None),
    (lambda p: p / "new" / "deeper", None),
    (lambda p: (p / "f").write_text("") or p / "f", "is not a folder"),
    (lambda p: (p / "f").write_text("") or p / "f" / "x" / "y", "is not a folder"),
], ids=["folder", "to-be-made", "a-file", "below-a-file"])  # fmt: skip
def test_cache_dir_problem(tmp_path, make, problem):
    from lantern_jax.core.jax_setup import cache_dir_problem

    found = cache_dir_problem(str(make(tmp_path)))
    assert found is None if problem is None else problem in found


#: ``import jax`` first and a compile before ``lantern_jax`` is imported; then one program
#: compiled; prints how many compilations JAX's persistent cache served.
JAX_FIRST = """
import jax, jax.numpy as jnp
from jax import monitoring
hits = []
monitoring.register_event_listener(
    lambda e, **k: hits.append(e) if e == "/jax/compilation_cache/cache_hits" else None)
jax.jit(lambda x: x + 1.0)(jnp.float32(1.0)).block_until_ready()
import lantern_jax
print(float(jax.jit(lambda x: jnp.cos(x) * 5.0 - x)(jnp.float32(0.25))), len(hits))
"""


def test_jax_first_a_second_process_is_served_by_the_cache(tmp_path):
    """The cache turned on after JAX's first compile still serves the next process."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "LANTERN_JAX_CACHE_DIR",
                        "LANTERN_JAX_AUTO_SETUP", XLA_CACHES_ENV)}  # fmt: skip
    env.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), JAX_PLATFORMS="cpu")

    def run():
        out = subprocess.run([sys.executable, "-c", JAX_FIRST], capture_output=True, text=True,
                             env=env, timeout=120, check=True)  # fmt: skip
        value, hits = out.stdout.split()
        return value, int(hits)

    first, again = run(), run()
    assert first[1] == 0 and again[1] >= 1 and again[0] == first[0]
    assert (tmp_path / "xdg" / "lantern-jax" / "jax").is_dir()


def test_bad_device_count_warns_on_first_use(tmp_path):
    out = _probe(tmp_path, "import lantern_jax; lantern_jax.load_suite",
                 LANTERN_JAX_CPU_DEVICES="two")  # fmt: skip
    assert out["devices"] == 1
    assert "LANTERN_JAX_CPU_DEVICES" in out["stderr"] and "'two'" in out["stderr"]


@pytest.mark.parametrize("value", ["0", "-1", "1.5", "two", ""])
def test_bad_device_count_is_refused_by_name(monkeypatch, value):
    monkeypatch.setenv("LANTERN_JAX_CPU_DEVICES", value)
    with pytest.raises(SetupError, match="LANTERN_JAX_CPU_DEVICES"):
        cpu_device_request()


#: Compiles one small program with the persistent cache in ``sys.argv[1]`` and prints how many
#: of its compilations JAX's persistent cache served.
CACHED = """
import sys
import lantern_jax
import jax, jax.numpy as jnp
from jax import monitoring
hits = []
monitoring.register_event_listener(
    lambda e, **k: hits.append(e) if e == "/jax/compilation_cache/cache_hits" else None)
jax.config.update("jax_compilation_cache_dir", sys.argv[1])
print(float(jax.jit(lambda x: jnp.sin(x) * 3.0 + x)(jnp.float32(0.5))), len(hits))
"""


def test_a_cache_folder_moved_elsewhere_still_serves_its_programs(tmp_path):
    """On a CPU-only install the cache folder's path is not part of a program's key (JAX's GPU
    autotuning cache, which puts it there, is off): a folder copied to another path serves the
    programs compiled into the first."""
    import shutil

    env = {k: v for k, v in os.environ.items() if k != XLA_CACHES_ENV}
    env.update(JAX_PLATFORMS="cpu", JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")

    def run(folder):
        out = subprocess.run([sys.executable, "-c", CACHED, str(folder)], capture_output=True,
                             text=True, env=env, timeout=120, check=True)  # fmt: skip
        value, hits = out.stdout.split()
        return value, int(hits)

    first = run(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    again = run(tmp_path / "b")
    assert first[1] == 0 and again[1] >= 1 and again[0] == first[0]


def test_the_xla_caches_are_off_on_the_cpu_unless_set(tmp_path):
    out = _probe(tmp_path, "import lantern_jax")
    assert out["xla_caches"] == XLA_CACHES_CPU
    mine = _probe(tmp_path, "import lantern_jax", **{XLA_CACHES_ENV: "all"})
    assert mine["xla_caches"] == "all"


def test_the_test_session_sets_what_the_package_sets():
    """``tests/conftest.py`` sets the XLA caches itself (it imports JAX before the package)."""
    from conftest import TEST_XLA_CACHES

    assert TEST_XLA_CACHES == XLA_CACHES_CPU == os.environ[XLA_CACHES_ENV]


def test_ci_builds_the_documentation_on_the_tests_device_count():
    """``.ci/run`` builds the site (its notebooks executed) after the README's test command, in
    the same cache folder.  The build's process imports the package, which would give its
    notebook kernels one CPU device per core; the tests run on one (JAX is imported before the
    package), and a program for two devices is another program: ``.ci/run`` gives the build one
    device (unless ``LANTERN_JAX_CPU_DEVICES`` says otherwise), so the kernels load what the
    tests compiled."""
    from pathlib import Path

    import jax

    assert jax.local_device_count() == 1
    ci = (Path(__file__).resolve().parents[1] / ".ci" / "run").read_text()
    build = ci[: ci.index("-m sphinx")].rsplit("mkdir -p docs/_build", 1)[1]  # the command
    assert 'LANTERN_JAX_CPU_DEVICES="${LANTERN_JAX_CPU_DEVICES:-1}"' in build


def test_the_processes_the_tests_start_run_on_the_tests_device_count():
    """A command-line or script process a test starts imports the package first, which gives
    it one CPU device per core unless told otherwise; ``tests/conftest.py`` exports one device,
    the test session's own, so such a process compiles (or loads) the programs the in-process
    tests keep in the shared cache, not two-device ones."""
    import jax
    from conftest import TEST_CPU_DEVICES

    if os.environ["LANTERN_JAX_CPU_DEVICES"] != TEST_CPU_DEVICES:
        pytest.skip("LANTERN_JAX_CPU_DEVICES was set before the tests started")
    code = "import lantern_jax, jax; print(jax.device_count())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)  # fmt: skip
    assert int(done.stdout.strip().splitlines()[-1]) == jax.local_device_count() == 1


def test_a_program_that_captures_a_large_constant_is_flagged():
    """The test session's limit on the constants one program captures (``tests/conftest.py``):
    an array past it, closed over by a jitted function, draws JAX's warning (which fails any
    other test, pyproject.toml); one within it does not."""
    import warnings

    import jax
    import jax.numpy as jnp
    from conftest import CAPTURED_CONSTANTS_LIMIT_BYTES

    assert jax.config.jax_captured_constants_warn_bytes == CAPTURED_CONSTANTS_LIMIT_BYTES
    big = jnp.ones(CAPTURED_CONSTANTS_LIMIT_BYTES // 4 + 1, jnp.float32)
    with pytest.warns(UserWarning, match="constants were captured"):
        jax.jit(lambda x: x + big.sum()).lower(1.0)
    small = jnp.ones(CAPTURED_CONSTANTS_LIMIT_BYTES // 8, jnp.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jax.jit(lambda x: x + small.sum()).lower(1.0)
