"""Bad inputs, third round: a result folder is evidence, user code is a guest, and nothing the
project did not write is ever touched (see ``docs/reproducibility.md``, bad inputs).

Every case here failed before: a user file that calls ``sys.exit`` ended the tool with exit
0; ``compare`` took a tampered or truncated CSV and ignored the protocol; a user's folder named
like a result file was deleted; a negative bootstrap seed was refused only after the
evaluation; a ``Policy`` could take a registered name through the API; two families files of
one name were one module; an edited ``route_2m`` was read without a check.  The principle tests
run every numeric option of every command at a bad value (refused by argparse, before anything
is loaded) and every writing command into a folder pre-filled with user entries named like its
outputs.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import jax
import pytest

from lantern_jax import cli
from lantern_jax.commands import families as families_cmd
from lantern_jax.core.user_code import UserCodeError, as_guest

ROOT = Path(__file__).resolve().parents[1]


#: XLA compilations and persistent-cache loads of this process (JAX's monitoring events): a
#: refusal "before anything ran" adds none
_PROGRAMS = {"compiled": 0, "loaded": 0}


def _count_compile(event: str, duration: float, **_) -> None:
    if event == "/jax/core/compile/backend_compile_duration":
        _PROGRAMS["compiled"] += 1


def _count_load(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _PROGRAMS["loaded"] += 1


jax.monitoring.register_event_duration_secs_listener(_count_compile)
jax.monitoring.register_event_listener(_count_load)


def programs_so_far() -> tuple[int, int]:
    """(XLA compilations, persistent-cache loads) of this process so far."""
    return _PROGRAMS["compiled"], _PROGRAMS["loaded"]


def test_the_program_count_sees_a_compilation():
    """The count the refusal tests rely on moves when a program is compiled (or loaded)."""
    import jax.numpy as jnp

    before = sum(programs_so_far())
    jax.jit(lambda x: jnp.sin(x) * 3.25 + 0.125)(jnp.arange(7.0)).block_until_ready()
    assert sum(programs_so_far()) > before


def run_cli(argv: list[str]) -> types.SimpleNamespace:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(argv)
    return types.SimpleNamespace(rc=rc, out=out.getvalue(), err=err.getvalue())


# ---------------------------------------------------------------------------------------------
# user code is a guest
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("body, said", [
    ("import sys\nsys.exit(0)\n", "sys.exit(0)"),
    ("raise SystemExit(3)\n", "sys.exit(3)"),
    ("raise KeyboardInterrupt\n", "raised KeyboardInterrupt itself"),
    ("import argparse\nargparse.ArgumentParser().parse_args(['--nope'])\n", "sys.exit(2)"),
])  # fmt: skip
def test_a_policy_file_that_exits_is_refused_naming_the_file(tmp_path, body, said):
    path = tmp_path / "exit0.py"
    path.write_text(body)
    r = run_cli(["evaluate", "--policy", f"{path}:POLICY", "--pairs", "pe_0001", "--out",
                 str(tmp_path / "r")])  # fmt: skip
    assert r.rc == 2, r.err
    assert "exit0.py" in r.err and said in r.err
    assert not (tmp_path / "r").exists()


def test_sys_exit_named_as_a_policy_is_refused():
    r = run_cli(["evaluate", "--policy", "sys:exit", "--pairs", "pe_0001"])
    assert r.rc == 2 and "sys.exit" in r.err, r.err


def test_a_families_file_that_exits_is_refused(tmp_path):
    path = tmp_path / "fam.py"
    path.write_text("import sys\nsys.exit(3)\n")
    r = run_cli(["--families", str(path), "suite", "--list"])
    assert r.rc == 2 and "fam.py" in r.err and "sys.exit(3)" in r.err, r.err


def test_what_user_code_prints_goes_to_standard_error_named(capsys):
    def noisy():
        print("hello from the file")
        return 7

    assert as_guest("policy file x.py", noisy) == 7
    captured = capsys.readouterr()
    assert captured.out == "" and "[policy file x.py] hello from the file" in captured.err


def test_a_guest_sees_its_own_name_as_argv():
    import sys

    seen = {}
    as_guest("file", lambda: seen.setdefault("argv", list(sys.argv)), argv0="/x/my.py")
    assert seen["argv"] == ["/x/my.py"]
    with pytest.raises(UserCodeError, match="file: ValueError: bad"):
        as_guest("file", lambda: (_ for _ in ()).throw(ValueError("bad")))


def test_two_families_files_of_one_name_in_two_folders_are_two_modules(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for d in ("a", "b"):
        (tmp_path / d / "fams.py").write_text(f"ORIGIN = {d!r}\n")
    names = families_cmd.load([str(tmp_path / "a" / "fams.py"), str(tmp_path / "b" / "fams.py")])
    import sys

    assert names[0] != names[1]
    assert [sys.modules[n].ORIGIN for n in names] == ["a", "b"]
    # the same file again is the same module, imported once
    assert families_cmd.load([str(tmp_path / "a" / "fams.py")]) == names[:1]


# ---------------------------------------------------------------------------------------------
# arguments checked before anything runs
# ---------------------------------------------------------------------------------------------
def _numeric_options() -> list[tuple[str, str, str]]:
    """(command, option, converter kind) of every numeric option of every command."""
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = []
    for name, command in sorted(sub.choices.items()):
        for action in command._actions:
            kind = getattr(action.type, "__name__", "")
            if action.option_strings and kind in ("whole number", "number", "int", "float"):
                out.append((name, action.option_strings[0], kind))
    return out


NUMERIC = _numeric_options()


def test_every_numeric_option_has_a_checked_type():
    assert len(NUMERIC) >= 30
    plain = [(c, o) for c, o, k in NUMERIC if k in ("int", "float")]
    assert not plain, f"options with an unchecked int/float type: {plain}"


@pytest.mark.parametrize("command, option, kind", NUMERIC)
def test_every_numeric_option_refuses_bad_values_before_running(command, option, kind):
    bad = ["-1", str(2**70), "abc", "1e400"] + (["nan", "inf"] if kind == "number" else ["1.5"])
    for value in bad:
        before = programs_so_far()
        argv = [command, f"{option}={value}"]
        r = run_cli(argv)
        assert r.rc == 2, (argv, r.err)
        assert option in r.err, (argv, r.err)
        assert programs_so_far() == before, argv  # refused before anything was compiled


def test_a_negative_bootstrap_seed_is_refused_by_the_api_before_compiling(monkeypatch):
    from lantern_jax.apps import evaluation
    from lantern_jax.scenarios.suite import load_suite

    def refuse(*a, **k):
        raise AssertionError("evaluation started")

    monkeypatch.setattr(evaluation, "build_executions", refuse)
    for seed in (-1, 2**70, 1.5, True):
        with pytest.raises(ValueError, match="bootstrap_seed"):
            evaluation.evaluate(["coop"], suite=load_suite().subset(1), bootstrap_seed=seed,
                                progress=False)  # fmt: skip


def test_a_policy_object_cannot_take_a_registered_name(monkeypatch):
    import lantern_jax as lj
    from lantern_jax.apps import evaluation
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.scenarios.suite import load_suite

    monkeypatch.setattr(evaluation, "build_executions", lambda *a, **k: 1 / 0)
    impostor = lj.Policy("expert", init=lambda key: None, act=get_policy("ego").act)
    with pytest.raises(ValueError, match="'expert' is a registered policy's"):
        evaluation.evaluate([impostor], suite=load_suite().subset(1), progress=False)
    # the registered policy itself, as an object, is of course accepted
    evaluation._policies_to_run([get_policy("expert")], load_suite().subset(1))


# ---------------------------------------------------------------------------------------------
# a result folder is evidence
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def result_set(tmp_path_factory):
    """A real result set of two policies on one pair (written by ``evaluate``; on the split
    path, whose world program the session holds, so that only the two policies' own programs
    are compiled: what is checked here is the result folder, not the rollout)."""
    out = tmp_path_factory.mktemp("evidence") / "r"
    r = run_cli(["evaluate", "--policy", "ego,coop", "--pairs", "pe_0001", "--out", str(out),
                 "--rollout", "split", "--quiet"])  # fmt: skip
    assert r.rc == 0, r.err
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _edit_csv(path: Path, column: str, value: str) -> None:
    rows = list(csv.reader(path.open()))
    i = rows[0].index(column)
    for row in rows[1:]:
        row[i] = value
    with path.open("w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)


@pytest.mark.parametrize("value", ["500", "nan"])
def test_compare_refuses_a_tampered_route_csv(result_set, tmp_path, value):
    b = _copy(result_set, tmp_path / "b")
    _edit_csv(b / "route_level_results.csv", "CUS", value)
    r = run_cli(["compare", str(result_set), str(b), "--policy", "coop", "--out",
                 str(tmp_path / "c")])  # fmt: skip
    assert r.rc == 2 and ("SHA-256" in r.err or "bytes" in r.err), r.err
    assert not (tmp_path / "c").exists()


def test_compare_refuses_a_tampered_csv_even_when_the_manifest_is_rehashed(result_set, tmp_path):
    """A careful forger who rewrites the manifest's hash still meets the schema's range."""
    import hashlib

    b = _copy(result_set, tmp_path / "b")
    csv_path = b / "route_level_results.csv"
    _edit_csv(csv_path, "CUS", "500")
    manifest = json.loads((b / "reproducibility_manifest.json").read_text())
    raw = csv_path.read_bytes()
    for entry in manifest["files"]:
        if entry["name"] == csv_path.name:
            entry.update(sha256=hashlib.sha256(raw).hexdigest(), bytes=len(raw))
    (b / "reproducibility_manifest.json").write_text(json.dumps(manifest))
    r = run_cli(["compare", str(b), "--policy", "coop", "--policy", "ego", "--out",
                 str(tmp_path / "c")])  # fmt: skip
    assert r.rc == 2 and "CUS must lie in [0, 100]" in r.err, r.err


def test_compare_refuses_a_route_csv_cut_short(result_set, tmp_path):
    b = _copy(result_set, tmp_path / "b")
    lines = (b / "route_level_results.csv").read_text().splitlines(keepends=True)
    (b / "route_level_results.csv").write_text("".join(lines[:2]))
    r = run_cli(["compare", str(result_set), str(b), "--policy", "coop", "--out",
                 str(tmp_path / "c")])  # fmt: skip
    assert r.rc == 2 and "cut short" in r.err, r.err


def test_compare_refuses_two_protocols_unless_accepted(result_set, tmp_path):
    """A late-onset ablation run against a normal run is another protocol, not a policy
    difference: refused, or compared with the difference named above the table."""
    b = tmp_path / "late"
    r = run_cli(["evaluate", "--policy", "coop", "--pairs", "pe_0001", "--ablation",
                 "late_onset", "--out", str(b), "--rollout", "split", "--quiet"])  # fmt: skip
    assert r.rc == 0, r.err
    r = run_cli(["compare", str(result_set), str(b), "--policy", "coop", "--out",
                 str(tmp_path / "c")])  # fmt: skip
    assert r.rc == 2 and "ablation: 'none' vs 'late_onset'" in r.err, r.err
    r = run_cli(["compare", str(result_set), str(b), "--policy", "coop", "--out",
                 str(tmp_path / "c"), "--accept-protocol-difference"])  # fmt: skip
    assert r.rc == 0, r.err
    assert r.out.splitlines()[0].startswith("protocol differs (accepted): ablation")
    assert "protocol differs (accepted)" in (tmp_path / "c" / "comparison.md").read_text()


def test_compare_refuses_a_policy_or_a_set_compared_with_itself(result_set, tmp_path):
    r = run_cli(["compare", str(result_set), "--policy", "coop", "--policy", "coop"])
    assert r.rc == 2 and "compared with itself" in r.err
    r = run_cli(["compare", str(result_set), str(result_set), "--policy", "coop"])
    assert r.rc == 2 and "the same result set" in r.err


def test_compare_of_two_sets_and_two_policies_is_the_first_sets_against_the_seconds(
    result_set, tmp_path
):
    """``compare A B --policy p --policy q``: A's p against B's q, the same differences as p
    against q in one set (B a copy of A), labelled with each set; a policy named twice with
    the same set twice is refused."""
    import pandas as pd

    b = _copy(result_set, tmp_path / "b")
    one = run_cli(["compare", str(result_set), "--policy", "ego", "--policy", "coop",
                   "--out", str(tmp_path / "one")])  # fmt: skip
    two = run_cli(["compare", str(result_set), str(b), "--policy", "ego", "--policy", "coop",
                   "--out", str(tmp_path / "two")])  # fmt: skip
    assert one.rc == 0 and two.rc == 0, (one.err, two.err)
    t1 = pd.read_csv(tmp_path / "one" / "comparison.csv")
    t2 = pd.read_csv(tmp_path / "two" / "comparison.csv")
    assert (t1["n"] > 0).any()
    cols = ["condition", "family", "n", "difference", "p"]
    pd.testing.assert_frame_equal(t1[cols], t2[cols])
    assert f"ego ({result_set})" in two.out and f"coop ({b})" in two.out
    r = run_cli(["compare", str(result_set), str(result_set), "--policy", "ego", "--policy",
                 "ego", "--out", str(tmp_path / "same")])  # fmt: skip
    assert r.rc == 2 and "the same result set" in r.err


def test_compare_refuses_a_folder_without_its_manifest(result_set, tmp_path):
    b = _copy(result_set, tmp_path / "b")
    (b / "reproducibility_manifest.json").unlink()
    r = run_cli(["compare", str(b), "--policy", "coop", "--policy", "ego"])
    assert r.rc == 2 and "no reproducibility_manifest.json beside it" in r.err, r.err
    (b / "reproducibility_manifest.json").write_text("{not json")
    r = run_cli(["compare", str(b), "--policy", "coop", "--policy", "ego"])
    assert r.rc == 2 and "not a readable manifest" in r.err, r.err


# ---------------------------------------------------------------------------------------------
# nothing the project did not write is touched
# ---------------------------------------------------------------------------------------------
def _prefill(folder: Path, names) -> dict[Path, bytes]:
    """A folder of the user's: an entry named like every output (a folder holding a note),
    and a file of its own; returns every user byte."""
    folder.mkdir(parents=True)
    kept = {}
    for name in names:
        (folder / name).mkdir()
        note = folder / name / "my_notes.txt"
        note.write_text(f"keep {name}")
        kept[note] = note.read_bytes()
    mine = folder / "mine.txt"
    mine.write_text("my own file")
    kept[mine] = mine.read_bytes()
    return kept


def _all_kept(kept: dict[Path, bytes]) -> bool:
    return all(p.is_file() and p.read_bytes() == b for p, b in kept.items())


def test_a_user_folder_named_like_a_result_file_is_never_deleted(tmp_path):
    from lantern_jax.report import OUTPUT_FILES

    out = tmp_path / "res"
    kept = _prefill(out, ["family_cus.csv"])
    r = run_cli(["evaluate", "--policy", "ego", "--pairs", "pe_0001", "--out", str(out)])
    assert r.rc == 2 and "family_cus.csv is a folder" in r.err, r.err
    assert _all_kept(kept)
    assert not any((out / n).is_file() for n in OUTPUT_FILES)


@pytest.mark.parametrize("argv, names", [
    (["evaluate", "--policy", "ego", "--pairs", "pe_0001"], "OUTPUT_FILES"),
    (["ablations", "--policy", "ego", "--pairs", "pe_0001"], "ABLATION_FILES"),
    (["wording", "--policy", "coop", "--pairs-per-family", "1"], ("wording.csv", "wording.md")),
    (["stress", "--family", "PE", "--policy", "ego"], "STRESS"),
    (["diagnostics", "language", "--policy", "coop"], ("language.csv", "language.md")),
    (["diagnostics", "distance", "--policy", "coop"],
     ("distance_summary.csv", "distance_open_loop.md")),
    (["compare", "RESULT", "--policy", "coop", "--policy", "ego"],
     ("comparison.md", "comparison.csv")),
    (["unseen", "--policy", "coop"], "UNSEEN"),
    (["plot", "--policy", "ego", "--pair", "pe_0001"], ("pe_0001_ego_warning.png",)),
    (["plot", "--policy", "ego", "--pair", "pe_0001", "--condition", "route-b", "--animate"],
     ("pe_0001_ego_route-b.gif",)),
    (["dataset", "--sequences", "12"], ("plan.json", "dataset_card.json", "dataset_card.md")),
    (["train", "--config", "configs/train_coop.toml"], "TRAIN"),
])  # fmt: skip
def test_every_writing_command_keeps_the_user_entries_named_like_its_outputs(
    tmp_path, argv, names, result_set
):
    from lantern_jax.apps.stress.report import RESULT_FILES
    from lantern_jax.apps.training.behaviour_cloning import run_files
    from lantern_jax.apps.training.config import load_config
    from lantern_jax.commands.unseen import unseen_files
    from lantern_jax.report.outputs import ABLATION_FILES, OUTPUT_FILES

    train = run_files(load_config(ROOT / "configs/train_coop.toml"))
    named = {"OUTPUT_FILES": OUTPUT_FILES, "ABLATION_FILES": ABLATION_FILES,
             "STRESS": RESULT_FILES, "UNSEEN": unseen_files(), "TRAIN": train}  # fmt: skip
    names = named.get(names, names) if isinstance(names, str) else names
    argv = [str(ROOT / a) if a.startswith("configs/") else a for a in argv]
    out = tmp_path / "out"
    kept = _prefill(out, names)
    argv = [str(result_set) if a == "RESULT" else a for a in argv]
    before = programs_so_far()
    r = run_cli([*argv, "--out", str(out)])
    assert r.rc == 2 and "is a folder" in r.err, r.err
    assert programs_so_far() == before  # refused before anything was compiled or loaded
    assert _all_kept(kept)


def test_a_training_run_refuses_a_checkpoint_folder_holding_user_entries(tmp_path):
    """orbax prunes old steps in ``checkpoints/``: a user's entry there is refused up front."""
    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    note = out / "checkpoints" / "notes.txt"
    note.write_text("keep")
    before = programs_so_far()
    r = run_cli(["train", "--config", str(ROOT / "configs/train_coop.toml"), "--out", str(out)])
    assert r.rc == 2 and "notes.txt: not an orbax step of a run" in r.err, r.err
    assert programs_so_far() == before
    assert note.read_text() == "keep"


def test_report_never_replaces_a_file_or_folder_it_did_not_write(tmp_path, result_set):
    """``report --out`` over the user's own HTML file, a folder or (with ``--figures``) a file
    where the figure folder goes: one line, nothing replaced; its own page is rewritten."""
    mine = tmp_path / "page.html"
    mine.write_text("<html>my page</html>")
    r = run_cli(["report", str(result_set), "--out", str(mine)])
    assert r.rc == 2 and "is not a report this project wrote" in r.err, r.err
    assert mine.read_text() == "<html>my page</html>"
    ours = tmp_path / "ours.html"
    blocker = tmp_path / "ours_files"
    blocker.write_text("not a folder")
    r = run_cli(["report", str(result_set), "--out", str(ours), "--figures"])
    assert r.rc == 2 and "the report's figure folder is a file" in r.err, r.err
    assert blocker.read_text() == "not a folder" and not ours.exists()
    for _ in range(2):  # a page this project wrote is replaced by the next report
        r = run_cli(["report", str(result_set), "--out", str(ours), "--quiet"])
        assert r.rc == 0, r.err


def test_a_staged_set_refuses_a_user_folder_at_commit_time_too(tmp_path):
    """Writers that check no folder up front still never replace a user's entry."""
    from lantern_jax.io.files import OutputFolderError, StagedFolder, atomic_write

    out = tmp_path / "t"
    kept = _prefill(out, ["a.csv"])
    with pytest.raises(OutputFolderError, match="a.csv is a folder"):
        with StagedFolder(out, ("a.csv", "b.md")) as stage:
            atomic_write(stage.path / "a.csv", b"x")
            stage.commit()
    assert _all_kept(kept)


# ---------------------------------------------------------------------------------------------
# every field of a file is covered by a hash or checked
# ---------------------------------------------------------------------------------------------
def test_a_suite_with_an_edited_route_2m_is_refused_where_the_route_is_read():
    from lantern_jax.apps.dataset.scenes import _suite_routes
    from lantern_jax.scenarios.suite import load_suite

    suite = load_suite().select(["pe_0001", "vc_0001"])
    assert _suite_routes(suite)  # the recorded routes are the ones the parameters build
    shifted = [p.route_2m for p in suite.pairs]
    shifted[1] = [[x + 5.0, y] for x, y in shifted[1]]
    edited = dataclasses_replace_pairs(suite, shifted)
    with pytest.raises(ValueError, match="pair vc_0001: route_2m is not the route its params"):
        _suite_routes(edited)


def dataclasses_replace_pairs(suite, routes):
    import dataclasses

    pairs = [dataclasses.replace(p, route_2m=r) for p, r in zip(suite.pairs, routes, strict=True)]
    return dataclasses.replace(suite, pairs=pairs)


# ---------------------------------------------------------------------------------------------
# the partly handled cases of the third round, now one line each
# ---------------------------------------------------------------------------------------------
def _program(argv: list[str], **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lantern_jax", *argv], capture_output=True,
                          text=True, cwd=ROOT, env={**os.environ, **env}, timeout=120)  # fmt: skip


LONG_NAME = "c" * 300  # a file name over every common file system's 255 bytes


@pytest.mark.parametrize("argv, option", [
    (["evaluate", "--policy", "ego", "--out", "LONG"], "--out"),
    (["evaluate", "--policy", "ego", "--suite", "LONG.json", "--out", "OK"], "--suite"),
    (["evaluate", "--policy", "LONG.py:POLICY", "--out", "OK"], "--policy"),
    (["--families", "LONG.py", "evaluate", "--policy", "ego", "--out", "OK"], "--families"),
    (["compare", "LONG", "--policy", "coop", "--policy", "ego"], "RESULTS"),
    (["compare", "DEEP", "--policy", "coop", "--policy", "ego"], "RESULTS"),
    (["report", "LONG", "--out", "OK.html"], "RESULTS"),
    (["dataset", "--out", "LONG"], "--out"),
    (["stress", "--family", "PE", "--policy", "ego", "--out", "LONG"], "--out"),
    (["suite", "--regenerate", "LONG.json"], "--regenerate"),
])  # fmt: skip
def test_a_path_too_long_for_the_file_system_is_one_line_before_anything_runs(
    tmp_path, argv, option
):
    """A name over NAME_MAX (or a path over PATH_MAX) in any path option: one line naming the
    option and the path's start, exit 2, nothing compiled (a traceback before)."""
    deep = str(tmp_path / ("d/" * 2100))
    subs = {"LONG": str(tmp_path / LONG_NAME), "DEEP": deep, "OK": str(tmp_path / "ok")}
    argv = [next((a.replace(k, v, 1) for k, v in subs.items() if a.startswith(k)), a)
            for a in argv]  # fmt: skip
    before = programs_so_far()
    r = run_cli(argv)
    assert r.rc == 2 and r.err.count("\n") == 1, r.err
    assert f"error: {option}: " in r.err and "too long a path" in r.err, r.err
    assert "characters)" in r.err  # the path's start, not all of it
    assert programs_so_far() == before


def test_a_path_too_long_from_a_config_file_is_one_line(tmp_path):
    """A path from a config file (not an option) that the file system refuses: one line."""
    cfg = tmp_path / "long.toml"
    cfg.write_text(f'[evaluate]\nout = "{tmp_path / LONG_NAME}"\npairs = ["pe_0001"]\n')
    r = run_cli(["evaluate", "--config", str(cfg), "--policy", "ego"])
    assert r.rc == 2 and r.err.count("\n") == 1, r.err
    assert "too long a path for the file system" in r.err, r.err


def test_a_backend_that_cannot_start_is_one_line_naming_the_variable(tmp_path):
    r = _program(["evaluate", "--policy", "ego", "--pairs", "pe_0001", "--out",
                  str(tmp_path / "r"), "--quiet"], JAX_PLATFORMS="tpu")  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "JAX_PLATFORMS='tpu'" in r.stderr, r.stderr


def test_the_unseen_suite_without_its_families_is_refused_naming_families():
    code = ("from lantern_jax.scenarios.suite import load_suite\n"
            "try:\n    load_suite('lantern-unseen')\n"
            "except ValueError as e:\n    print(e)")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)  # fmt: skip
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1 and "--families lantern_jax.scenarios.unseen" in lines[0], r.stdout


def test_evaluate_refuses_a_suite_holding_one_pair_twice_before_building(monkeypatch):
    import dataclasses

    from lantern_jax.apps import evaluation
    from lantern_jax.scenarios.suite import load_suite

    monkeypatch.setattr(evaluation, "build_executions", lambda *a, **k: 1 / 0)
    suite = load_suite().select(["pe_0001"])
    twice = dataclasses.replace(suite, pairs=[*suite.pairs, *suite.pairs])
    with pytest.raises(ValueError, match=r"holds pair\(s\) \['pe_0001'\] more than once"):
        evaluation.evaluate(["ego"], suite=twice, progress=False)


def test_jax_64_bit_mode_is_refused_by_name(monkeypatch):
    import jax

    from lantern_jax.apps import evaluation

    monkeypatch.setattr(evaluation, "build_executions", lambda *a, **k: 1 / 0)
    jax.config.update("jax_enable_x64", True)
    try:
        with pytest.raises(ValueError, match="64-bit mode is on"):
            evaluation.evaluate(["coop"], progress=False)
    finally:
        jax.config.update("jax_enable_x64", False)


@pytest.mark.parametrize("rng, says", [
    ("FloatRange(5.0, 1.0)", "empty interval"),
    ("FloatRange(0.0, float('nan'))", "bounds must be finite"),
    ("Choice(())", "a choice of no option"),
])  # fmt: skip
def test_a_family_with_an_empty_or_nan_range_is_refused_when_registered(rng, says):
    import dataclasses

    import family_example  # the cyclist example family (tests/family_example.py)

    from lantern_jax.scenarios import registry
    from lantern_jax.scenarios.spec import Choice, FloatRange  # noqa: F401  (in rng's text)

    record = family_example.RECORD
    bad = dataclasses.replace(record, code="ZZQ", ranges={**record.ranges, "extra": eval(rng)})
    with pytest.raises(ValueError, match=f"ranges\\['extra'\\]: {says}"):
        registry._check_record(bad)


def test_a_vector_environment_of_a_fractional_size_is_refused():
    pytest.importorskip("brax")
    from lantern_jax.apps.envs.vector import LanternVectorEnv

    with pytest.raises(TypeError, match="num_envs must be a whole number, got 1.7"):
        LanternVectorEnv(num_envs=1.7)


def test_a_temporary_file_left_by_a_killed_writer_is_removed_by_the_next_write(tmp_path):
    from lantern_jax.io.files import atomic_write

    stale = tmp_path / ".out.csv.999999999.abcd1234.tmp"  # a process id that is not running
    stale.write_bytes(b"half")
    live = tmp_path / f".out.csv.{os.getpid()}.efgh5678.tmp"  # this process: kept
    live.write_bytes(b"mine")
    atomic_write(tmp_path / "out.csv", b"whole")
    assert not stale.exists() and live.exists()
    assert (tmp_path / "out.csv").read_bytes() == b"whole"


def test_a_ppo_checkpoint_variable_naming_junk_is_one_message(tmp_path, monkeypatch):
    from lantern_jax.policies import learned_ppo

    junk = tmp_path / "junk.msgpack"
    junk.write_bytes(b"not msgpack at all")
    monkeypatch.setenv(learned_ppo.CHECKPOINT_ENV, str(junk))
    with pytest.raises(ValueError, match="from LANTERN_JAX_PPO_CHECKPOINT.*not a PPO checkpoint"):
        learned_ppo.load_checkpoint()


def test_the_environment_without_brax_names_the_extra(monkeypatch):
    """``import lantern_jax.apps.envs`` on the plain install (no brax) says which extra to
    install."""
    envs = [m for m in sys.modules if m.split(".")[:3] == ["lantern_jax", "apps", "envs"]]
    for name in envs:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "brax", None)
    says = r"needs the 'rl' extra: pip install -e '\.\[rl\]'"
    with pytest.raises(ModuleNotFoundError, match=says):
        import lantern_jax.apps.envs  # noqa: F401


def test_a_family_code_clash_with_the_unseen_hazards_is_one_line(tmp_path):
    fams = tmp_path / "clash.py"
    fams.write_text(
        "import dataclasses, sys\n"
        f"sys.path.insert(0, {str(ROOT / 'tests')!r})\n"
        "import family_example\n"
        "from lantern_jax.scenarios.registry import register_family\n"
        "register_family(dataclasses.replace(family_example.RECORD, code='CYC'))\n"
    )
    r = _program(["--families", str(fams), "unseen", "--policy", "ego", "--out",
                  str(tmp_path / "u")])  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "CYC" in r.stderr, r.stderr
