"""A catalogue of bad inputs and faults: each gets a clear error naming what is wrong, or a
defined outcome, never a silent wrong result, a raw traceback or a mixed set of files.

Catalogue (87 bad inputs and faults):

* suite files (41: 39 in ``SUITE_CASES``, a duplicated JSON key, broken JSON): family and
  weather labels that disagree with the parameters; a 4e-7 change and a larger one under the
  old hash; out-of-range, negative, missing, string, boolean, unknown, NaN, inf and infeasible
  parameters (hashes recomputed); occluder and road-geometry fields missing, NaN, infinite or
  placing a parked truck in the route corridor; a recorded route with a NaN point or of the
  wrong type; wrong JSON types of pair id, seed (null, ``"abc"``), pair hash, report, suite id,
  pairs and params; a parameter seed ``"abc"``; unknown family (label and parameters);
  duplicate pair ids and scenarios; missing and unknown fields; no pairs; a wrong suite hash;
  an unsupported format version — each refused by ``load_suite`` with a line naming file, pair
  and field, and by the CLI with exit code 2 before anything is built;
* suite selections (4): ``select([])``, an id twice, ``subset(0)``, a missing file;
* result sets (10): ``kill -9`` at five points of a write (into a fresh folder; with every file
  staged; between the exchange and moving the folder's other entries back; between the two
  renames of the fallback; at three random moments) leaves the old or the new complete set and
  the next write cleans up and keeps the other entries; a leftover ``*.tmp`` and a stale
  staging folder are cleaned (a live process's is kept); a route table failing its schema
  leaves the old set; a suite manifest onto a folder (API: clear error, no temp file; CLI:
  exit 2 before generating);
* ``--out`` (5): a file, under a file, unwritable, empty — exit 2 before the evaluation; a
  symbolic link is followed;
* configs and flags (17): keys beside ``[evaluate]``, keys without it, another table, an
  unknown key, a nested table, ``pairs = []``, ``policy = []``, ``policy = ""``, an empty file,
  ``--pol``, ``--pairs-per``, ``--abl``, ``--pairs ""``, ``--pairs ","``, ``--policy ""``, a
  pair given twice — exit 2; explicit flags (even with their default value) win over the file;
* Python API (5): ``evaluate([])``, ``evaluate(["ego", "ego"])``, a policy object beside its
  name, an empty ``Suite`` — ``ValueError`` before anything is built; ``select`` of one str;
* interrupts and policy errors (5): SIGINT during compile exits 130 (it used to segfault) and
  leaves nothing; a policy raising while traced and one raising inside the rollout, each
  through the API (``PolicyError``) and the CLI (exit 1), the error naming the policy.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import json
import math
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import time
import types
from pathlib import Path

import jax
import pandas as pd
import pytest

import lantern_jax.evaluate as ev
from lantern_jax import cli
from lantern_jax.policies import registry as policy_registry
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.report import OUTPUT_FILES, write_outputs
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import (
    PairSpec,
    SuiteError,
    load_suite,
    suite_hash,
    write_manifest,
)
from lantern_jax.scoring.aggregate import decomposition_table
from lantern_jax.scoring.table import schema_columns

PAIRS = ["pe_0001", "lww_0001"]
ROOT = Path(__file__).resolve().parents[1]


def run_cli(argv: list[str]) -> types.SimpleNamespace:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(argv)
    return types.SimpleNamespace(rc=rc, out=out.getvalue(), err=err.getvalue())


@pytest.fixture
def no_evaluation(monkeypatch):
    """Fail the test if the CLI gets as far as building or evaluating anything."""

    def refuse(*a, **k):
        raise AssertionError("the evaluation started although the input was invalid")

    monkeypatch.setattr(ev, "evaluate", refuse)
    monkeypatch.setattr(ev, "build_executions", refuse)


# ---------------------------------------------------------------------------------------------
# suite files
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def base_manifest() -> dict:
    return cli.suite_to_manifest(load_suite().select(PAIRS), "two-pairs")


def rehash(m: dict) -> dict:
    """Recompute every pair hash that can be computed, then the suite hash (a careful forger)."""
    for p in m.get("pairs", []):
        with contextlib.suppress(Exception):
            p["sha256"] = content_hash(p["params"])
    with contextlib.suppress(Exception):
        specs = [PairSpec(p["pair_id"], p["family"], p["weather"], p["params"], p["sha256"])
                 for p in m["pairs"]]  # fmt: skip
        m["suite_sha256"] = suite_hash(specs)
    return m


def _pe(m):
    return m["pairs"][0]


def _set(path, value):
    """A mutation that sets ``m[path...] = value`` (path of keys/indices)."""

    def f(m):
        obj = m
        for k in path[:-1]:
            obj = obj[k]
        obj[path[-1]] = value

    return f


def _del(path):
    def f(m):
        obj = m
        for k in path[:-1]:
            obj = obj[k]
        del obj[path[-1]]

    return f


def _nudge(m):
    _pe(m)["params"]["v_ref"] += 4e-7


def _swap(m):
    m["pairs"].reverse()


def _dup_id(m):
    m["pairs"][1]["pair_id"] = "pe_0001"  # the LWW pair takes the PE pair's id


def _dup_scenario(m):
    m["pairs"].append(dict(copy.deepcopy(m["pairs"][0]), pair_id="pe_0099"))


def _infeasible(m):  # in range, but the route ends before the recovery stretch
    _pe(m)["params"].update(conflict_s=48.0, route_length=68.0)


def _truck_in_corridor(m):  # every field in range, but the widest truck in the narrowest
    # parking lane beside the narrowest lane reaches within 1.0 m of the route (needs 1.56)
    _pe(m)["params"].update(lane_width=3.0, parking_width=2.2, truck_width=2.6)


P = ("pairs", 0, "params")
SUITE_CASES = [
    # (id, mutation, recompute hashes?, expected message after "suite <file>: ")
    ("family-label", _set(("pairs", 1, "family"), "PE"), True,
     r"pair lww_0001: family: label 'PE' disagrees with params.family 'LWW'"),
    ("weather-label", _set(("pairs", 0, "weather"), "dusk"), True,
     r"pair pe_0001: weather: label 'dusk' disagrees with params.weather 'clear_day'"),
    ("4e-7-change", _nudge, False, r"pair pe_0001: sha256: does not match its parameters"),
    ("tampered", _set((*P, "v_ref"), 9.0), False, r"pair pe_0001: sha256: does not match"),
    ("out-of-range", _set((*P, "route_length"), 150.0), True,
     r"pair pe_0001: PE.route_length: 150.0 outside \[68, 135\]"),
    ("negative", _set((*P, "conflict_s"), -5.0), True,
     r"pair pe_0001: PE.conflict_s: -5.0 outside \[33, 48\]"),
    ("missing-param", _del((*P, "v_ref")), True, r"pair pe_0001: PE.v_ref: missing"),
    ("string-param", _set((*P, "v_ref"), "9"), True,
     r"pair pe_0001: PE.v_ref: expected a number, got '9'"),
    ("bool-param", _set((*P, "v_ref"), True), True,
     r"pair pe_0001: PE.v_ref: expected a number, got True"),
    ("unknown-param", _set((*P, "v_max"), 3.0), True,
     r"pair pe_0001: PE.v_max: unknown parameter \(known: seed, "),
    ("nan-param", _set((*P, "v_ref"), math.nan), True,
     r"pair pe_0001: PE.v_ref: nan outside \[8, 10\]"),
    ("inf-param", _set((*P, "route_length"), math.inf), True,
     r"pair pe_0001: PE.route_length: inf outside \[68, 135\]"),
    ("infeasible", _infeasible, True, r"pair pe_0001: PE.route_length: 68.0 too short"),
    ("occluder-in-corridor", _truck_in_corridor, True,
     r"pair pe_0001: PE.truck_width: occluder truck overlaps the route corridor"),
    ("occluder-missing", _del((*P, "truck_length")), True,
     r"pair pe_0001: PE.truck_length: missing"),
    ("occluder-nan", _set((*P, "truck_width"), math.nan), True,
     r"pair pe_0001: PE.truck_width: nan outside \[2.2, 2.6\]"),
    ("geometry-missing", _del((*P, "lane_width")), True, r"pair pe_0001: PE.lane_width: missing"),
    ("geometry-inf", _set((*P, "curvature_1"), math.inf), True,
     r"pair pe_0001: PE.curvature_1: inf outside"),
    ("junction-nan", _set(("pairs", 1, "params", "kerb_radius"), math.nan), True,
     r"pair lww_0001: LWW.kerb_radius: nan outside \[6.5, 8.5\]"),
    ("route-nan", _set(("pairs", 0, "route_2m", 0), [math.nan, 0.0]), False,
     r"pair pe_0001: route_2m: point 0: expected \[x, y\] with finite numbers"),
    ("route-type", _set(("pairs", 0, "route_2m"), "none"), False,
     r"pair pe_0001: route_2m: expected a JSON array of at least two"),
    ("param-seed-abc", _set((*P, "seed"), "abc"), True,
     r"pair pe_0001: PE.seed: expected an integer, got 'abc'"),
    ("seed-abc", _set(("seed",), "abc"), True,
     r"seed: expected an integer in \[0, 2147483647\], got string 'abc'"),
    ("seed-null", _set(("seed",), None), True, r"seed: expected an integer .*got null None"),
    ("pair-id-int", _set(("pairs", 0, "pair_id"), 7), True,
     r"pairs\[0\]: pair_id: expected a non-empty string .*got int 7"),
    ("hash-int", _set(("pairs", 0, "sha256"), 12), False,
     r"pair pe_0001: sha256: expected a 64-digit lowercase hex string, got int 12"),
    ("report-list", _set(("generation_report",), []), True,
     r"generation_report: expected a JSON object, got array"),
    ("suite-id-int", _set(("suite_id",), 3), True, r"suite_id: expected a non-empty string"),
    ("pairs-object", _set(("pairs",), {}), False, r"pairs: expected a JSON array, got object"),
    ("params-list", _set(("pairs", 0, "params"), []), False,
     r"pair pe_0001: params: expected a JSON object, got array"),
    ("unknown-family", _set(("pairs", 0, "family"), "XX"), True,
     r"pair pe_0001: family: 'XX' not one of \{PE, VC, OR, LWW, RWW, RTY\}"),
    ("unknown-params-family", _set((*P, "family"), "XX"), True,
     r"pair pe_0001: params.family: 'XX' not one of"),
    ("duplicate-id", _dup_id, True, r"pair pe_0001: pair_id: duplicate \(also pairs\[0\]\)"),
    ("duplicate-scenario", _dup_scenario, True,
     r"pair pe_0099: params: same parameters \(content hash\) as pair pe_0001"),
    ("missing-field", _del(("pairs", 0, "weather")), True, r"pair pe_0001: weather: missing"),
    ("unknown-field", _set(("pairs", 0, "note"), "x"), True,
     r"pair pe_0001: note: unknown field"),
    ("empty-pairs", _set(("pairs",), []), True, r"pairs: empty"),
    ("suite-hash", _swap, False, r"suite_sha256: suite hash mismatch"),
    ("format-version", _set(("format_version",), 2), True, r"format_version: 2 not supported"),
]  # fmt: skip


@pytest.mark.parametrize("case", SUITE_CASES, ids=[c[0] for c in SUITE_CASES])
def test_bad_suite_file(case, base_manifest, tmp_path, no_evaluation):
    name, mutate, recompute, expected = case
    m = copy.deepcopy(base_manifest)
    mutate(m)
    if recompute:
        rehash(m)
    path = tmp_path / "my.json"
    path.write_text(json.dumps(m))  # NaN / Infinity written as JSON's extension
    with pytest.raises(SuiteError, match=rf"(^|\n)suite {re.escape(str(path))}: {expected}"):
        load_suite(path)
    res = run_cli(["evaluate", "--suite", str(path), "--out", str(tmp_path / "out")])
    assert res.rc == 2
    assert f"suite {path}: " in res.err and len(res.err.splitlines()) >= 1
    assert not (tmp_path / "out").exists()


def test_duplicate_json_key_and_broken_json(base_manifest, tmp_path, no_evaluation):
    text = json.dumps(base_manifest).replace('"v_ref": ', '"v_ref": 9.5, "v_ref": ', 1)
    path = tmp_path / "dup.json"
    path.write_text(text)
    with pytest.raises(SuiteError, match=r"pair pe_0001: params.v_ref: given more than once"):
        load_suite(path)
    path.write_text(text[:-5])
    with pytest.raises(SuiteError, match=rf"^suite {re.escape(str(path))}: not valid JSON"):
        load_suite(path)
    assert run_cli(["suite", "--suite", str(path)]).rc == 2


def test_every_error_is_collected(base_manifest, tmp_path):
    m = copy.deepcopy(base_manifest)
    m["pairs"][0]["params"]["v_ref"] = 99.0
    m["pairs"][1]["params"]["actor_speed"] = "x"
    path = tmp_path / "two.json"
    path.write_text(json.dumps(rehash(m)))
    with pytest.raises(SuiteError) as e:
        load_suite(path)
    assert [line.split(": ")[1] for line in e.value.errors] == ["pair pe_0001", "pair lww_0001"]


def test_hash_is_exact_and_shipped_hashes_unchanged():
    shipped = load_suite()
    assert shipped.suite_sha256 == (
        "cee6e0dafefda9b089ef86d99e824a3f0497de0a0ed67df25e09e26d20988f06"
    )
    p = dict(shipped.pairs[0].params)
    assert content_hash(p) == shipped.pairs[0].sha256
    q = dict(p, v_ref=p["v_ref"] + 4e-7)
    assert content_hash(q) != content_hash(p)
    assert content_hash(dict(p, rotation_deg=-0.0)) == content_hash(dict(p, rotation_deg=0.0))


@pytest.mark.parametrize(
    "call, error",
    [
        (lambda s: s.select([]), r"no pair ids given"),
        (lambda s: s.select(["pe_0001", "pe_0001"]), r"given more than once: pe_0001"),
        (lambda s: s.subset(0), r"pairs per family must be an integer >= 1, got 0"),
        (lambda s: load_suite("no/such/suite.json"), r"suite file no/such/suite.json not found"),
    ],
    ids=["select-empty", "select-twice", "subset-0", "missing-file"],
)
def test_bad_selection(call, error):
    with pytest.raises((ValueError, FileNotFoundError), match=error):
        call(load_suite())


# ---------------------------------------------------------------------------------------------
# result sets
# ---------------------------------------------------------------------------------------------
def synthetic_result(cus: float) -> ev.EvalResult:
    """An evaluation result of two pairs built from the schema (no rollout): every gate passed,
    every continuous value 0.5, the given CUS."""
    rows = []
    for cond in ev.CONDITIONS:
        for pid, fam in (("pe_0001", "PE"), ("vc_0001", "VC")):
            row = {}
            for col, dtype in schema_columns():
                if dtype == "string":
                    row[col] = dict(
                        model="m", condition=cond, pair_id=pid, family=fam, weather="clear_day"
                    )[col]
                elif dtype == "int64":
                    row[col] = 1 if col.startswith("gate_") else 0
                else:
                    row[col] = {"CUS": cus, "A_progress": 1.0, "B_progress": 1.0}.get(col, 0.5)
            rows.append(row)
    route = pd.DataFrame(rows)
    manifest = dict(suite_id="two-pairs", num_pairs=2, ablation="none", cus=cus)
    return ev.EvalResult(
        route_table=route,
        family_table=ev.family_table(route),
        decomposition=decomposition_table(route).reset_index(),
        manifest=manifest,
        runs=[],
        premise=pd.DataFrame(),
    )


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    """Two complete result sets (old: CUS 10, new: CUS 90) as reference folders."""
    root = tmp_path_factory.mktemp("sets")
    write_outputs(synthetic_result(10.0), root / "old")
    write_outputs(synthetic_result(90.0), root / "new")
    return {k: {n: (root / k / n).read_bytes() for n in OUTPUT_FILES} for k in ("old", "new")}


def result_set(folder: Path, sets: dict) -> str:
    """'old' or 'new' when ``folder`` holds exactly one complete reference set."""
    got = {n: (folder / n).read_bytes() for n in OUTPUT_FILES if (folder / n).is_file()}
    which = [k for k, ref in sets.items() if got == ref]
    assert len(which) == 1, f"{folder} holds a mixed or partial set: {sorted(got)}"
    return which[0]


def leftovers(folder: Path) -> list[str]:
    """Hidden staging / old / probe folders beside ``folder`` and temporary files inside it."""
    beside = [e for e in os.listdir(folder.parent) if e.startswith(f".{folder.name}.")]
    inside = [e for e in os.listdir(folder) if e.endswith(".tmp")] if folder.is_dir() else []
    return beside + inside


KILL_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    from pathlib import Path
    from lantern_jax import files

    point, target, src = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    names = sorted(os.listdir(src))
    die = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
    if point == "staged":
        files.exchange = die
    elif point == "exchanged":
        files._empty_into = die
    elif point == "fallback":
        files.exchange = lambda a, b: False
        real, calls = os.rename, []
        def rename(a, b):
            calls.append(a)
            if len(calls) == 2:
                die()
            real(a, b)
        files.os.rename = rename
    print("ready", flush=True)
    while True:
        with files.StagedFolder(target, names) as stage:
            for i, n in enumerate(names):
                files.atomic_write(stage.path / n, (src / n).read_bytes())
                if point == "fresh" and i == 2:
                    die()
            stage.commit()
    """
)


def kill_during_write(point: str, target: Path, src: Path, delay: float = 0.0) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", KILL_SCRIPT, point, str(target), str(src)],
        stdout=subprocess.PIPE,
        cwd=ROOT,
    )
    assert proc.stdout.readline().strip() == b"ready"
    if point == "random":
        time.sleep(delay)
        proc.kill()
    assert proc.wait(timeout=60) == -signal.SIGKILL


@pytest.mark.parametrize("point", ["fresh", "staged", "exchanged", "fallback", "random"])
def test_kill_during_write_leaves_a_whole_set(point, sets, tmp_path):
    """kill -9 while a new result set replaces an old one: the folder holds the complete old
    or the complete new set (the fallback may briefly hold none); the next write cleans up and
    keeps the folder's other entries."""
    src = tmp_path / "src"
    src.mkdir()
    for n, data in sets["new"].items():
        (src / n).write_bytes(data)
    out = tmp_path / "results"
    if point != "fresh":
        write_outputs(synthetic_result(10.0), out)
        (out / "quick").mkdir()
        (out / "quick" / "notes.txt").write_text("keep me")
    for delay in [0.0] if point != "random" else random.Random(0).sample([0.05, 0.2, 0.4], 3):
        kill_during_write(point, out, src, delay)
        if point == "fresh":
            assert not out.exists()  # nothing half-written at the target
        elif point != "fallback":
            assert result_set(out, sets) in ("old", "new")
        assert point == "random" or leftovers(out)
    write_outputs(synthetic_result(90.0), out)
    assert result_set(out, sets) == "new"
    assert leftovers(out) == []
    if point != "fresh":
        assert (out / "quick" / "notes.txt").read_text() == "keep me"


def test_leftover_tmp_and_staging_are_cleaned(sets, tmp_path):
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    pid = int(dead.stdout)
    (out / ".route_level_results.csv.x1y2.tmp").write_text("half")
    stale = tmp_path / f".results.staging-{pid}-dead"
    stale.mkdir()
    (stale / "family_cus.csv").write_text("half")
    live = tmp_path / f".results.staging-{os.getppid()}-live"  # a running process: kept
    live.mkdir()
    write_outputs(synthetic_result(90.0), out)
    assert result_set(out, sets) == "new"
    assert leftovers(out) == [live.name]


def test_schema_failure_leaves_the_old_set(sets, tmp_path):
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)
    bad = synthetic_result(90.0)
    bad.route_table.loc[0, "CUS"] = 150.0
    with pytest.raises(ValueError, match="CUS must lie in"):
        write_outputs(bad, out)
    assert result_set(out, sets) == "old"
    assert leftovers(out) == []


def test_manifest_onto_a_folder(base_manifest, tmp_path, monkeypatch):
    folder = tmp_path / "suite.json"
    folder.mkdir()
    with pytest.raises(IsADirectoryError, match="it is a folder"):
        write_manifest(base_manifest, folder)
    assert os.listdir(tmp_path) == ["suite.json"] and os.listdir(folder) == []

    def refuse(*a, **k):
        raise AssertionError("generated although the target is a folder")

    monkeypatch.setattr("lantern_jax.generate.generate_suite", refuse)
    res = run_cli(["suite", "--regenerate", str(folder)])
    assert res.rc == 2 and "give the path of a file" in res.err


# ---------------------------------------------------------------------------------------------
# --out
# ---------------------------------------------------------------------------------------------
def _unwritable(tmp_path: Path) -> str:
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        return str(ro / "results")
    if not Path("/proc/self").is_dir():
        pytest.skip("no read-only place to write to")
    return "/proc/lantern-results"  # read-only even for root


@pytest.mark.parametrize("kind", ["file", "under-file", "unwritable", "empty"])
def test_bad_out_is_refused_before_evaluating(kind, tmp_path, no_evaluation):
    f = tmp_path / "a_file"
    f.write_text("x")
    out = {"file": str(f), "under-file": str(f / "results"), "empty": ""}.get(kind)
    out = _unwritable(tmp_path) if kind == "unwritable" else out
    expected = {
        "file": "is a file, not a folder",
        "under-file": "is a file, not a folder",
        "unwritable": "cannot create folders in|not writable",
        "empty": "empty path",
    }[kind]
    res = run_cli(["evaluate", "--pairs", "pe_0001", "--out", out])
    assert res.rc == 2
    assert "--out: output folder" in res.err
    assert any(e in res.err for e in expected.split("|")), res.err
    assert f.read_text() == "x"


def test_out_symlink_is_followed(sets, tmp_path):
    real = tmp_path / "real"
    write_outputs(synthetic_result(10.0), real)
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    write_outputs(synthetic_result(90.0), link)
    assert link.is_symlink() and result_set(real, sets) == "new"


# ---------------------------------------------------------------------------------------------
# configs and flags
# ---------------------------------------------------------------------------------------------
CONFIG_CASES = [
    ("beside-table", 'policy = "coop"\n[evaluate]\nout = "x"\n',
     r"key\(s\) 'policy' outside the \[evaluate\] table"),
    ("no-table", 'policy = "coop"\npairs_per_family = 1\n',
     r"key\(s\) 'policy', 'pairs_per_family' outside the \[evaluate\] table"),
    ("other-table", '[evaluate]\nout = "x"\n[run]\npolicy = "coop"\n',
     r"key\(s\) 'run' outside the \[evaluate\] table"),
    ("unknown-key", '[evaluate]\nablaton = "none"\n', r"unknown key 'ablaton' in \[evaluate\]"),
    ("nested-table", '[evaluate]\n[evaluate.policy]\nname = "coop"\n',
     r"policy must be str or list"),
    ("empty-pairs", "[evaluate]\npairs = []\n", r"pairs is empty"),
    ("empty-policy", "[evaluate]\npolicy = []\n", r"policy is empty"),
    ("blank-policy", '[evaluate]\npolicy = ""\n', r"policy is empty"),
    ("empty-file", "", r"no \[evaluate\] table"),
]  # fmt: skip


@pytest.mark.parametrize("case", CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_bad_config(case, tmp_path, no_evaluation):
    _, text, expected = case
    path = tmp_path / "exp.toml"
    path.write_text(text)
    with pytest.raises(cli.UsageError, match=rf"config {re.escape(str(path))}: {expected}"):
        cli.load_config(str(path))
    res = run_cli(["evaluate", "--config", str(path), "--out", str(tmp_path / "out")])
    assert res.rc == 2 and f"config {path}" in res.err


FLAG_CASES = [
    (["--pol", "coop"], "unrecognized arguments: --pol"),
    (["--pairs-per", "1"], "unrecognized arguments: --pairs-per"),
    (["--abl", "late_onset"], "unrecognized arguments: --abl"),
    (["--pairs", ""], "--pairs: no pair id given"),
    (["--pairs", ","], "--pairs: no pair id given"),
    (["--policy", ""], "--policy: no policy name given"),
    (["--pairs", "pe_0001,pe_0001"], "--pairs: pair ids given more than once: pe_0001"),
]


@pytest.mark.parametrize("flags, expected", FLAG_CASES, ids=[" ".join(c[0]) for c in FLAG_CASES])
def test_bad_flags(flags, expected, tmp_path, no_evaluation):
    res = run_cli(["evaluate", *flags, "--out", str(tmp_path / "out")])
    assert res.rc == 2
    assert expected in res.err


def test_explicit_flags_win_over_the_config(tmp_path, monkeypatch):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        '[evaluate]\npolicy = "ego"\nablation = "late_onset"\npairs_per_family = 2\n'
        f'out = "{tmp_path / "from_config"}"\n'
    )
    seen = {}

    class Stop(Exception):
        pass

    def capture(policies, suite, ablation, progress, one_program):
        seen.update(policies=policies, pairs=len(suite), ablation=ablation, one=one_program)
        raise Stop

    monkeypatch.setattr(ev, "evaluate", capture)
    argv = ["evaluate", "--config", str(cfg), "--policy", "coop", "--ablation", "none"]
    with pytest.raises(Stop):
        run_cli([*argv, "--pairs-per-family", "1", "--out", str(tmp_path / "o")])
    assert seen == dict(policies=["coop"], pairs=6, ablation="none", one=True)
    with pytest.raises(Stop):
        run_cli(["evaluate", "--config", str(cfg), "--program-per-policy"])
    assert seen == dict(policies=["ego"], pairs=12, ablation="late_onset", one=False)


# ---------------------------------------------------------------------------------------------
# Python API
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "policies, error",
    [
        ([], r"evaluate: no policies given"),
        (["ego", "ego"], r"policy name\(s\) 'ego' given more than once"),
        ("object-and-name", r"policy name\(s\) 'coop' given more than once"),
        ("empty-suite", r"suite 'two-pairs' has no pairs"),
    ],
    ids=["empty", "duplicate", "object-and-name", "empty-suite"],
)
def test_bad_evaluate_arguments(policies, error, monkeypatch):
    monkeypatch.setattr(ev, "build_executions", lambda *a: pytest.fail("built executions"))
    suite = load_suite().select(PAIRS)
    if policies == "object-and-name":
        policies = [get_policy("coop"), "coop"]
    if policies == "empty-suite":
        policies, suite = ["coop"], dataclasses.replace(suite, suite_id="two-pairs", pairs=())
    with pytest.raises(ValueError, match=error):
        ev.evaluate(policies, suite=suite, progress=False)


def test_select_of_one_id_string():
    assert [p.pair_id for p in load_suite().select("pe_0001").pairs] == ["pe_0001"]


# ---------------------------------------------------------------------------------------------
# interrupts and policy errors
# ---------------------------------------------------------------------------------------------
def test_sigint_during_compile_exits_130(tmp_path):
    env = dict(os.environ, JAX_LOG_COMPILES="1", JAX_COMPILATION_CACHE_DIR=str(tmp_path / "cc"))
    out = tmp_path / "results"
    proc = subprocess.Popen(
        [sys.executable, "-m", "lantern_jax", "evaluate", "--policy", "coop",
         "--pairs", "lww_0001", "--out", str(out), "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
    )  # fmt: skip
    seen = []
    for line in proc.stderr:  # the rollout's XLA compilation starts after this line
        seen.append(line)
        if "Finished jaxpr to MLIR module conversion jit(program)" in line:
            break
    else:
        pytest.fail("no rollout compilation seen:\n" + "".join(seen[-20:]))
    time.sleep(1.0)  # well inside the compilation (about 10 s on two cores)
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read()
    assert proc.wait(timeout=120) == 130, rest[-2000:]
    assert "lantern-jax: interrupted" in rest
    assert "Segmentation fault" not in rest and "Traceback" not in rest
    assert not out.exists() and leftovers(out) == []


def _raising_policies():
    coop = get_policy("coop")

    def fail(*args):
        raise RuntimeError("no waypoints today")

    def act_in_rollout(params, obs):
        jax.debug.callback(fail, obs.ego_speed)
        return coop.act(params, obs)

    def act_traced(params, obs):
        raise RuntimeError("cannot trace me")

    return {
        "raises-in-rollout": Policy("raises-in-rollout", coop.init, act_in_rollout),
        "raises-traced": Policy("raises-traced", coop.init, act_traced),
    }


RAISING = _raising_policies()


@pytest.mark.parametrize(
    "name, why",
    [
        ("raises-traced", r"RuntimeError: cannot trace me"),
        ("raises-in-rollout", r"JaxRuntimeError: .*RuntimeError: no waypoints today"),
    ],
)
def test_raising_policy_is_named(name, why, tmp_path, monkeypatch):
    pol = RAISING[name]
    suite = load_suite().select(["lww_0001"])
    with pytest.raises(ev.PolicyError, match=rf"policy '{name}' failed .*: {why}"):
        ev.evaluate([pol], suite=suite, progress=False)
    monkeypatch.setitem(policy_registry._REGISTRY, name, lambda: pol)
    out = tmp_path / "results"
    res = run_cli(["evaluate", "--policy", name, "--pairs", "lww_0001", "--out", str(out)])
    assert res.rc == 1
    assert f"error: policy '{name}' failed" in res.err
    assert not out.exists() and leftovers(out) == []


def test_a_swallowed_interrupt_still_ends_the_command_with_130(monkeypatch, tmp_path, capsys):
    """Ctrl-C raised where Python ignores exceptions (a finalizer on the way back from a long
    native call) must not let the command go on and report success."""
    import signal as signal_module

    from lantern_jax import cli

    def swallowed(args, argv):
        try:
            signal_module.raise_signal(signal_module.SIGINT)
        except KeyboardInterrupt:
            pass  # what a finalizer does with it
        return 0

    monkeypatch.setattr(cli, "cmd_policies", swallowed)
    before = signal_module.getsignal(signal_module.SIGINT)
    assert cli.main(["policies"]) == 130
    assert "lantern-jax: interrupted" in capsys.readouterr().err
    assert signal_module.getsignal(signal_module.SIGINT) is before  # handler restored
    cli._SIGINT_SEEN = True  # a stale flag from an earlier command is cleared on entry
    monkeypatch.setattr(cli, "cmd_policies", lambda args, argv: 0)
    assert cli.main(["policies"]) == 0
