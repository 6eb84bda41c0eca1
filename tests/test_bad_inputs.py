"""A catalogue of bad inputs and faults: each gets a clear error naming what is wrong, or a
defined outcome, never a silent wrong result, a raw traceback or a mixed set of files.

Three rules hold throughout: a usage error ends in one line naming the bad value and where it
came from (flag, config file and key, file and field), exit code 2, before anything is
compiled; a fault is recorded where the result is, and a result set is complete or absent;
nothing the project did not write is deleted or overwritten.

Catalogue (190 bad inputs and faults, in 13 categories):

* suite files (43: 40 in ``SUITE_CASES``, a duplicated JSON key, broken JSON, a generated
  suite's id): family and weather labels that disagree with the parameters; a 4e-7 change and
  a larger one under the old hash; out-of-range, negative, missing, string, boolean, unknown,
  NaN, inf and infeasible parameters (hashes recomputed); occluder and road-geometry fields
  missing, NaN, infinite or placing a parked truck in the route corridor; a recorded route with
  a NaN point or of the wrong type; wrong JSON types of pair id, seed (null, ``"abc"``), pair
  hash, report, suite id, pairs and params; a parameter seed ``"abc"``; unknown family (label
  and parameters); duplicate pair ids and scenarios; missing and unknown fields; no pairs; a
  wrong suite hash; an unsupported format version; an edited, re-hashed file that keeps the
  shipped id ``lantern-v3`` — each refused by ``load_suite`` with a line naming file, pair and
  field, and by the CLI with exit code 2 before anything is built; a suite generated with
  another seed never claims the shipped id;
* suite selections (4): ``select([])``, an id twice, ``subset(0)``, a missing file;
* result sets (13): ``kill -9`` at five points of a write (into a fresh folder; with every file
  staged; between the exchange and moving the folder's other entries back; between the two
  renames of the fallback; at three random moments) leaves the old or the new complete set and
  the next write cleans up and keeps the other entries; ``kill -9`` while a set is written in
  place leaves no manifest; a leftover ``*.tmp`` and a stale staging folder are cleaned (a live
  process's is kept); a route table failing its schema leaves the old set; a suite manifest
  onto a folder (API: clear error, no temp file; CLI: exit 2 before generating); two runs of
  the same evaluation give a byte-identical manifest (wall times and the command go to
  ``run_record.json``); two processes writing one folder at once leave one whole set;
* output folders (14): a file, under a file, unwritable, empty — exit 2 before the evaluation;
  a symbolic link is followed; a bind mount and an exchange failing with EBUSY are written in
  place, saying so; ``--out .`` keeps the working folder and the user's files; a 250-character
  folder name; root writing into a user's folder keeps its owner, group and mode; ``dataset``,
  ``train``, ``stress`` and ``unseen`` with ``--out`` a file;
* configs, flags and environment (37): keys beside ``[evaluate]``, keys without it, another
  table, an unknown key, a nested table, ``pairs = []``, ``policy = []``, ``policy = ""``, an
  empty file, ``pairs_per_family = 0`` and ``-2``, ``--pol``, ``--pairs-per``, ``--abl``,
  ``--pairs ""``, ``--pairs ","``, ``--policy ""``, a pair given twice, ``--checkpoint ""`` and
  ``","``, ``--pairs-per-family 0`` — exit 2; a bad policy, ablation, pair list, suite,
  checkpoint or output folder from the file, named by file and key; a UTF-8 byte-order mark in
  both config formats (read), UTF-16 (refused); ``LANTERN_JAX_CPU_DEVICES`` ``abc``, ``0``,
  ``-2``, empty, ``LANTERN_JAX_SPLIT_WORKERS=0``, ``LANTERN_JAX_COMPACT_SLOTS=many``; explicit
  flags (even with their default value) win over the file;
* training configs (8): ``lr = inf`` and ``nan``, ``weight_decay = -1``, ``val_fraction = 0``,
  a name that is a path or ``all``, ``max_minutes = inf``, ``--epochs 0`` (named as the flag);
* checkpoints (24): 17 descriptions (``CHECKPOINT_CASES``: a name edited without its hash, a
  string or negative width, a list for the description or the config, a NaN config, no config,
  rig ``"sixcams"``, a string for ``language``, heads not dividing the width, an unknown config
  field, an unselectable name, a string ``train_config``, no hash, a wrong hash type, a
  negative epoch, a NaN loss) refused naming file and field, by the API and the CLI; a model
  named ``coop`` or ``learned-coop`` does not replace the registered policy; the same
  checkpoint registers twice, another under the same name is refused, ``NAME=PATH`` names one,
  an unselectable given name is refused; infinite weights are refused naming the parameter;
* stress and diagnostics options (17): ``--restarts 0``, ``--samples 0`` and ``1`` (CMA-ES),
  ``--samples 0`` (gradient only), ``--sigma -1``, ``--temperature 0`` and ``nan``,
  ``--actor-temperature 0``, ``--budget-s inf``, ``--range`` with an infinite bound,
  ``--window inf``, ``--routes 100000``,
  distance-only options given to ``nonactionable`` (one, two), ``wording`` with ``--policy`` and
  ``--checkpoint``, an empty ``--checkpoint`` (``wording``, ``diagnostics``) — exit 2 before
  anything runs;
* program store (7): swapped entries, an entry of the old format, flipped bytes, a truncated
  entry — each deleted with a warning and compiled again, JAX's own cache still serving it;
  two processes storing one program; a full disk; a changed ``XLA_FLAGS`` is another program;
* standard output (2): a full disk (``> /dev/full``) is one line and exit 1; a reader that left
  (``| head -1``) ends quietly with 141;
* Python API (9): ``evaluate([])``, ``evaluate(["ego", "ego"])``, a policy object beside its
  name, an empty ``Suite`` — ``ValueError`` before anything is built; ``select`` of one str;
  NaN, infinite and huge plans from a user policy are recorded controller faults, a backwards
  plan is driven as the controller defines it;
* reproducibility promise (2, slow): the same batch gives the same files; a pair alone on one
  CPU device keeps the promise against the pair inside a batch split over two devices;
* interrupts and policy errors (13): SIGINT during compile exits 130 (it used to segfault) and
  leaves nothing; a policy raising while traced and one raising inside the rollout, each
  through the API (``PolicyError``) and the CLI (exit 1), the error naming the policy; a
  swallowed SIGINT still ends with 130; ``kill -9`` between a chunk's shards or before its card
  and SIGINT while recording leave a dataset that training refuses until the same command
  resumes it (then identical to an uninterrupted run); ``kill -9`` and SIGINT between an
  exported model's weights and its description leave a pair that is refused; SIGINT during a
  stress search writes nothing and ``kill -9`` while its results are written leaves the last
  whole set.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import errno
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
import numpy as np
import pandas as pd
import pytest

import lantern_jax.apps.evaluation as ev
from lantern_jax import cli
from lantern_jax.commands import UsageError
from lantern_jax.commands.common import register_checkpoints
from lantern_jax.commands.evaluate import load_config
from lantern_jax.commands.suite import suite_to_manifest
from lantern_jax.io import files
from lantern_jax.policies import registry as policy_registry
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.report import MANIFEST_JSON, OUTPUT_FILES, RUN_RECORD_JSON, write_outputs
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import (
    PairSpec,
    SuiteError,
    load_suite,
    suite_hash,
    write_manifest,
)
from lantern_jax.scoring.aggregate import decomposition_table
from lantern_jax.scoring.table import schema_columns, validate_route_table

PAIRS = ["pe_0001", "lww_0001"]
ROOT = Path(__file__).resolve().parents[1]


def run_cli(argv: list[str]) -> types.SimpleNamespace:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(argv)
    return types.SimpleNamespace(rc=rc, out=out.getvalue(), err=err.getvalue())


def run_program(argv: list[str], env: dict | None = None, **kw) -> subprocess.CompletedProcess:
    """``python -m lantern_jax ARGV`` in a new process (output captured unless ``kw`` says
    where it goes)."""
    opts = dict(stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                env=dict(os.environ, **(env or {})), timeout=300)  # fmt: skip
    return subprocess.run([sys.executable, "-m", "lantern_jax", *argv], **{**opts, **kw})


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
    return suite_to_manifest(load_suite().select(PAIRS), "two-pairs")


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
     # the six built-in families, then any registered in the process (the unseen hazards)
     r"pair pe_0001: family: 'XX' not one of \{PE, VC, OR, LWW, RWW, RTY(, [A-Z]+)*\}"),
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
    ("shipped-id", _set(("suite_id",), "lantern-v3"), True,
     r"suite_id: 'lantern-v3' is the shipped suite's id, but the pairs hash to [0-9a-f]{12}\.\.\. "
     r"\(shipped: cee6e0dafefd\.\.\.\); give an edited suite an id of its own"),
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


def test_a_generated_suite_claims_the_shipped_id_only_when_it_is_that_suite():
    from lantern_jax.apps.suite_generation import regenerated_suite_id
    from lantern_jax.scenarios.suite import shipped_suite_hash

    shipped = load_suite()
    assert shipped_suite_hash("lantern-v3") == shipped.suite_sha256
    assert regenerated_suite_id(shipped.seed, shipped.suite_sha256) == "lantern-v3"
    assert regenerated_suite_id(5, "ab" * 32) == "lantern-v3-seed5-abababab"
    assert shipped_suite_hash("lantern-v3-seed5-abababab") is None


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
def synthetic_result(cus: float, seconds: float = 1.0) -> ev.EvalResult:
    """An evaluation result of two pairs built from the schema (no rollout): every gate passed,
    every continuous value 0.5, the given CUS; ``seconds`` of compilation and rollout."""
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
    manifest = dict(suite_id="two-pairs", num_pairs=2, ablation="none", cus=cus,
                    executions_per_policy=6,
                    policies=[dict(name="m", params_sha256="0" * 64, seconds_compile=seconds,
                                   seconds_run=seconds)])  # fmt: skip
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
    """'old' or 'new' when ``folder`` holds exactly one complete reference set (its run record,
    which names the command that wrote it, only present)."""
    got = {n: (folder / n).read_bytes() for n in OUTPUT_FILES if (folder / n).is_file()}
    if RUN_RECORD_JSON in got:
        got[RUN_RECORD_JSON] = None
    which = [k for k, ref in sets.items() if got == {**ref, RUN_RECORD_JSON: None}]
    assert len(which) == 1, f"{folder} holds a mixed or partial set: {sorted(got)}"
    return which[0]


def leftovers(folder: Path) -> list[str]:
    """Hidden staging / old / probe folders beside ``folder`` (or, from a set written in place,
    inside it) and temporary files inside it."""
    ours = f".{files.name_stem(folder.name)}."
    beside = [e for e in os.listdir(folder.parent) if e.startswith(ours)]
    inside = [e for e in os.listdir(folder) if e.endswith(".tmp") or e.startswith(ours)
              ] if folder.is_dir() else []  # fmt: skip
    return beside + inside


KILL_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    from pathlib import Path
    from lantern_jax.io import files

    point, target, src = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    names = sys.argv[4].split(",")
    die = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
    if point == "staged":
        files.exchange = die
    elif point == "exchanged":
        files._empty_into = die
    elif point == "in-place":  # after the manifest went and two files were replaced
        files.in_place_reason = lambda t: "written in place for the test"
        real_replace, placed = os.replace, []
        def replace(a, b):
            if Path(b).parent == Path(os.path.realpath(target)):
                placed.append(b)
                if len(placed) == 3:
                    die()
            real_replace(a, b)
        files.os.replace = replace
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
        [sys.executable, "-c", KILL_SCRIPT, point, str(target), str(src), ",".join(OUTPUT_FILES)],
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

    monkeypatch.setattr("lantern_jax.apps.suite_generation.generate_suite", refuse)
    res = run_cli(["suite", "--regenerate", str(folder)])
    assert res.rc == 2 and "give the path of a file" in res.err


def test_kill_while_writing_in_place_leaves_no_manifest(sets, tmp_path):
    """kill -9 while a set is written into a folder in place (a mount point, the current
    folder): the manifest went first, so the folder holds no set that claims to be complete;
    the next write completes it and cleans the staging folder inside."""
    src = tmp_path / "src"
    src.mkdir()
    for n, data in sets["new"].items():
        (src / n).write_bytes(data)
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)
    (out / "notes.txt").write_text("keep me")
    kill_during_write("in-place", out, src)
    assert not (out / MANIFEST_JSON).exists() and leftovers(out)
    write_outputs(synthetic_result(90.0), out)
    assert result_set(out, sets) == "new" and leftovers(out) == []
    assert (out / "notes.txt").read_text() == "keep me"


def test_same_inputs_give_the_same_manifest_and_a_run_record(tmp_path):
    """Two runs of the same evaluation differ in wall times and command line: those go to
    ``run_record.json``; every other file, the manifest included, is byte-identical."""
    a = write_outputs(synthetic_result(50.0, seconds=1.5), tmp_path / "a",
                      run_record={"command": "lantern-jax evaluate"})  # fmt: skip
    b = write_outputs(synthetic_result(50.0, seconds=9.25), tmp_path / "b",
                      run_record={"command": "lantern-jax evaluate --quiet"})  # fmt: skip
    for name in OUTPUT_FILES:
        assert (a[name].read_bytes() == b[name].read_bytes()) == (name != RUN_RECORD_JSON), name
    assert json.loads(b[RUN_RECORD_JSON].read_text()) == {
        "command": "lantern-jax evaluate --quiet",
        "policies": [{"name": "m", "seconds_compile": 9.25, "seconds_run": 9.25}],
    }
    manifest = json.loads(a[MANIFEST_JSON].read_text())
    assert "seconds" not in a[MANIFEST_JSON].read_text() and "command" not in manifest
    assert {f["name"] for f in manifest["files"]} == set(OUTPUT_FILES) - {
        MANIFEST_JSON, RUN_RECORD_JSON}  # fmt: skip


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from lantern_jax.io import files

    target, src, names = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3].split(",")
    print("ready", flush=True)
    sys.stdin.readline()
    for _ in range(12):
        with files.StagedFolder(target, names) as stage:
            for n in names:
                files.atomic_write(stage.path / n, (src / n).read_bytes())
            stage.commit()
    """
)


def test_two_processes_writing_one_folder_leave_one_whole_set(sets, tmp_path):
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)
    (out / "quick").mkdir()
    (out / "quick" / "notes.txt").write_text("keep me")
    procs = []
    for which in ("old", "new"):
        src = tmp_path / which
        src.mkdir()
        for n, data in sets[which].items():
            (src / n).write_bytes(data)
        procs.append(subprocess.Popen(
            [sys.executable, "-c", WRITER_SCRIPT, str(out), str(src), ",".join(OUTPUT_FILES)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
        ))  # fmt: skip
    for proc in procs:
        assert proc.stdout.readline().strip() == b"ready"
    for proc in procs:  # both start writing at the same moment
        proc.stdin.write(b"go\n")
        proc.stdin.flush()
    for proc in procs:
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err.decode()[-2000:]
    assert result_set(out, sets) in ("old", "new") and leftovers(out) == []
    assert (out / "quick" / "notes.txt").read_text() == "keep me"


# ---------------------------------------------------------------------------------------------
# output folders
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


@pytest.fixture
def fake_evaluation(monkeypatch):
    """``lantern-jax evaluate`` without a rollout: the evaluation returns
    :func:`synthetic_result` (CUS from the returned list, 10 then 90)."""
    cus = [10.0, 90.0]
    monkeypatch.setattr(ev, "evaluate", lambda *a, **k: synthetic_result(cus.pop(0)))


def _bind_mount(folder: Path) -> None:
    """Make ``folder`` a mount point of its own (a bind mount), or skip the test."""
    if os.geteuid() != 0 or subprocess.run(["mount", "--bind", str(folder), str(folder)],
                                           capture_output=True).returncode != 0:  # fmt: skip
        pytest.skip("cannot bind-mount here (needs root and mount rights)")


def test_out_on_a_mount_point_is_written_in_place(sets, tmp_path, fake_evaluation, caplog):
    """A bind mount (Docker's ``-v host:/app/results``) cannot be exchanged ("Device or
    resource busy" after the whole evaluation): it is detected up front and written in place,
    and the command says so."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    (mnt / "notes.txt").write_text("keep me")
    _bind_mount(mnt)
    try:
        inode = os.stat(mnt).st_ino
        assert files.is_mount_point(mnt) and not os.path.ismount(mnt)  # same file system
        for which in ("old", "new"):
            res = run_cli(["evaluate", "--policy", "coop", "--pairs", "pe_0001", "--out", str(mnt)])
            assert res.rc == 0, res.err
            assert result_set(mnt, sets) == which and leftovers(mnt) == []
        assert os.stat(mnt).st_ino == inode and (mnt / "notes.txt").read_text() == "keep me"
        assert f"output folder {mnt}: it is a mount point" in caplog.text
        record = json.loads((mnt / RUN_RECORD_JSON).read_text())
        assert record["written_in_place"] == "it is a mount point (its name cannot be exchanged)"
        assert "replaced one by one (each atomically, reproducibility_manifest.json last)" in (
            caplog.text)  # fmt: skip
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


def test_a_busy_exchange_falls_back_to_writing_in_place(sets, tmp_path, monkeypatch, caplog):
    """Where the exchange fails with EBUSY although no mount point was seen, the set is
    written in place instead of being lost, and the command says which happened."""
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)

    def busy(a, b):
        raise OSError(errno.EBUSY, os.strerror(errno.EBUSY))

    monkeypatch.setattr(files, "exchange", busy)
    write_outputs(synthetic_result(90.0), out)
    assert result_set(out, sets) == "new" and leftovers(out) == []
    assert "its name cannot be exchanged (Device or resource busy)" in caplog.text
    assert "replaced one by one (each atomically, reproducibility_manifest.json last) instead" in (
        caplog.text)  # fmt: skip


def test_out_dot_keeps_the_working_folder(sets, tmp_path, monkeypatch, fake_evaluation, caplog):
    """``--out .`` writes into the current folder: the folder (the shell's working folder) is
    not replaced, the user's files stay, and the next run replaces only the result files."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "mine.txt").write_text("mine")
    monkeypatch.chdir(work)
    inode = os.stat(work).st_ino
    for which in ("old", "new"):
        res = run_cli(["evaluate", "--policy", "coop", "--pairs", "pe_0001", "--out", "."])
        assert res.rc == 0, res.err
        assert result_set(work, sets) == which and leftovers(work) == []
    assert os.stat(work).st_ino == inode and os.getcwd() == str(work)
    assert (work / "mine.txt").read_text() == "mine"
    assert "output folder .: it is (or holds) the current folder" in caplog.text
    record = json.loads((work / RUN_RECORD_JSON).read_text())
    assert record["written_in_place"] == "it is (or holds) the current folder"


def test_a_250_character_folder_name_is_written(sets, tmp_path):
    """A valid folder name of 250 characters: the hidden probe, staging and temporary names
    are shortened (with a hash of the name) instead of exceeding the 255-byte limit."""
    out = tmp_path / ("r" * 250)
    for cus, which in ((10.0, "old"), (90.0, "new")):
        write_outputs(synthetic_result(cus), out)
        assert result_set(out, sets) == which and leftovers(out) == []
    assert len(files.name_stem(out.name)) < len(out.name)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root")
def test_root_keeps_the_owner_and_mode_of_a_users_folder(sets, tmp_path):
    out = tmp_path / "results"
    write_outputs(synthetic_result(10.0), out)
    for p in (out, *out.iterdir()):
        os.chown(p, 4321, 4322)
    out.chmod(0o750)
    write_outputs(synthetic_result(90.0), out)  # as root
    assert result_set(out, sets) == "new"
    st = os.stat(out)
    assert (st.st_uid, st.st_gid, st.st_mode & 0o777) == (4321, 4322, 0o750)
    assert {(p.stat().st_uid, p.stat().st_gid) for p in out.iterdir()} == {(4321, 4322)}


@pytest.mark.parametrize("command", ["dataset", "train", "stress", "unseen"])
def test_an_output_folder_that_is_a_file_is_refused(command, tmp_path):
    """``lantern-jax dataset --out /etc/passwd`` (a file): one line naming ``--out``, exit 2, the
    file intact; the same for every command with ``--out``."""
    a_file = tmp_path / "passwd"
    a_file.write_text("root:x:0:0")
    config = tmp_path / "t.toml"
    config.write_text('[train]\nname = "mine"\nrecipe = "base"\n')
    argv = {
        "dataset": ["dataset", "--out", str(a_file)],
        "train": ["train", "--config", str(config), "--out", str(a_file)],
        "stress": ["stress", "--family", "PE", "--out", str(a_file)],
        "unseen": ["unseen", "--policy", "coop", "--out", str(a_file)],
    }[command]
    res = run_cli(argv)
    assert res.rc == 2 and a_file.read_text() == "root:x:0:0"
    assert res.err == (f"lantern-jax {command}: error: --out: output folder {a_file}: is a "
                       "file, not a folder\n")  # fmt: skip


# ---------------------------------------------------------------------------------------------
# configs, flags and environment
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
    ("pairs-per-family-0", "[evaluate]\npairs_per_family = 0\n",
     r"pairs_per_family must be >= 1 \(got 0\)"),
    ("pairs-per-family-negative", "[evaluate]\npairs_per_family = -2\n",
     r"pairs_per_family must be >= 1 \(got -2\)"),
]  # fmt: skip


@pytest.mark.parametrize("case", CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_bad_config(case, tmp_path, no_evaluation):
    _, text, expected = case
    path = tmp_path / "exp.toml"
    path.write_text(text)
    with pytest.raises(UsageError, match=rf"config {re.escape(str(path))}: {expected}"):
        load_config(str(path))
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
    (["--checkpoint", ""], "--checkpoint: no checkpoint given (leave the option out for none)"),
    (["--checkpoint", ",", "--policy", "coop"], "--checkpoint: no checkpoint given"),
    (["--pairs-per-family", "0"],
     "argument --pairs-per-family: expected a whole number in 1 .. 1000000, got 0"),
]


@pytest.mark.parametrize("flags, expected", FLAG_CASES, ids=[" ".join(c[0]) for c in FLAG_CASES])
def test_bad_flags(flags, expected, tmp_path, no_evaluation):
    res = run_cli(["evaluate", *flags, "--out", str(tmp_path / "out")])
    assert res.rc == 2
    assert expected in res.err


#: A value the file gives that is wrong only once it is used: the message names the file's key.
CONFIG_VALUE_CASES = [
    ("policy", 'policy = "nosuch"', "config {path}: policy: unknown policy 'nosuch'"),
    ("ablation", 'ablation = "nosuch"', "config {path}: ablation: unknown ablation 'nosuch'"),
    ("pairs", 'pairs = ["zz_0001"]', "config {path}: pairs: pairs not in suite lantern-v3"),
    ("suite", 'suite = "lantern-v9"', "config {path}: suite: unknown suite 'lantern-v9'"),
    ("checkpoint", 'checkpoint = "none.msgpack"', "config {path}: checkpoint: none.msgpack: no "
     "such checkpoint"),
    ("out", 'out = "{file}"', "config {path}: out: output folder {file}: is a file"),
]  # fmt: skip


@pytest.mark.parametrize("case", CONFIG_VALUE_CASES, ids=[c[0] for c in CONFIG_VALUE_CASES])
def test_a_bad_value_from_the_config_names_its_key(case, tmp_path, no_evaluation):
    _, line, expected = case
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    path = tmp_path / "exp.toml"
    path.write_text("[evaluate]\n" + line.format(file=a_file) + "\n")
    res = run_cli(["evaluate", "--config", str(path)])
    assert res.rc == 2 and "Traceback" not in res.err
    assert expected.format(path=path, file=a_file) in res.err, res.err


def test_a_config_with_a_byte_order_mark_is_read(tmp_path, monkeypatch):
    """Editors that write a UTF-8 byte-order mark: both config formats read such a file as if
    it had none (it gave "Invalid statement (line 1, col 1)")."""
    from lantern_jax.apps.training.config import load_config as load_train_config

    path = tmp_path / "exp.toml"
    path.write_bytes(b'\xef\xbb\xbf[evaluate]\npolicy = "coop"\npairs_per_family = 1\n')
    assert load_config(str(path)) == {"policy": "coop", "pairs_per_family": 1}
    path.write_bytes(b'\xef\xbb\xbf[train]\nname = "mine"\nrecipe = "base"\n')
    assert load_train_config(path).name == "mine"
    path.write_bytes(b"\xff\xfe[\x00e\x00")  # UTF-16: refused with the reason
    with pytest.raises(UsageError, match=r"not valid TOML \(not UTF-8 text"):
        load_config(str(path))


def test_explicit_flags_win_over_the_config(tmp_path, monkeypatch):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        '[evaluate]\npolicy = "ego"\nablation = "late_onset"\npairs_per_family = 2\n'
        f'out = "{tmp_path / "from_config"}"\n'
    )
    seen = {}

    class Stop(Exception):
        pass

    def capture(policies, suite, ablation, progress, one_program, path):
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


@pytest.mark.parametrize(("name", "value"), [
    ("LANTERN_JAX_CPU_DEVICES", "abc"), ("LANTERN_JAX_CPU_DEVICES", "0"),
    ("LANTERN_JAX_CPU_DEVICES", "-2"), ("LANTERN_JAX_CPU_DEVICES", ""),
    ("LANTERN_JAX_SPLIT_WORKERS", "0"), ("LANTERN_JAX_COMPACT_SLOTS", "many"),
])  # fmt: skip
def test_a_bad_count_variable_is_named_before_any_work(name, value):
    res = run_program(["policies"], env={name: value})
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr == (f"lantern-jax: error: environment variable {name}: "
                          f"expected a whole number >= 1, got {value!r}\n")  # fmt: skip


# ---------------------------------------------------------------------------------------------
# training configs
# ---------------------------------------------------------------------------------------------
TRAIN_CONFIG_CASES = [
    ("lr-inf", "lr = inf", "train.lr: must be a finite number, got inf"),
    ("lr-nan", "lr = nan", "train.lr: must be a finite number, got nan"),
    ("weight-decay-negative", "weight_decay = -1.0", "train.weight_decay: must be >= 0, got -1.0"),
    ("val-fraction-0", "val_fraction = 0.0", "train.val_fraction: must be in (0, 1)"),
    ("name-path", 'name = "../../../x"', "train.name: '../../../x' is not a selectable name"),
    ("name-all", 'name = "all"', "train.name: 'all' is reserved on the command line"),
    ("max-minutes-inf", "max_minutes = inf", "train.max_minutes: must be a finite number"),
]  # fmt: skip


@pytest.mark.parametrize("case", TRAIN_CONFIG_CASES, ids=[c[0] for c in TRAIN_CONFIG_CASES])
def test_bad_training_config_values(case, tmp_path, monkeypatch):
    from lantern_jax.apps.training import behaviour_cloning as train_module

    monkeypatch.setattr(train_module, "train", lambda *a, **k: pytest.fail("training started"))
    _, line, expected = case
    path = tmp_path / "t.toml"
    body = {"name": 'name = "mine"', "recipe": 'recipe = "base"'}
    key = line.split(" ")[0]
    body[key] = line
    path.write_text("[train]\n" + "\n".join(body.values()) + "\n")
    res = run_cli(["train", "--config", str(path)])
    assert res.rc == 2 and len(res.err.splitlines()) == 1
    assert res.err.startswith(f"lantern-jax train: error: config {path}: {expected}"), res.err


def test_a_bad_training_option_names_the_option(tmp_path, monkeypatch):
    from lantern_jax.apps.training import behaviour_cloning as train_module

    monkeypatch.setattr(train_module, "train", lambda *a, **k: pytest.fail("training started"))
    path = tmp_path / "t.toml"
    path.write_text('[train]\nname = "mine"\nrecipe = "base"\n')
    res = run_cli(["train", "--config", str(path), "--epochs", "0"])
    assert res.rc == 2 and res.err == (
        "lantern-jax train: error: argument --epochs: expected a whole number in 1 .. 1000000, got "
        "0; lantern-jax train --help lists the options\n"
    )


# ---------------------------------------------------------------------------------------------
# checkpoints
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def saved_models(tmp_path_factory) -> Path:
    """Two small saved models: ``mine.*`` (trained under the name "mine") and ``other.*``."""
    from lantern_jax.policies.learned.checkpoint import new_model, save_model
    from lantern_jax.policies.learned.model import ModelConfig

    folder = tmp_path_factory.mktemp("models")
    small = ModelConfig(width=8, heads=2)
    for stem, seed in (("mine", 1), ("other", 2)):
        save_model(new_model(small, seed), folder / stem,
                   dict(recipe="base", epoch=0, val_l1_m=0.5,
                        train_config=dict(name=stem, recipe="base")))  # fmt: skip
    return folder


@pytest.fixture
def registry(monkeypatch):
    """The policy registry, restored after the test."""
    monkeypatch.setattr(policy_registry, "_REGISTRY", dict(policy_registry._REGISTRY))
    monkeypatch.setattr(policy_registry, "_CHECKPOINT_HASHES", {})
    return policy_registry


def copy_checkpoint(saved_models: Path, tmp_path: Path, mutate=None, rehash=True,
                    stem: str = "mine") -> Path:  # fmt: skip
    """A copy of a saved model whose description ``mutate`` changed (hash recomputed: a careful
    forger); returns the ``.msgpack`` path."""
    from lantern_jax.policies.learned.checkpoint import description_hash

    for ext in (".msgpack", ".json"):
        (tmp_path / f"{stem}{ext}").write_bytes((saved_models / f"mine{ext}").read_bytes())
    meta = json.loads((tmp_path / f"{stem}.json").read_text())
    if mutate is not None:
        meta = mutate(meta) or meta
    if rehash and isinstance(meta, dict):
        with contextlib.suppress(Exception):
            meta["sha256"] = description_hash(meta)
    (tmp_path / f"{stem}.json").write_text(json.dumps(meta))
    return tmp_path / f"{stem}.msgpack"


CHECKPOINT_CASES = [
    # (id, mutation, recompute the description hash?, message after "<file>.json: ")
    ("name-edited", _set(("train_config", "name"), "coop"), False,
     r"sha256: does not match the description"),
    ("width-string", _set(("config", "width"), "64"), True,
     r"config\.width: expected a whole number >= 1, got '64'"),
    ("width-negative", _set(("config", "width"), -64), True,
     r"config\.width: expected a whole number >= 1, got -64"),
    ("top-level-list", lambda m: [m], True, r"\(top level\): expected a JSON object, got list"),
    ("config-list", _set(("config",), [8, 2]), True,
     r"config: expected a JSON object, got list"),
    ("config-nan", _set(("config",), math.nan), True,
     r"config: expected a JSON object, got float nan"),
    ("no-config", _del(("config",)), True, r"config: missing"),
    ("rig-sixcams", _set(("config", "rig"), "sixcams"), True,
     r"config\.rig: 'sixcams' not one of front, surround"),
    ("language-string", _set(("config", "language"), "yes"), True,
     r"config\.language: expected true or false, got 'yes'"),
    ("heads-not-dividing", _set(("config", "heads"), 3), True,
     r"config\.heads: 3 does not divide width 8"),
    ("unknown-config-field", _set(("config", "depth"), 3), True,
     r"config\.depth: unknown field"),
    ("name-unselectable", _set(("train_config", "name"), "../../x,y"), True,
     r"train_config\.name: '\.\./\.\./x,y' is not a selectable name"),
    ("train-config-string", _set(("train_config",), "x"), True,
     r"train_config: expected a JSON object, got str"),
    ("no-hash", _del(("sha256",)), False, r"sha256: missing \(written by an earlier"),
    ("params-hash-int", _set(("params_sha256",), 12), True,
     r"params_sha256: expected a 64-digit lowercase hex string, got 12"),
    ("epoch-negative", _set(("epoch",), -1), True,
     r"epoch: expected a whole number >= 0, got -1"),
    ("val-loss-nan", _set(("val_l1_m",), math.nan), True,
     r"val_l1_m: expected a finite number >= 0, got nan"),
]  # fmt: skip


@pytest.mark.parametrize("case", CHECKPOINT_CASES, ids=[c[0] for c in CHECKPOINT_CASES])
def test_bad_checkpoint_description(case, saved_models, tmp_path, registry, no_evaluation):
    from lantern_jax.policies.learned.checkpoint import CheckpointError, checkpoint_policy

    _, mutate, rehash, expected = case
    path = copy_checkpoint(saved_models, tmp_path, mutate, rehash)
    where = re.escape(str(path.with_suffix(".json")))
    with pytest.raises(CheckpointError, match=rf"^{where}: {expected}"):
        checkpoint_policy(path)
    res = run_cli(["evaluate", "--checkpoint", str(path), "--out", str(tmp_path / "out")])
    assert res.rc == 2 and len(res.err.splitlines()) == 1 and "Traceback" not in res.err
    assert re.search(rf"error: --checkpoint: {where}: {expected}", res.err), res.err
    assert not (tmp_path / "out").exists()


def test_a_checkpoint_cannot_take_a_registered_name(saved_models, tmp_path, registry,
                                                    no_evaluation):  # fmt: skip
    """A description that names its model ``coop`` (hash recomputed) does not replace the
    built-in ``coop``: rows labelled ``coop`` always come from the built-in policy."""
    from lantern_jax.policies.learned.checkpoint import CheckpointError

    builtin = get_policy("coop")
    for name, what in (("coop", "built in"), ("learned-coop", "a shipped model")):
        path = copy_checkpoint(saved_models, tmp_path, _set(("train_config", "name"), name))
        with pytest.raises(CheckpointError, match=rf"name '{name}' is already registered "
                                                  rf"\({what}\)"):  # fmt: skip
            registry.register_checkpoint(str(path))
        res = run_cli(["evaluate", "--policy", "coop", "--checkpoint", str(path),
                       "--pairs", "pe_0001", "--out", str(tmp_path / "out")])  # fmt: skip
        assert res.rc == 2 and f"name '{name}' is already registered ({what})" in res.err
        assert f"--checkpoint OTHER_NAME={path}" in res.err  # how to name it instead
    assert get_policy("coop").act is builtin.act
    assert "learned" not in get_policy("coop").description


def test_a_checkpoint_registers_once_and_under_a_name_given(saved_models, registry):
    from lantern_jax.policies.learned.checkpoint import CheckpointError

    mine = str(saved_models / "mine.msgpack")
    assert registry.register_checkpoint(mine) == "mine"
    first = get_policy("mine")
    assert registry.register_checkpoint(mine) == "mine" and get_policy("mine") is first  # same
    with pytest.raises(CheckpointError, match=r"name 'mine' is already registered \(another "):
        registry.register_checkpoint(str(saved_models / "other.msgpack"), "mine")
    assert register_checkpoints([f"mine2={saved_models / 'other.msgpack'}"]) == ["mine2"]
    with pytest.raises(CheckpointError, match=r"other\.msgpack: name: 'x/y' is not a selectable"):
        registry.register_checkpoint(str(saved_models / "other.msgpack"), "x/y")


def test_non_finite_weights_are_refused(saved_models, tmp_path, registry):
    """A model whose weights hold NaN (a diverged training, hashes recomputed) is refused when
    loaded, naming the parameter, instead of driving with NaN plans to the end."""
    import hashlib

    from flax import serialization

    from lantern_jax.policies.learned.checkpoint import CheckpointError, checkpoint_policy

    path = copy_checkpoint(saved_models, tmp_path)
    tree = serialization.msgpack_restore(path.read_bytes())
    kernel = np.array(tree["head"]["layers"]["0"]["kernel"])
    kernel[0, 0] = np.inf
    tree["head"]["layers"]["0"]["kernel"] = kernel
    data = serialization.msgpack_serialize(tree)
    copy_checkpoint(saved_models, tmp_path,
                    _set(("params_sha256",), hashlib.sha256(data).hexdigest()))  # fmt: skip
    path.write_bytes(data)
    with pytest.raises(CheckpointError, match=r"mine\.msgpack: parameter \['head'\]\['layers'\]"
                                              r"\[.?0.?\]\['kernel'\] holds values that are "
                                              r"not finite"):  # fmt: skip
        checkpoint_policy(path)
    res = run_cli(["evaluate", "--checkpoint", str(path), "--out", str(tmp_path / "out")])
    assert res.rc == 2 and "holds values that are not finite" in res.err


# ---------------------------------------------------------------------------------------------
# stress and diagnostics options
# ---------------------------------------------------------------------------------------------
#: What the command line adds to an option's refusal (the one line of argparse's error).
STRESS_HELP = "; lantern-jax stress --help lists the options"
STRESS_CASES = [
    (["--restarts", "0"],
     "argument --restarts: expected a whole number in 1 .. 4096, got 0" + STRESS_HELP),
    (["--samples", "0"],
     "argument --samples: expected a whole number in 1 .. 4096, got 0" + STRESS_HELP),
    (["--samples", "1"], "--samples: must be a whole number >= 2 (CMA-ES's population), got 1"),
    (["--samples", "0", "--methods", "gradient"],
     "argument --samples: expected a whole number in 1 .. 4096, got 0" + STRESS_HELP),
    (["--sigma", "-1"],
     "argument --sigma: expected a finite number in [0, 10], got -1" + STRESS_HELP),
    (["--temperature", "0"],
     "argument --temperature: expected a finite number in (0, 10], got 0" + STRESS_HELP),
    (["--temperature", "nan"],
     "argument --temperature: expected a finite number in (0, 10], got nan" + STRESS_HELP),
    (["--actor-temperature", "0"],
     "argument --actor-temperature: expected a finite number in (0, 100], got 0" + STRESS_HELP),
    (["--budget-s", "inf"],
     "argument --budget-s: expected a finite number in (0, 1e+06], got inf" + STRESS_HELP),
    (["--range", "v_ref=0:inf"], "--range 'v_ref=0:inf': LO and HI must be finite numbers"),
    (["--hybrid-draws", "0"],
     "argument --hybrid-draws: expected a whole number in 1 .. 4096, got 0" + STRESS_HELP),
    (["--hybrid-steps", "-2"],
     "argument --hybrid-steps: expected a whole number in 1 .. 4096, got -2" + STRESS_HELP),
    (["--methods", "hybrid,annealing"],
     "--methods: ['annealing']; valid: gradient, random, cmaes, hybrid, king"),
]  # fmt: skip


@pytest.mark.parametrize(
    "flags, expected", STRESS_CASES, ids=[" ".join(c[0]) for c in STRESS_CASES]
)
def test_bad_stress_options(flags, expected, tmp_path, monkeypatch):
    from lantern_jax.apps.stress import report as stress_report

    monkeypatch.setattr(stress_report, "stress_test", lambda *a, **k: pytest.fail("it ran"))
    res = run_cli(["stress", "--family", "PE", *flags, "--out", str(tmp_path / "out")])
    assert res.rc == 2 and res.err == f"lantern-jax stress: error: {expected}\n"
    assert not (tmp_path / "out").exists()


DIAGNOSTICS_CASES = [
    (["diagnostics", "distance", "--window", "inf"],
     "argument --window: expected a finite number in (0, 60], got inf"),
    (["diagnostics", "distance", "--routes", "100000"],
     "--routes 100000: suite lantern-v3 has 20 PE pairs"),
    (["diagnostics", "nonactionable", "--family", "OR"],
     "--family: the nonactionable diagnostic does not read it"),
    (["diagnostics", "nonactionable", "--routes", "2", "--window", "3"],
     "--routes, --window: the nonactionable diagnostic does not read them"),
    (["diagnostics", "language", "--family", "OR"],
     "--family: the language diagnostic does not read it"),
    (["diagnostics", "distance", "--pairs-per-family", "2"],
     "--pairs-per-family: the distance diagnostic does not read it"),
    (["wording", "--policy", "coop", "--checkpoint", "m.msgpack"],
     "--policy and --checkpoint: give one of them"),
    (["wording", "--checkpoint", ""], "--checkpoint: no checkpoint given"),
    (["diagnostics", "distance", "--checkpoint", ","], "--checkpoint: no checkpoint given"),
]  # fmt: skip


@pytest.mark.parametrize("argv, expected", DIAGNOSTICS_CASES,
                         ids=[" ".join(c[0]) for c in DIAGNOSTICS_CASES])  # fmt: skip
def test_bad_diagnostics_options(argv, expected, tmp_path, monkeypatch):
    from lantern_jax.apps import diagnostics

    for name in ("nonactionable_table", "distance_table", "wording_table", "language_table"):
        monkeypatch.setattr(diagnostics, name, lambda *a, **k: pytest.fail("it ran"))
    res = run_cli([*argv, "--out", str(tmp_path / "out")])
    assert res.rc == 2 and res.err.startswith(f"lantern-jax {argv[0]}: error: {expected}")
    assert len(res.err.splitlines()) == 1 and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------
# the program store
# ---------------------------------------------------------------------------------------------
@pytest.fixture
def store(tmp_path, monkeypatch):
    """A fresh program-store folder."""
    from lantern_jax.io import program_store

    monkeypatch.setattr(program_store, "store_dir", lambda: tmp_path)
    return tmp_path


def _fresh_program(n: int, salt: float | None = None):
    """A program no run compiled before (a random constant, unless ``salt`` is given), compiled
    for ``n`` floats: ``(salt, x, (compiled, fresh))``."""
    import jax.numpy as jnp

    from lantern_jax.io import program_store

    salt = float(np.random.default_rng().uniform(1.0, 2.0)) if salt is None else salt
    x = np.linspace(0.0, 1.0, n, dtype=np.float32)
    lowered = jax.jit(lambda v: jnp.sin(v) * salt).lower(x)  # a new function every time
    return salt, x, program_store.compile_lowered(lowered)


def test_swapped_store_entries_are_deleted_and_compiled_again(store, caplog):
    """Two entries whose files were exchanged (or one copied under another's name) used to load
    and then fail every later run until deleted by hand: each now names the program it holds."""
    from lantern_jax.io import program_store

    for key, n in (("a" * 64, 5), ("b" * 64, 7)):
        _, x, (compiled, fresh) = _fresh_program(n)
        assert fresh and program_store.save(key, compiled)
        assert np.allclose(program_store.load(key)(x), compiled(x))
    a, b = store / ("a" * 64 + ".program"), store / ("b" * 64 + ".program")
    data_a, data_b = a.read_bytes(), b.read_bytes()
    a.write_bytes(data_b)
    b.write_bytes(data_a)
    assert program_store.load("a" * 64) is None and program_store.load("b" * 64) is None
    assert not a.exists() and not b.exists()
    assert "holds program bbbbbbbbbbbb..., not aaaaaaaaaaaa... (swapped or copied" in caplog.text
    assert "compiling it again" in caplog.text


@pytest.mark.parametrize("damage", ["old-format", "flipped-bytes", "truncated"])
def test_a_broken_store_entry_is_compiled_again_from_jax_cache(damage, store, caplog):
    """A broken entry is deleted with a warning, and JAX's own persistent cache still serves the
    compilation (it did not miss because of the store)."""
    import pickle

    from lantern_jax.io import program_store

    if not jax.config.jax_enable_compilation_cache:
        pytest.skip("needs the test session's persistent compilation cache")
    key = "c" * 64
    salt, x, (compiled, fresh) = _fresh_program(6)
    assert fresh and program_store.save(key, compiled)
    path = store / (key + ".program")
    blob = path.read_bytes()
    if damage == "old-format":
        _, _, payload, in_tree, out_tree, ids = pickle.loads(blob)
        path.write_bytes(pickle.dumps((payload, in_tree, out_tree, ids)))
    elif damage == "flipped-bytes":
        record = list(pickle.loads(blob))
        record[2] = record[2][:100] + bytes(b ^ 0x5A for b in record[2][100:300]) + record[2][300:]
        path.write_bytes(pickle.dumps(tuple(record)))
    else:
        path.write_bytes(blob[: len(blob) // 2])
    assert program_store.load(key) is None and not path.exists()
    why = {
        "old-format": "not an entry of store format",
        "flipped-bytes": "does not match its SHA-256 (corrupted)",
        "truncated": "",
    }[damage]
    assert why in caplog.text and "compiling it again" in caplog.text
    _, _, (again, fresh) = _fresh_program(6, salt)
    assert not fresh  # served by JAX's persistent cache
    assert np.allclose(again(x), compiled(x))


STORE_SAVE_SCRIPT = textwrap.dedent(
    """
    import sys
    import jax, jax.numpy as jnp, numpy as np
    from lantern_jax.io import program_store
    from pathlib import Path

    folder = Path(sys.argv[1])
    program_store.store_dir = lambda: folder
    x = np.linspace(0.0, 1.0, 9, dtype=np.float32)
    compiled = jax.jit(lambda v: jnp.cos(v) * 1.25).lower(x).compile()
    print("ready", flush=True)
    sys.stdin.readline()
    for _ in range(20):
        assert program_store.save("d" * 64, compiled)
    """
)


def test_two_processes_storing_one_program_leave_one_whole_entry(store):
    env = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false")
    procs = [subprocess.Popen([sys.executable, "-c", STORE_SAVE_SCRIPT, str(store)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, cwd=ROOT, env=env)
             for _ in range(2)]  # fmt: skip
    for proc in procs:
        assert proc.stdout.readline().strip() == b"ready"
    for proc in procs:
        proc.stdin.write(b"go\n")
        proc.stdin.flush()
    for proc in procs:
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err.decode()[-2000:]
    from lantern_jax.io import program_store

    x = np.linspace(0.0, 1.0, 9, dtype=np.float32)
    assert os.listdir(store) == ["d" * 64 + ".program"]
    assert np.allclose(program_store.load("d" * 64)(x), np.cos(x) * 1.25)


def test_a_full_cache_disk_stores_nothing_and_changes_no_result(store, monkeypatch):
    from lantern_jax.io import program_store

    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(program_store, "atomic_write", full)
    _, x, (compiled, _) = _fresh_program(4)
    assert program_store.save("e" * 64, compiled) is False
    assert program_store.load("e" * 64) is None and os.listdir(store) == []


def test_a_changed_xla_flags_is_another_program(monkeypatch):
    from lantern_jax.io import program_store

    args = (np.zeros(3, np.float32),)
    identity = ("rollout", program_store.describe)  # any function of the package
    monkeypatch.setenv("XLA_FLAGS", "")
    before = program_store.program_key(identity, args)
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=true")
    assert program_store.program_key(identity, args) not in (None, before)


# ---------------------------------------------------------------------------------------------
# standard output
# ---------------------------------------------------------------------------------------------
def test_a_full_standard_output_is_one_line_and_exit_1():
    with open("/dev/full", "w") as full:
        res = run_program(["policies"], stdout=full)
    assert res.returncode == 1
    assert res.stderr == ("lantern-jax: error: cannot write to standard output (No space left on "
                          "device)\n")  # fmt: skip


def test_a_closed_pipe_ends_quietly():
    """``lantern-jax ablations --list | head -1``: the reader leaves, the command stops without
    a BrokenPipeError traceback and exits as a command stopped by SIGPIPE (141)."""
    r, w = os.pipe()
    os.close(r)
    try:
        res = run_program(["ablations", "--list"], stdout=w)
    finally:
        os.close(w)
    assert res.returncode == cli.EXIT_STDOUT_CLOSED == 141 and res.stderr == ""


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


def _plan_policies() -> list[Policy]:
    """User policies (Python API) whose plans the vehicle cannot drive: NaN, an infinite
    waypoint, 1e30 m, a plan pointing backwards at 8 m/s and the same scaled by 1e4 (a model's
    output in other units)."""
    import jax.numpy as jnp

    coop = get_policy("coop")
    ahead = jnp.stack([jnp.arange(1.0, 11.0) * 2.0, jnp.zeros(10)], axis=-1)  # 8 m/s
    plans = {
        "plan-nan": lambda params, obs: ahead * jnp.nan,
        "plan-inf": lambda params, obs: ahead.at[3, 0].set(jnp.inf),
        "plan-huge": lambda params, obs: ahead * 1e30,
        "plan-backwards": lambda params, obs: -ahead,
        "plan-backwards-x1e4": lambda params, obs: -ahead * 1e4,
    }
    return [Policy(name, coop.init, act) for name, act in plans.items()]


def test_plans_a_vehicle_cannot_drive_have_a_defined_outcome():
    """NaN, infinite and huge waypoints, and a plan faster than ``MAX_PLAN_SPEED`` (a backwards
    plan scaled by 1e4: 80 km/s), are controller faults, recorded with their time in the row
    (Route A and Route B), braking fully from the first tick; a plan pointing backwards at a
    drivable speed is driven as the controller defines it (the plan's speeds are magnitudes
    and the vehicle has no reverse gear: it drives forward at the plan's 8 m/s), with no fault;
    every row keeps the route table's schema (missing values only where it allows them)."""
    res = ev.evaluate(_plan_policies(), suite=load_suite().select(["pe_0001"]), progress=False)
    rows = res.route_table.set_index(["model", "condition"])
    for name in ("plan-nan", "plan-inf", "plan-huge", "plan-backwards-x1e4"):
        for cond in ("warning", "no-warning"):
            row = rows.loc[(name, cond)]
            assert (row["controller_fault"], row["B_controller_fault"]) == (1, 1), name
            assert row["t_fault_s"] == row["B_t_fault_s"] == pytest.approx(0.05)
            assert row["not_blocked"] == 0 and row["CUS"] == 0.0 and row["A_progress"] < 0.1
    back = rows.loc[("plan-backwards", "warning")]
    assert (back["controller_fault"], back["B_controller_fault"]) == (0, 0)
    assert back["B_progress"] == 1.0 and back["no_collision"] == 0  # drove on, into the hazard
    validate_route_table(res.route_table)  # every value within its schema's rules


# ---------------------------------------------------------------------------------------------
# the reproducibility promise (README, "Reproducibility")
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_the_written_promise_across_devices_and_batches(tmp_path):
    """What the README promises, through the command line: the same batch on the same machine
    gives the same files (the run record aside); the two-pair batch on one CPU device and split
    over two, and a pair evaluated alone on one device, keep ids, gates and discrete columns and
    stay within the stated tolerance elsewhere.  (The processes run XLA's default flags, as a
    user's do, not the tests' own.)"""
    from lantern_jax.scoring.table import compare_route_tables, read_route_table

    both_pairs = "pe_0001,lww_0001"
    runs = {"two-devices": ("2", both_pairs), "again": ("2", both_pairs),
            "one-device": ("1", both_pairs), "alone-one-device": ("1", "lww_0001")}  # fmt: skip
    for name, (devices, pairs) in runs.items():
        res = run_program(["evaluate", "--policy", "coop", "--pairs", pairs, "--quiet",
                           "--out", str(tmp_path / name)],
                          env={"LANTERN_JAX_CPU_DEVICES": devices, "XLA_FLAGS": ""})  # fmt: skip
        assert res.returncode == 0, res.stderr[-2000:]
    for n in OUTPUT_FILES:
        same = (tmp_path / "two-devices" / n).read_bytes() == (tmp_path / "again" / n).read_bytes()
        assert same == (n != RUN_RECORD_JSON), n
    both = read_route_table(tmp_path / "two-devices" / "route_level_results.csv")
    one = read_route_table(tmp_path / "one-device" / "route_level_results.csv")
    ok, report = compare_route_tables(both, one)
    assert ok, report
    alone = read_route_table(tmp_path / "alone-one-device" / "route_level_results.csv")
    ok, report = compare_route_tables(both[both["pair_id"] == "lww_0001"].reset_index(drop=True),
                                      alone)  # fmt: skip
    assert ok, report


# ---------------------------------------------------------------------------------------------
# interrupts and policy errors
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow  # compiles its own programs; run by the slow tier
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
        if "Finished jaxpr to MLIR module conversion jit(_scheduled)" in line:
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


#: Fakes of the costly parts of dataset generation (planning and recording scenes), shared by
#: the killed process and the test: chunk ``k`` of two pairs gives four one-frame sequences.
DATASET_FAKES = textwrap.dedent(
    """
    import numpy as np
    from lantern_jax.apps.dataset import generation as dataset_generate
    from lantern_jax.scenarios.suite import load_suite

    def fake_dataset(on_chunk=lambda k: None):
        pairs = load_suite().subset(1).pairs
        specs = [dataset_generate.SceneSpec(i, p.family, p.weather, p.params, p.sha256)
                 for i, p in enumerate(pairs)]
        done = []

        def record_chunk(chunk, recorder, params):
            on_chunk(len(done))
            done.append(1)
            seqs = [(s, r) for r in "AB" for s in chunk]
            ids = [f"{s.family.lower()}_{s.index:05d}_{r}" for s, r in seqs]
            cols = dict(sequence_id=np.array(ids), route=np.array([r for _, r in seqs]),
                        t_s=np.zeros(len(ids), np.float32),
                        horizon_crossing=np.zeros(len(ids), bool),
                        waypoints=np.full((len(ids), 10, 2), float(chunk[0].index), np.float32))
            rows = [dict(sequence_id=i, family=s.family, route=r, weather=s.weather,
                         pair_sha256=s.sha256, accepted=True, reason="", frames=1)
                    for i, (s, r) in zip(ids, seqs)]
            return cols, rows, {}

        dataset_generate.plan_scenes = lambda *a, **k: specs
        dataset_generate.batched_recorder = lambda *a, **k: None
        dataset_generate._record_chunk = record_chunk
    """
)

DATASET_KILL_SCRIPT = DATASET_FAKES + textwrap.dedent(
    """
    import os, signal, sys
    from lantern_jax import cli

    point, out = sys.argv[1], sys.argv[2]
    die = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)

    def on_chunk(k):
        if point == "sigint" and k == 1:
            os.kill(os.getpid(), signal.SIGINT)

    fake_dataset(on_chunk)
    real_shard, real_card, shards = dataset_generate.write_shard, dataset_generate.write_card, []

    def write_shard(path, cols):  # chunk 1's frames are written, its sequences are not
        shards.append(path)
        if point == "shard" and len(shards) == 4:
            die()
        return real_shard(path, cols)

    def write_card(folder, card):  # chunk 1's shards are written, the card is not
        if point == "card" and card["chunks_done"] == 2:
            die()
        return real_card(folder, card)

    dataset_generate.write_shard, dataset_generate.write_card = write_shard, write_card
    real = dataset_generate.generate_dataset
    dataset_generate.generate_dataset = lambda *a, **k: real(*a, **k, chunk_pairs=2)
    sys.exit(cli.main(["dataset", "--out", out, "--sequences", "12", "--quiet"]))
    """
)


@pytest.fixture(scope="module")
def dataset_reference(tmp_path_factory):
    """A complete (fake) dataset of three chunks, written without interruption."""
    from lantern_jax.apps.dataset import generation as dataset_generate

    folder = tmp_path_factory.mktemp("dataset") / "ref"
    with _dataset_fakes():
        dataset_generate.generate_dataset(folder, pairs_per_family=1, chunk_pairs=2,
                                          progress=False)  # fmt: skip
    return folder


@contextlib.contextmanager
def _dataset_fakes():
    from lantern_jax.apps.dataset import generation as dataset_generate

    saved = {n: getattr(dataset_generate, n)
             for n in ("plan_scenes", "batched_recorder", "_record_chunk")}  # fmt: skip
    scope: dict = {}
    exec(DATASET_FAKES, scope)
    scope["fake_dataset"]()
    try:
        yield
    finally:
        for n, f in saved.items():
            setattr(dataset_generate, n, f)


@pytest.mark.parametrize("point", ["shard", "card", "sigint"])
def test_an_interrupted_dataset_is_refused_then_resumed(point, dataset_reference, tmp_path):
    """kill -9 between the two shards of a chunk or before its card, or Ctrl-C while a chunk is
    recorded: training refuses the part as a dataset, naming the card and the fix, and the same
    command resumes and gives the same shards as an uninterrupted run."""
    from lantern_jax.apps.dataset import generation as dataset_generate
    from lantern_jax.apps.dataset.store import CARD_JSON, DatasetError, load_frames, read_card

    out = tmp_path / "data"
    proc = subprocess.run([sys.executable, "-c", DATASET_KILL_SCRIPT, point, str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)  # fmt: skip
    if point == "sigint":
        assert proc.returncode == 130 and "lantern-jax: interrupted" in proc.stderr
        assert "Traceback" not in proc.stderr
    else:
        assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]
    with pytest.raises(DatasetError, match=rf"{CARD_JSON}: 1 of 3 chunks recorded \(the "
                                           r"generation was interrupted\); run the same "
                                           r"'lantern-jax dataset --out "):  # fmt: skip
        load_frames(out)
    assert not [e for e in os.listdir(out) if e.endswith(".tmp")]
    with _dataset_fakes():
        dataset_generate.generate_dataset(out, pairs_per_family=1, chunk_pairs=2, progress=False)
    ref, got = read_card(dataset_reference), read_card(out)
    assert {k: v for k, v in got.items() if k != "seconds"} == {
        k: v for k, v in ref.items() if k != "seconds"}  # fmt: skip
    assert len(load_frames(out)) == len(load_frames(dataset_reference)) == 12


TRAIN_EXPORT_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    from lantern_jax import cli
    from lantern_jax.policies.learned import checkpoint
    from lantern_jax.policies.learned.checkpoint import new_model, save_model
    from lantern_jax.policies.learned.model import ModelConfig
    from lantern_jax.apps.training import behaviour_cloning as train_module

    point, config, out = sys.argv[1], sys.argv[2], sys.argv[3]
    small = ModelConfig(width=8, heads=2)
    info = dict(train_config=dict(name="mine", recipe="base"))
    real = checkpoint.atomic_write  # the writer save_model calls

    def write(path, data):  # the new weights are written, their description is not
        if str(path).endswith(".json"):
            os.kill(os.getpid(), signal.SIGKILL if point == "kill" else signal.SIGINT)
        return real(path, data)

    def train(cfg, progress=True):  # an earlier epoch's export, then the best epoch's
        save_model(new_model(small, 1), f"{out}/mine", info)
        checkpoint.atomic_write = write
        save_model(new_model(small, 2), f"{out}/mine", info)

    train_module.train = train
    sys.exit(cli.main(["train", "--config", config, "--quiet"]))
    """
)


@pytest.mark.parametrize("point", ["kill", "sigint"])
def test_an_export_cut_short_is_refused(point, tmp_path, registry):
    """kill -9 or Ctrl-C between the new weights and their description (the export of a better
    epoch): the pair no longer matches and is refused, naming the file, never loaded as the
    old description with the new weights.  (A rerun of the same config resumes from the last
    orbax checkpoint, before that epoch, and exports again.)"""
    config = tmp_path / "t.toml"
    config.write_text(f'[train]\nname = "mine"\nrecipe = "base"\nout = "{tmp_path / "run"}"\n')
    proc = subprocess.run([sys.executable, "-c", TRAIN_EXPORT_SCRIPT, point, str(config),
                           str(tmp_path / "run")], capture_output=True, text=True, cwd=ROOT,
                          timeout=300)  # fmt: skip
    if point == "sigint":
        assert proc.returncode == 130 and "lantern-jax: interrupted" in proc.stderr
        assert "Traceback" not in proc.stderr
    else:
        assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]
    weights = tmp_path / "run" / "mine.msgpack"
    res = run_cli(["evaluate", "--checkpoint", str(weights), "--out", str(tmp_path / "res")])
    assert res.rc == 2 and not (tmp_path / "res").exists()
    assert res.err == (f"lantern-jax evaluate: error: --checkpoint: {weights}: content does "
                       "not match params_sha256 of its .json\n")  # fmt: skip
    assert not [e for e in os.listdir(tmp_path / "run") if e.endswith(".tmp")]


STRESS_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    from lantern_jax import cli
    from lantern_jax.io import files
    from lantern_jax.apps.stress import report, search

    point, out = sys.argv[1], sys.argv[2]

    def stress_test(pair, policy, cfg, suite, knobs, ranges, progress=True):
        if point == "sigint":
            os.kill(os.getpid(), signal.SIGINT)
        evals = {"old": 8, "new": 16}.get(point, 12)
        trace = search.Trace(method="random", restarts=2, seconds=[0.5, 1.0],
                             evaluations=[4, evals], best_cus=[80.0, 60.0])
        return None, [trace]

    report.stress_test = stress_test
    if point == "kill":
        files.exchange = lambda a, b: os.kill(os.getpid(), signal.SIGKILL)
    sys.exit(cli.main(["stress", "--family", "PE", "--methods", "random", "--budget-s", "1",
                       "--out", out, "--quiet"]))
    """
)


def test_stress_interrupted_leaves_its_last_whole_set(tmp_path):
    """Ctrl-C during the search writes nothing; kill -9 while the results are written leaves
    the earlier complete set (comparison, failures, suite and plot are one set)."""
    from lantern_jax.apps.stress.report import RESULT_FILES

    out = tmp_path / "stress"

    def run(point: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", STRESS_SCRIPT, point, str(out)],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)  # fmt: skip

    res = run("sigint")
    assert res.returncode == 130 and "Traceback" not in res.stderr and not out.exists()
    assert run("old").returncode == 0
    before = {n: (out / n).read_bytes() for n in RESULT_FILES}
    assert run("kill").returncode == -signal.SIGKILL
    assert {n: (out / n).read_bytes() for n in RESULT_FILES} == before
    assert run("new").returncode == 0
    assert (out / "comparison.csv").read_bytes() != before["comparison.csv"]
    assert leftovers(out) == []


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
        # raised in a host callback: the callback's own error and the user's line, not the
        # runtime's wrapper around it
        ("raises-in-rollout",
         r"in the host callback: RuntimeError: no waypoints today \(at test_bad_inputs\.py:\d+\)"),
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
    assert "Traceback" not in res.err, res.err  # JAX's logged traceback is not shown
    assert not out.exists() and leftovers(out) == []


def test_a_swallowed_interrupt_still_ends_the_command_with_130(monkeypatch, tmp_path, capsys):
    """Ctrl-C raised where Python ignores exceptions (a finalizer on the way back from a long
    native call) must not let the command go on and report success."""
    import signal as signal_module

    from lantern_jax import cli
    from lantern_jax.commands import policies, runtime

    def swallowed(args, argv):
        try:
            signal_module.raise_signal(signal_module.SIGINT)
        except KeyboardInterrupt:
            pass  # what a finalizer does with it
        return 0

    monkeypatch.setattr(policies, "cmd_policies", swallowed)
    before = signal_module.getsignal(signal_module.SIGINT)
    assert cli.main(["policies"]) == 130
    assert "lantern-jax: interrupted" in capsys.readouterr().err
    assert signal_module.getsignal(signal_module.SIGINT) is before  # handler restored
    runtime._SIGINT_SEEN = True  # a stale flag from an earlier command is cleared on entry
    monkeypatch.setattr(policies, "cmd_policies", lambda args, argv: 0)
    assert cli.main(["policies"]) == 0
