"""The ``lantern-jax`` command line on a two-pair suite (one PE pair, one LWW pair).

The evaluation batch has the same shape as the one in ``test_evaluate.py``, so in one pytest
process both modules share one compiled rollout.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import shutil
import subprocess
import sys
import types

import jax
import pandas as pd
import pytest

from lantern_jax import cli
from lantern_jax.apps.evaluation import ablation_names, params_hash
from lantern_jax.commands import runtime
from lantern_jax.commands.suite import suite_to_manifest
from lantern_jax.core.constants import FAMILIES
from lantern_jax.policies.registry import get_policy, policy_names
from lantern_jax.report import OUTPUT_FILES
from lantern_jax.scenarios.suite import load_suite, write_manifest
from lantern_jax.scoring import uncertainty
from lantern_jax.scoring.aggregate import DECOMPOSITION_COLUMNS
from lantern_jax.scoring.table import read_route_table, schema_columns, validate_route_table
from lantern_jax.scoring.uncertainty import interval_columns

PAIRS = ["pe_0001", "lww_0001"]


def run_cli(argv: list[str]) -> types.SimpleNamespace:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(argv)
    return types.SimpleNamespace(rc=rc, out=out.getvalue(), err=err.getvalue())


@pytest.fixture(scope="module")
def manifest_path(tmp_path_factory):
    suite = load_suite().select(PAIRS)
    path = tmp_path_factory.mktemp("suite") / "two-pairs.json"
    write_manifest(suite_to_manifest(suite, "two-pairs"), path)
    return path


@pytest.fixture(scope="module")
def evaluated(manifest_path, tmp_path_factory):
    out_dir = tmp_path_factory.mktemp("results")
    argv = ["evaluate", "--policy", "coop", "--suite", str(manifest_path)]
    argv += ["--pairs-per-family", "1", "--out", str(out_dir)]
    res = run_cli(argv)
    res.out_dir = out_dir
    return res


def test_evaluate_exits_zero_and_writes_every_file(evaluated):
    assert evaluated.rc == 0, evaluated.err
    for name in OUTPUT_FILES:
        assert (evaluated.out_dir / name).is_file(), name


def test_route_csv(evaluated):
    path = evaluated.out_dir / "route_level_results.csv"
    header = path.read_text().splitlines()[0].split(",")
    assert header == [c for c, _ in schema_columns()]
    df = validate_route_table(read_route_table(path))
    assert len(df) == 2 * 2
    assert set(zip(df["condition"], df["pair_id"], strict=True)) == {
        (c, p) for c in ("warning", "no-warning") for p in PAIRS
    }
    assert set(df["model"]) == {"coop"}
    # Route B efficiency: every route completed, so every pair has its time
    assert (df["B_time_s"] > 0).all() and (df["B_slow_s"] >= 0).all()
    schema = json.loads((evaluated.out_dir / "route_level_results.schema.json").read_text())
    assert [c["name"] for c in schema["columns"]] == header


def test_family_and_decomposition_csv(evaluated):
    def with_intervals(columns):
        return [x for c in columns for x in (c, *interval_columns(c))]

    fam = pd.read_csv(evaluated.out_dir / "family_cus.csv")
    assert list(fam.columns) == ["model", "condition", *with_intervals([*FAMILIES, "Overall"])]
    assert list(fam["condition"]) == ["warning", "no-warning", "warning gain"]
    gain = fam.iloc[2]
    assert gain["PE"] == pytest.approx(fam.iloc[0]["PE"] - fam.iloc[1]["PE"], abs=2e-6)
    # one PE and one LWW pair: a degenerate interval at the estimate, n = 1, 0 elsewhere
    assert gain["PE_lo"] == pytest.approx(gain["PE"], abs=2e-6)
    assert gain["PE_hi"] == pytest.approx(gain["PE"], abs=2e-6)
    assert list(fam.loc[0, [f"{f}_n" for f in FAMILIES]]) == [1, 0, 0, 1, 0, 0]
    assert fam.loc[0, "Overall_n"] == 2 and math.isnan(fam.loc[0, "VC_lo"])
    dec = pd.read_csv(evaluated.out_dir / "decomposition.csv")
    assert list(dec.columns) == ["model", "condition", *with_intervals(DECOMPOSITION_COLUMNS)]
    assert list(dec["condition"]) == ["warning", "no-warning"]
    md = (evaluated.out_dir / "family_cus.md").read_text()
    assert "| Model (condition)" in md and "coop (warning gain)" in md
    assert "PE n=1" in md and "*" in md  # n per column, cells of fewer than MIN_N pairs flagged


def test_manifest(evaluated, manifest_path):
    m = json.loads((evaluated.out_dir / "reproducibility_manifest.json").read_text())
    suite = load_suite(manifest_path)
    assert m["suite_sha256"] == suite.suite_sha256
    assert m["suite_id"].startswith("two-pairs")
    assert m["ablation"] == "none"
    assert {"jax", "jaxlib", "numpy", "pandas", "python"} <= set(m["packages"])
    coop = get_policy("coop")
    assert m["policies"][0]["name"] == "coop"
    assert m["policies"][0]["params_sha256"] == params_hash(coop.init(jax.random.PRNGKey(0)))
    record = json.loads((evaluated.out_dir / "run_record.json").read_text())
    assert record["command"].startswith("lantern-jax evaluate --policy coop")
    assert record["policies"][0]["name"] == "coop" and record["policies"][0]["seconds_run"] > 0
    assert "command" not in m and "seconds_run" not in m["policies"][0]
    assert m["intervals"]["seed"] == uncertainty.SEED
    assert m["intervals"]["confidence"] == uncertainty.CONFIDENCE
    listed = {f["name"]: f["sha256"] for f in m["files"]}
    assert set(listed) == set(OUTPUT_FILES) - {"reproducibility_manifest.json", "run_record.json"}
    for name, digest in listed.items():
        assert hashlib.sha256((evaluated.out_dir / name).read_bytes()).hexdigest() == digest


def _shipped_text() -> str:
    from lantern_jax.core.constants import SUITE_ID
    from lantern_jax.scenarios.suite import _shipped_path

    return _shipped_path(SUITE_ID).read_text()


def test_printed_tables(evaluated):
    out = evaluated.out
    for word in ("Model (condition)", *FAMILIES, "Overall", *DECOMPOSITION_COLUMNS):
        assert word in out, word
    for label in ("hidden at the warning point", "hidden for the whole approach",
                  "Route A executions"):  # fmt: skip
        assert label in out, label
    assert "coop (warning gain)" in out and "coop (no-warning)" in out
    for name in OUTPUT_FILES:
        assert name in out
    assert "[lantern-jax] loading suite" in evaluated.err


def test_pairs_option_gives_the_same_rows(evaluated, tmp_path):
    """Also: ``--profile`` prints where the time went and changes no file."""
    res = run_cli(
        ["evaluate", "--policy", "coop", "--pairs", ",".join(PAIRS), "--out", str(tmp_path)]
        + ["--quiet", "--profile"]
    )
    assert res.rc == 0, res.err
    assert "[lantern-jax]" not in res.err
    assert "Where the time went" not in evaluated.out
    profile = res.out.split("Where the time went", 1)[1]
    for label in ("imports", "suite load", "world build (6 executions)", "policy coop",
                  "trace + lower", "XLA compile", "rollout", "scoring", "tables",
                  "writing the result files", "printing the tables", "total"):  # fmt: skip
        assert label in profile, label
    total = float(profile.splitlines()[-1].split()[1])
    rows = [ln for ln in profile.splitlines()[1:-2] if not ln.startswith(" ")]
    assert sum(float(ln.rsplit(None, 3)[1]) for ln in rows) <= total + 0.05
    name = "route_level_results.csv"
    assert (tmp_path / name).read_bytes() == (evaluated.out_dir / name).read_bytes()


def test_compare_a_policy_against_itself_gives_zero_with_p_one(evaluated, tmp_path):
    """A copy of a result set (one policy in two identical result sets over the same pairs);
    the same folder given twice is refused as a comparison with itself."""
    copy = tmp_path / "copy"
    shutil.copytree(evaluated.out_dir, copy)
    res = run_cli(["compare", str(evaluated.out_dir), str(evaluated.out_dir), "--policy", "coop",
                   "--out", str(tmp_path / "same")])  # fmt: skip
    assert res.rc == 2 and "the same result set" in res.err
    res = run_cli(["compare", str(evaluated.out_dir), str(copy), "--policy", "coop",
                   "--out", str(tmp_path)])  # fmt: skip
    assert res.rc == 0, res.err
    table = pd.read_csv(tmp_path / "comparison.csv")
    assert set(table["condition"]) == {"warning", "no-warning", "warning gain"}
    shared = table[table["n"] > 0]
    assert (shared["difference"] == 0.0).all() and (shared["p"] == 1.0).all()
    assert set(table.loc[table["family"] == "Overall", "n"]) == {len(PAIRS)}
    md = (tmp_path / "comparison.md").read_text()
    assert md.startswith("# Paired comparison of mean CUS") and "| Condition" in md
    assert "1.000" in res.out


def test_compare_refuses_a_bad_selection_and_other_suites(evaluated, tmp_path):
    res = run_cli(["compare", str(evaluated.out_dir), "--policy", "coop"])
    assert res.rc == 2 and "two --policy names" in res.err
    res = run_cli(["compare", str(evaluated.out_dir), "--policy", "coop", "--policy", "expert"])
    assert res.rc == 2 and "'expert': not in" in res.err
    res = run_cli(["compare", str(tmp_path), "--policy", "coop", "--policy", "ego"])
    assert res.rc == 2 and "no result set there" in res.err
    other = tmp_path / "other"
    shutil.copytree(evaluated.out_dir, other)
    manifest = other / "reproducibility_manifest.json"
    m = json.loads(manifest.read_text())
    m["suite_sha256"] = "0" * 64
    manifest.write_text(json.dumps(m))
    res = run_cli(["compare", str(evaluated.out_dir), str(other), "--policy", "coop",
                   "--out", str(tmp_path / "cmp")])  # fmt: skip
    assert res.rc == 2 and "not run under one protocol (suite_sha256:" in res.err


def test_fresh_suites_evaluate_every_suite_and_report_the_spread(
    manifest_path, tmp_path, monkeypatch
):
    """``--fresh-suites``: generation is replaced by the two-pair suite re-labelled with the
    requested seed (the orchestration, files and records are what is tested; the generator
    has its own tests), so every suite holds the same pairs and the spread across suites is 0."""
    import lantern_jax.apps.suite_generation as generate

    base = load_suite(manifest_path)
    calls = []

    def fake_generate(seed, progress=True, validator="expert"):
        calls.append((seed, validator))
        return dict(suite_to_manifest(base), seed=seed)

    monkeypatch.setattr(generate, "generate_suite", fake_generate)
    argv = ["evaluate", "--policy", "coop", "--suite", str(manifest_path), "--quiet",
            "--fresh-suites", "2", "--seed", "500", "--out", str(tmp_path)]  # fmt: skip
    res = run_cli(argv)
    assert res.rc == 0, res.err
    assert calls == [(500, "expert-v1"), (501, "expert-v1")]  # the base suite's validator
    record = json.loads((tmp_path / "across_suites.json").read_text())
    ids = [s["suite_id"] for s in record["suites"]]
    assert ids == ["two-pairs", "lantern-v3-seed500", "lantern-v3-seed501"]
    assert [s["suite_seed"] for s in record["suites"][1:]] == [500, 501]
    assert {s["suite_sha256"] for s in record["suites"]} == {base.suite_sha256}
    for sid in ids:
        assert (tmp_path / sid / "family_cus.csv").is_file(), sid
    across = pd.read_csv(tmp_path / "across_suites.csv")
    assert (across["suites"] == 3).all()
    assert across["Overall_sd"].abs().max() == pytest.approx(0.0, abs=1e-9)
    assert "Per-family CUS across 3 suites" in res.out
    # a second run loads the written manifests instead of generating them again
    calls.clear()
    assert run_cli(argv).rc == 0 and calls == []
    res = run_cli(["evaluate", "--policy", "coop", "--suite", str(manifest_path),
                   "--fresh-suites", "1", "--out", str(tmp_path)])  # fmt: skip
    assert res.rc == 2 and "needs --seed" in res.err
    res = run_cli(["evaluate", "--policy", "coop", "--seed", "3", "--out", str(tmp_path)])
    assert res.rc == 2 and "--fresh-suites" in res.err


def test_unknown_policy_exits_2_listing_names(capsys):
    assert cli.main(["evaluate", "--policy", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "nosuch" in err
    for name in policy_names():
        assert name in err


def test_unknown_ablation_exits_2_listing_names(capsys):
    assert cli.main(["evaluate", "--policy", "coop", "--ablation", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "nosuch" in err
    for name in ablation_names():
        assert name in err


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--pairs", "xx_0001"],
        ["evaluate", "--pairs-per-family", "0"],
        ["evaluate", "--suite", "no-such-suite"],
        ["evaluate", "--bogus"],
        [],
    ],
)
def test_usage_errors_exit_2(argv, capsys):
    assert cli.main(argv) == 2
    assert capsys.readouterr().err


def test_suite_list(capsys):
    suite = load_suite()
    assert cli.main(["suite", "--list"]) == 0
    out = capsys.readouterr().out
    assert suite.suite_sha256 in out
    assert "expert pass rate" in out
    for p in suite.pairs:
        assert p.pair_id in out and p.sha256[:12] in out


def test_suite_list_of_a_manifest(manifest_path, capsys):
    assert cli.main(["suite", "--suite", str(manifest_path)]) == 0
    out = capsys.readouterr().out
    assert "two-pairs: 2 pairs" in out
    assert all(p in out for p in PAIRS)


def test_policies_and_ablations(capsys):
    assert cli.main(["policies"]) == 0
    out = capsys.readouterr().out
    for name in policy_names():
        assert name in out
    assert cli.main(["ablations"]) == 0
    out = capsys.readouterr().out
    for name in ablation_names():
        assert name in out


def test_ablations_list_and_bad_policy(capsys):
    assert cli.main(["ablations", "--list"]) == 0
    out = capsys.readouterr().out
    for name in ablation_names():
        assert name in out
    res = run_cli(["ablations", "--policy", "nope"])
    assert res.rc == 2 and "unknown policy 'nope'" in res.err


def test_ablations_table_command(manifest_path, tmp_path):
    """``lantern-jax ablations --policy coop`` runs the six protocol variants, prints the
    paper's table and writes it (same batch shape as ``evaluated``: one compile)."""
    from lantern_jax.apps.ablation_table import TABLE_COLUMNS
    from lantern_jax.report import ABLATION_FILES
    from lantern_jax.scenarios.protocol_variants import ABLATIONS

    out_dir = tmp_path / "abl"
    res = run_cli(["ablations", "--policy", "coop", "--suite", str(manifest_path),
                   "--out", str(out_dir), "--quiet"])  # fmt: skip
    assert res.rc == 0, res.err
    for name in ABLATION_FILES:
        assert (out_dir / name).is_file(), name
    for ablation in ABLATIONS:
        assert ablation.label in res.out
    for col in TABLE_COLUMNS:
        assert col in res.out
    table = pd.read_csv(out_dir / "ablations.csv")
    with_intervals = [x for c in TABLE_COLUMNS for x in (c, *interval_columns(c))]
    assert list(table.columns) == ["model", "condition", "variant", "label", *with_intervals]
    assert (table["CUS_n"] == len(PAIRS)).all() and "Pairs" in res.out
    warned = table[table["condition"] == "warning"].set_index("variant")
    assert list(warned.index) == [a.name for a in ABLATIONS]
    assert warned.loc["none", "Event Exp."] == 100.0
    # late onset: the warning arrives with the event, nothing to anticipate with
    assert warned.loc["late_onset", "Ant."] <= warned.loc["none", "Ant."]
    routes = validate_route_table(read_route_table(out_dir / "ablation_route_level_results.csv"))
    assert set(routes["condition"]) == {
        c if v == "none" else f"{c}:{v}"
        for c in ("warning", "no-warning")
        for v in (a.name for a in ABLATIONS)
    }


def test_python_dash_m():
    res = subprocess.run(
        [sys.executable, "-m", "lantern_jax", "ablations"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    assert "late_onset" in res.stdout


@pytest.mark.slow
def test_suite_regenerates(tmp_path, capsys, monkeypatch):
    """``--regenerate`` and ``--verify`` together generate the suite once: the manifest just
    written is the one compared with the shipped suite."""
    from lantern_jax.apps import suite_generation as generate

    calls, real = [], generate.generate_suite
    monkeypatch.setattr(generate, "generate_suite",
                        lambda *a, **k: calls.append(a) or real(*a, **k))  # fmt: skip
    path = tmp_path / "fresh.json"
    assert cli.main(["suite", "--regenerate", str(path), "--verify", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "OK: lantern-v3" in out
    assert len(calls) == 1
    fresh, shipped = load_suite(path), load_suite()
    assert fresh.suite_sha256 == shipped.suite_sha256
    assert [p.route_2m for p in fresh.pairs] == [p.route_2m for p in shipped.pairs]
    assert path.read_text() == _shipped_text()  # the whole manifest, bit for bit


def test_verify_reuses_a_generation_only_of_the_suite_s_own_seed_and_validator():
    from lantern_jax.apps.suite_generation import DEFAULT_SEED, regenerates_suite, suite_validator

    own = suite_validator(load_suite().report)
    assert regenerates_suite("lantern-v3", DEFAULT_SEED, own)
    assert not regenerates_suite("lantern-v3", DEFAULT_SEED + 1, own)
    assert not regenerates_suite("lantern-v3", DEFAULT_SEED, "coop")


def test_shipped_configs_parse_and_bad_configs_name_the_field(tmp_path):
    """Every file in configs/ is a valid experiment; a bad key or type is named in the error."""
    from pathlib import Path

    from lantern_jax.commands import UsageError
    from lantern_jax.commands.evaluate import CONFIG_KEYS, load_config

    root = Path(__file__).resolve().parents[1] / "configs"
    # training configs (train_*.toml, a [train] table) are checked by tests/test_learned.py
    files = [f for f in sorted(root.glob("*.toml")) if not f.name.startswith("train_")]
    assert files, "configs/ holds the experiment files"
    for f in files:
        cfg = load_config(str(f))
        assert set(cfg) <= set(CONFIG_KEYS), f.name
    bad = tmp_path / "bad.toml"
    bad.write_text('[evaluate]\npairs_per_family = "two"\n')
    with pytest.raises(UsageError, match="pairs_per_family must be int"):
        load_config(str(bad))
    bad.write_text('[evaluate]\nablaton = "none"\n')
    with pytest.raises(UsageError, match="unknown key 'ablaton'"):
        load_config(str(bad))


# ---------------------------------------------------------------------------------------------
# language commands: wording, diagnostics
# ---------------------------------------------------------------------------------------------
def test_wording_command(manifest_path, tmp_path):
    """Same batch shape as ``evaluate`` above: the compiled rollout is shared."""
    res = run_cli(["wording", "--policy", "coop", "--suite", str(manifest_path),
                   "--out", str(tmp_path), "--quiet"])  # fmt: skip
    assert res.rc == 0, res.err
    assert "Low ambiguity" in res.out and "All tiers" in res.out and "Retention" in res.out
    table = pd.read_csv(tmp_path / "wording.csv")
    values = ["Paraphrase CUS", "Matched canonical", "Retention (%)", "Coll. (%)",
              "Matched no-warning"]  # fmt: skip
    bounds = [x for c in values for x in interval_columns(c)[:2]]
    assert list(table.columns) == ["Wording", "n", *values, *bounds]
    held = table[table["n"] > 0]  # a tier may hold none of the two pairs
    assert (held["Paraphrase CUS_lo"] <= held["Paraphrase CUS"] + 0.05).all()  # CSV: 4 digits
    assert table["n"].iloc[-1] == len(PAIRS)
    # coop ignores paraphrases: the paraphrase CUS is the no-warning CUS (CSV keeps 4 digits)
    all_tiers = table.iloc[-1]
    assert all_tiers["Paraphrase CUS"] == pytest.approx(all_tiers["Matched no-warning"], rel=1e-3)
    assert (tmp_path / "wording.md").read_text().startswith("# Warning wording by ambiguity")


@pytest.mark.slow
def test_diagnostics_commands(shared_runner, tmp_path):
    res = run_cli(["diagnostics", "nonactionable", "--out", str(tmp_path), "--quiet"])
    assert res.rc == 0, res.err
    assert "Caution: maintenance equipment is operating behind the roadside barrier." in res.out
    na = pd.read_csv(tmp_path / "nonactionable.csv")
    assert len(na) == 6 and (na["Non-actionable"].iloc[1:] == "yes").all()
    res = run_cli(["diagnostics", "distance", "--routes", "2", "--out", str(tmp_path), "--quiet"])
    assert res.rc == 0, res.err
    assert "(12.0, 0.5)" in res.out and "(100.0, 0.5)" in res.out
    dist = pd.read_csv(tmp_path / "distance.csv")
    assert list(dist["pair"]) == ["pe_0001", "pe_0002"]
    assert len(pd.read_csv(tmp_path / "distance_closed_loop.csv")) == 6
    assert (tmp_path / "nonactionable.csv").exists()  # an earlier set in the folder is kept


@pytest.mark.parametrize(
    "argv",
    [
        ["wording", "--policy", "nosuch"],
        ["wording", "--policy", "coop,ego"],
        ["wording", "--pairs-per-family", "0"],
        ["diagnostics", "nope"],
        ["diagnostics", "distance", "--family", "XX"],
        ["diagnostics", "distance", "--routes", "0"],
        ["diagnostics", "distance", "--window", "0"],
        ["diagnostics", "nonactionable", "--policy", "nosuch"],
    ],
)
def test_language_usage_errors_exit_2(argv, capsys):
    assert cli.main(argv) == 2
    assert capsys.readouterr().err


@pytest.mark.slow
def test_nonactionable_command_end_to_end(tmp_path):
    """The command with its own compiled runner (``diagnostics.run_recorded``)."""
    res = run_cli(["diagnostics", "nonactionable", "--policy", "coop", "--out", str(tmp_path)])
    assert res.rc == 0, res.err
    na = pd.read_csv(tmp_path / "nonactionable.csv")
    assert (na["dv_max (m/s)"] == 0.0).all() and (na["RC (%)"] == 100.0).all()


def test_compile_cache_folder_environment_and_flag(tmp_path, monkeypatch):
    import jax

    before = (jax.config.jax_enable_compilation_cache, jax.config.jax_compilation_cache_dir)
    monkeypatch.delenv(runtime.CACHE_DIR_ENV, raising=False)
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    try:
        assert runtime.compile_cache_dir() == str(tmp_path / "lantern-jax" / "jax")
        monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "jax-own"))
        assert runtime.compile_cache_dir() == str(tmp_path / "jax-own")
        monkeypatch.setenv(runtime.CACHE_DIR_ENV, str(tmp_path / "moved"))  # ours wins
        assert runtime.configure_compile_cache(True) == str(tmp_path / "moved")
        assert jax.config.jax_enable_compilation_cache
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "moved")
        assert runtime.configure_compile_cache(False) is None
        assert not jax.config.jax_enable_compilation_cache
    finally:
        jax.config.update("jax_enable_compilation_cache", before[0])
        jax.config.update("jax_compilation_cache_dir", before[1])
    parser = cli.build_parser()
    for cmd in ("evaluate", "suite"):
        assert parser.parse_args([cmd, "--no-compile-cache"]).no_compile_cache
        assert not parser.parse_args([cmd]).no_compile_cache


@pytest.mark.slow
def test_evaluate_fills_the_compile_cache_unless_told_not_to(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), LANTERN_JAX_CPU_DEVICES="1")
    # the split path: its world and policy programs compile in about 12 s against the fused
    # program's 17 s (2-core CPU); where the cache is kept does not depend on the path
    base = [sys.executable, "-m", "lantern_jax", "evaluate", "--policy", "ego", "--quiet",
            "--pairs", "pe_0001", "--rollout", "split"]  # fmt: skip
    cache = tmp_path / "xdg" / "lantern-jax" / "jax"
    subprocess.run([*base, "--no-compile-cache", "--out", str(tmp_path / "a")], env=env,
                   check=True, capture_output=True)  # fmt: skip
    assert not cache.exists()
    subprocess.run([*base, "--out", str(tmp_path / "b")], env=env, check=True,
                   capture_output=True)  # fmt: skip
    assert any(cache.iterdir())
