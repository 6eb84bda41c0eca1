"""JAX's set-up for the Python API (:mod:`lantern_jax.core.jax_setup`): ``import lantern_jax``
before JAX gives one XLA CPU device per core and the persistent compilation cache, as the command
line has them; it can be turned off; JAX imported first keeps its own device count and
:func:`lantern_jax.setup` says why; a bad device count is a warning naming the variable.

Each case runs in a fresh Python process (the set-up is only possible before JAX starts).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from lantern_jax.core.jax_setup import SetupError, cpu_device_request

PROBE = """
import json, os, sys, warnings
warnings.simplefilter("always")
{first}
import jax
out = {{"devices": jax.device_count(), "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "cache": jax.config.jax_compilation_cache_dir,
        "cache_on": bool(jax.config.jax_enable_compilation_cache)}}
{after}
print(json.dumps(out))
"""


def _probe(tmp_path, first: str, after: str = "", **env: str) -> dict:
    base = {k: v for k, v in os.environ.items()
            if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR", "LANTERN_JAX_CACHE_DIR",
                         "LANTERN_JAX_CPU_DEVICES", "LANTERN_JAX_AUTO_SETUP")}  # fmt: skip
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
