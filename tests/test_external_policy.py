"""A user's policy named by its code (``file.py:NAME``, ``package.module:attr``): loaded,
registered under its own name, evaluated from the command line, and its source hash recorded
in the result's manifest; every way of naming it wrongly is refused with the spec in the
message."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
from pathlib import Path

import pandas as pd
import pytest

from lantern_jax.cli import main
from lantern_jax.policies.base import Policy
from lantern_jax.policies.external import is_policy_source, load_policy_source
from lantern_jax.policies.registry import get_policy, policy_source, register_policy_source

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "examples" / "my_policy.py"

#: A user's file: a constant-speed policy (straight waypoints at 5 m/s) and a factory of it.
USER_FILE = """
import jax.numpy as jnp
from lantern_jax.policies.base import Policy

def act(params, obs):
    k = jnp.arange(1, 11, dtype=jnp.float32) * 0.25
    return jnp.stack([k * params, jnp.zeros_like(k)], axis=-1)

SLOW = Policy("{name}", lambda key: jnp.float32(5.0), act, "straight ahead at 5 m/s")

def make():
    return SLOW

NOT_A_POLICY = 3
"""


def _write(folder: Path, name: str) -> Path:
    path = folder / "user_policy.py"
    path.write_text(USER_FILE.format(name=name))
    return path


def test_what_counts_as_a_source():
    assert is_policy_source("my.py:POLICY") and is_policy_source("pkg.mod:attr")
    assert is_policy_source("dir/with-dash/file.py:make")
    assert not is_policy_source("coop") and not is_policy_source("learned-coop")
    assert not is_policy_source("a:b:c") and not is_policy_source("not a module:x")


def test_a_file_a_factory_and_a_module_load(tmp_path):
    path = _write(tmp_path, "user-slow")
    policy, source = load_policy_source(f"{path}:SLOW")
    assert isinstance(policy, Policy) and policy.name == "user-slow"
    assert source["kind"] == "file" and source["source_path"] == str(path.resolve())
    assert source["file"] == "user_policy.py" and source["source_spec"] == f"{path}:SLOW"
    assert source["source_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    made, _ = load_policy_source(f"{path}:make")
    assert made is policy  # the same module: the file is imported once per content
    mod, msource = load_policy_source("lantern_jax.policies.reference:coop_policy")
    assert mod.name == "coop" and msource["kind"] == "module"
    assert msource["file"] == "reference.py" and len(msource["source_sha256"]) == 64


@pytest.mark.parametrize(
    ("attr", "error", "says"),
    [
        ("MISSING", ValueError, "defines no 'MISSING'"),
        ("NOT_A_POLICY", TypeError, "expected a Policy"),
        ("act", TypeError, "act is a function of (params, obs); NAME must be a Policy"),
    ],
)
def test_a_bad_attribute_is_named(tmp_path, attr, error, says):
    path = _write(tmp_path, "user-bad")
    with pytest.raises(error, match=says.replace("(", r"\(").replace(")", r"\)")):
        load_policy_source(f"{path}:{attr}")


def test_a_missing_file_or_module_is_named(tmp_path):
    with pytest.raises(ValueError, match="no file"):
        load_policy_source(f"{tmp_path / 'absent.py'}:POLICY")
    with pytest.raises(ValueError, match="importing module 'no_such_module_here' failed"):
        load_policy_source("no_such_module_here:POLICY")
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('boom')\n")
    with pytest.raises(ValueError, match="RuntimeError: boom"):
        load_policy_source(f"{broken}:POLICY")


def test_registration_keeps_one_policy_per_name(tmp_path):
    path = _write(tmp_path, "user-registered")
    assert register_policy_source(f"{path}:SLOW") == "user-registered"
    assert register_policy_source(f"{path}:SLOW") == "user-registered"  # the same code again
    assert get_policy("user-registered").name == "user-registered"
    assert policy_source("user-registered")["source_path"] == str(path.resolve())
    assert policy_source("coop") is None
    with pytest.raises(ValueError, match="already registered"):
        register_policy_source("lantern_jax.policies.reference:coop_policy")  # a built-in name
    other = tmp_path / "other"
    other.mkdir()
    with pytest.raises(ValueError, match="already registered"):  # same name, other code
        register_policy_source(f"{_write(other, 'user-registered')}:SLOW")


def test_the_command_line_refuses_a_bad_source(tmp_path, capsys):
    rc = main(["evaluate", "--policy", f"{tmp_path / 'absent.py'}:POLICY", "--pairs-per-family",
               "1", "--out", str(tmp_path / "r"), "--quiet"])  # fmt: skip
    assert rc == 2
    err = capsys.readouterr().err
    assert "--policy" in err and "absent.py" in err and "no file" in err


def test_the_template_evaluates_from_the_command_line_with_its_source_hash(tmp_path, capsys):
    """The documented template, named by its file, runs on two pairs; its rows carry its name
    and the manifest its file's SHA-256."""
    out = tmp_path / "res"
    rc = main(["evaluate", "--policy", f"{TEMPLATE}:POLICY", "--pairs", "pe_0001,vc_0001",
               "--out", str(out), "--quiet"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    route = pd.read_csv(out / "route_level_results.csv")
    assert set(route["model"]) == {"cautious-when-warned"}
    assert sorted(set(route["pair_id"])) == ["pe_0001", "vc_0001"] and len(route) == 4
    manifest = json.loads((out / "reproducibility_manifest.json").read_text())
    (entry,) = manifest["policies"]
    assert entry["name"] == "cautious-when-warned"
    assert entry["source"]["source_sha256"] == hashlib.sha256(TEMPLATE.read_bytes()).hexdigest()
    assert entry["source"]["file"] == "my_policy.py" and "source_path" not in entry["source"]
    record = json.loads((out / "run_record.json").read_text())
    assert f"{TEMPLATE}:POLICY" in json.dumps(record)  # where it lay: the run's own record


def test_a_policy_file_without_its_name_lists_the_policies_it_defines(tmp_path):
    """``--policy mine.py`` (no ``:NAME``) says how a file is given and names its Policy
    objects, instead of "unknown policy"."""
    from lantern_jax import cli

    path = _write(tmp_path, "user-listed")
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = cli.main(["evaluate", "--policy", str(path), "--pairs", "pe_0001", "--out",
                       str(tmp_path / "r")])  # fmt: skip
    assert rc == 2
    assert f"a policy file is given as {path}:NAME" in err.getvalue()
    assert "it defines" in err.getvalue() and "SLOW" in err.getvalue()


def test_a_trace_error_in_a_users_act_names_its_line_and_suggests_jnp_where(tmp_path):
    """A Python ``if`` on an array inside ``act``: the PolicyError names the user's file and
    line and hints at ``jnp.where``."""
    import lantern_jax as lj
    from lantern_jax.apps.evaluation import PolicyError

    path = tmp_path / "iffy.py"
    path.write_text(
        "import jax.numpy as jnp\n"
        "import lantern_jax as lj\n"
        "def act(params, obs):\n"
        "    if obs.ego_speed > 3.0:\n"
        "        return jnp.zeros((10, 2))\n"
        "    return jnp.ones((10, 2))\n"
        "POLICY = lj.Policy('iffy', init=lambda key: None, act=act)\n"
    )
    policy, _ = load_policy_source(f"{path}:POLICY")
    with pytest.raises(PolicyError) as info:
        lj.evaluate([policy], suite=lj.load_suite().select(["pe_0001"]), progress=False)
    text = str(info.value)
    assert "TracerBoolConversionError" in text and "iffy.py:4" in text
    assert "jnp.where" in text
