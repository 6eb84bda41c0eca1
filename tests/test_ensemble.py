"""Ensembles of learned models (``lantern_jax.policies.learned.ensemble``): the mean plan of the
members, one compiled act for every ensemble of an architecture, differentiable in every
member's weights, and members that cannot be averaged refused by name."""

from __future__ import annotations

import os
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.policies.learned.checkpoint import (
    CheckpointError,
    model_policy,
    new_model,
    save_model,
)
from lantern_jax.policies.learned.ensemble import ensemble_act, ensemble_policy
from lantern_jax.policies.learned.model import ModelConfig
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite

SMALL = ModelConfig(width=16, heads=2)


def tiny(name: str, seed: int, embedding, config: ModelConfig = SMALL):
    return model_policy(name, new_model(config, seed=seed), embedding=embedding)


def plan(policy, obs) -> np.ndarray:
    return np.asarray(jax.jit(policy.act)(policy.init(jax.random.PRNGKey(0)), obs))


def test_the_plan_is_the_mean_of_the_members_plans(obs, embedding):
    members = [tiny(f"m{i}", i, embedding) for i in range(2)]
    ens = ensemble_policy("ens", members)
    plans = [plan(m, obs) for m in members]
    assert not np.allclose(plans[0], plans[1])  # the members differ, so the mean is a test
    np.testing.assert_allclose(plan(ens, obs), (plans[0] + plans[1]) / 2, rtol=1e-5, atol=1e-5)
    assert ens.sensors == members[0].sensors and not ens.stateful
    assert "m0, m1" in ens.description


def test_the_median_plan_is_each_coordinates_middle_member(obs, embedding):
    """``combine="median"``: with three members, every coordinate of every waypoint is the
    middle one of the three plans' (their element-wise median), not their mean; any other
    combine is refused naming it."""
    members = [tiny(f"m{i}", i, embedding) for i in range(3)]
    ens = ensemble_policy("med", members, combine="median")
    plans = np.stack([plan(m, obs) for m in members])  # (3, 10, 2)
    middle = np.sort(plans, axis=0)[1]
    assert not np.allclose(middle, plans.mean(axis=0), atol=1e-4)  # the median is a test
    np.testing.assert_allclose(plan(ens, obs), middle, rtol=1e-5, atol=1e-5)
    assert ens.description.startswith("median plan of 3 models")
    with pytest.raises(ValueError, match="is not one of mean, median, medoid, slowest"):
        ensemble_policy("bad", members, combine="vote")


def test_the_medoid_plan_is_one_members_plan_nearest_the_others(obs, embedding):
    """``combine="medoid"``: hand-built plans -- one stopping at 2 m, one crossing to 20 m and
    one to 18 m -- give the 18-m plan (distances 16·√10 + 2·√10 against 18·√10 + 2·√10 and
    18·√10 + 16·√10: the mean and the median would be plans no member proposed); a tie gives
    the first; with three learned members the plan is the member's whose summed distance to
    the others is least (the NumPy reference)."""
    from lantern_jax.policies.learned.ensemble import medoid_plan

    ahead = np.linspace(0.1, 1.0, 10, dtype=np.float32)[:, None] * np.asarray([1.0, 0.0])
    plans = np.stack([2.0 * ahead, 20.0 * ahead, 18.0 * ahead]).astype(np.float32)  # (3, 10, 2)
    np.testing.assert_array_equal(np.asarray(medoid_plan(jnp.asarray(plans))), plans[2])
    np.testing.assert_array_equal(np.asarray(medoid_plan(jnp.asarray(plans[[1, 1]]))), plans[1])
    members = [tiny(f"m{i}", i, embedding) for i in range(3)]
    ens = ensemble_policy("medoid", members, combine="medoid")
    got = np.stack([plan(m, obs) for m in members])  # (3, 10, 2)
    flat = got.reshape(3, -1).astype(np.float64)
    summed = np.linalg.norm(flat[:, None] - flat[None], axis=-1).sum(axis=1)
    want = got[int(np.argmin(summed))]
    np.testing.assert_allclose(plan(ens, obs), want, rtol=1e-6, atol=1e-6)
    assert not np.allclose(want, got.mean(axis=0), atol=1e-4)  # not the mean: a test
    assert ens.description.startswith("medoid plan of 3 models")


def test_the_slowest_plan_is_the_members_plan_that_travels_least(obs, embedding):
    """``combine="slowest"``: hand-built plans -- one to 20 m, one stopping at 2 m, one to 18 m
    straight ahead -- have path lengths 20, 2 and 18 m and give the 2-m plan; a plan that zigzags
    sideways (0.5 m ahead and 3 m across at every other waypoint) travels farther than its last
    waypoint's distance and is not chosen over a straight 4-m plan; a tie gives the first; with
    three learned members the plan is the member's with the shortest path (the NumPy
    reference)."""
    from lantern_jax.policies.learned.ensemble import plan_length, slowest_plan

    ahead = np.linspace(0.1, 1.0, 10, dtype=np.float32)[:, None] * np.asarray([1.0, 0.0])
    plans = np.stack([20.0 * ahead, 2.0 * ahead, 18.0 * ahead]).astype(np.float32)  # (3, 10, 2)
    np.testing.assert_allclose(np.asarray(plan_length(jnp.asarray(plans))), [20.0, 2.0, 18.0],
                               rtol=1e-5)  # fmt: skip
    np.testing.assert_array_equal(np.asarray(slowest_plan(jnp.asarray(plans))), plans[1])
    zigzag = np.stack([0.05 * np.arange(1, 11), 3.0 * (np.arange(1, 11) % 2)], -1)  # ends 0.5 m
    two = np.stack([zigzag, 4.0 * ahead]).astype(np.float32)
    assert float(plan_length(jnp.asarray(two))[0]) > 30.0
    np.testing.assert_array_equal(np.asarray(slowest_plan(jnp.asarray(two))), two[1])
    np.testing.assert_array_equal(np.asarray(slowest_plan(jnp.asarray(plans[[2, 2]]))), plans[2])
    members = [tiny(f"m{i}", i, embedding) for i in range(3)]
    ens = ensemble_policy("slowest", members, combine="slowest")
    got = np.stack([plan(m, obs) for m in members]).astype(np.float64)  # (3, 10, 2)
    path = np.concatenate([np.zeros((3, 1, 2)), got], axis=1)
    lengths = np.linalg.norm(np.diff(path, axis=1), axis=-1).sum(axis=1)
    assert np.ptp(lengths) > 1e-3  # the members' lengths differ, so the choice is a test
    np.testing.assert_allclose(plan(ens, obs), got[int(np.argmin(lengths))], rtol=1e-6,
                               atol=1e-6)  # fmt: skip
    assert ens.description.startswith("slowest plan of 3 models")


def test_one_member_is_that_member(obs, embedding):
    member = tiny("m", 4, embedding)
    np.testing.assert_allclose(plan(ensemble_policy("one", [member]), obs), plan(member, obs),
                               rtol=1e-6, atol=1e-6)  # fmt: skip


def test_a_batch_is_each_observation_alone(obs, embedding):
    ens = ensemble_policy("ens", [tiny("a", 0, embedding), tiny("b", 1, embedding)])
    params = ens.init(jax.random.PRNGKey(0))
    moved = obs.replace(ego_speed=obs.ego_speed + 3.0)
    batch = jax.tree.map(lambda a, b: jnp.stack([a, b]), obs, moved)
    together = np.asarray(jax.jit(jax.vmap(ens.act, (None, 0)))(params, batch))
    np.testing.assert_allclose(together[1], plan(ens, moved), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(together[0], plan(ens, obs), rtol=1e-5, atol=1e-5)


def test_ensembles_of_one_architecture_share_one_program(obs, embedding):
    """The act is one function and the weights are arguments: other members, same program."""
    a = ensemble_policy("a", [tiny("a0", 0, embedding), tiny("a1", 1, embedding)])
    b = ensemble_policy("b", [tiny("b0", 5, embedding), tiny("b1", 6, embedding)])
    assert a.program == b.program and a.act is ensemble_act
    act = jax.jit(ensemble_act)
    assert act.lower(a.init(None), obs).as_text() == act.lower(b.init(None), obs).as_text()


def test_gradient_reaches_every_member(obs, embedding):
    ens = ensemble_policy("ens", [tiny("a", 0, embedding), tiny("b", 1, embedding)])
    params = ens.init(jax.random.PRNGKey(0))
    # the parameters an argument (their 33 MB text table is no constant of the program)
    grad = jax.jit(jax.grad(lambda w, p, o: jnp.sum(ensemble_act(p.replace(model=w), o))))
    grads = grad(params.model, params, obs)
    for g in jax.tree.leaves(grads):
        assert np.all(np.isfinite(np.asarray(g)))
    per_member = sum(np.abs(np.asarray(g)).reshape(2, -1).sum(1) for g in jax.tree.leaves(grads))
    assert np.all(per_member > 0), per_member


def test_members_from_checkpoint_files(tmp_path, obs, embedding):
    paths = []
    for i in range(2):
        save_model(new_model(SMALL, seed=i), tmp_path / f"m{i}", dict(note="test"))
        paths.append(tmp_path / f"m{i}.msgpack")
    ens = ensemble_policy("from-files", paths)
    mine = [model_policy(f"m{i}", new_model(SMALL, seed=i)) for i in range(2)]
    np.testing.assert_allclose(plan(ens, obs), np.mean([plan(m, obs) for m in mine], 0),
                               rtol=1e-5, atol=1e-5)  # fmt: skip
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        ensemble_policy("missing", [paths[0], tmp_path / "nowhere.msgpack"])


def test_an_ensemble_of_copies_drives_as_its_member(embedding):
    """In the closed loop (the split path: the session's world program, the ensemble's own
    small program), two copies of a model score the pair as the model does."""
    member = tiny("copied", 3, embedding)
    suite = load_suite().select(["lww_0001"])
    one = evaluate([member], suite=suite, progress=False, path="split").route_table
    two = evaluate([ensemble_policy("two-copies", [member, member])], suite=suite,
                   progress=False, path="split").route_table  # fmt: skip
    cols = [c for c in one.columns if c.startswith("CUS")]
    assert cols
    np.testing.assert_allclose(two[cols].to_numpy(float), one[cols].to_numpy(float), atol=1e-3)


@pytest.mark.parametrize("case, error, match", [
    ("empty", ValueError, "at least one"),
    ("a string", ValueError, "sequence"),
    ("not learned", TypeError, "'coop': not a learned model"),
    ("other width", ValueError, "'wide': architecture"),
    ("other sensors", ValueError, "'rig': sensors"),
    ("other tables", ValueError, "'shifted': its token-embedding table"),
])  # fmt: skip
def test_members_that_cannot_be_averaged_are_named(case, error, match, embedding):
    base = lambda: tiny("base", 0, embedding)  # noqa: E731
    members = {
        "empty": lambda: [],
        "a string": lambda: "learned-coop",
        "not learned": lambda: [get_policy("coop")],
        "other width": lambda: [base(), tiny("wide", 1, embedding, ModelConfig(width=8, heads=2))],
        "other sensors": lambda: [base(), tiny("rig", 1, embedding,
                                               ModelConfig(width=16, heads=2, rig="surround"))],
        "other tables": lambda: [base(), model_policy("shifted", new_model(SMALL, seed=1),
                                                      embedding=embedding + 1.0)],
    }[case]()  # fmt: skip
    with pytest.raises(error, match=match):
        ensemble_policy("bad", members)


def test_stacked_weights_keep_the_members_in_order(embedding):
    members = [tiny(f"m{i}", i, embedding) for i in range(3)]
    stacked = ensemble_policy("ens", members).init(None).model
    for i, m in enumerate(members):
        own = m.init(None).model
        for s, w in zip(jax.tree.leaves(stacked), jax.tree.leaves(own), strict=True):
            np.testing.assert_array_equal(np.asarray(s)[i], np.asarray(w))


def test_the_example_ensemble_file_averages_the_three_chains_it_names(tmp_path, obs, embedding,
                                                                       monkeypatch):  # fmt: skip
    """``examples/bigram_ensemble.py`` loads through ``--policy FILE:NAME`` from the folder the
    training script writes (run from the project's folder): three bigram checkpoints in its
    layout drive as their mean; a missing chain is named.  The script itself is valid bash and
    trains with configs that exist."""
    import subprocess
    from pathlib import Path

    from lantern_jax.policies.external import load_policy_source

    root = Path(__file__).resolve().parents[1]
    bigram = ModelConfig(width=16, heads=2, text_encoder="bigram")
    monkeypatch.chdir(tmp_path)
    members = []
    for seed in (0, 1, 2):
        where = tmp_path / "runs/train/bigram_ensemble" / f"bigram_s{seed}" / "closed"
        where.mkdir(parents=True)
        save_model(new_model(bigram, seed=seed), where / "learned-closed-loop-rig-bigram")
        members.append(tiny(f"s{seed}", seed, embedding, bigram))
    ens, source = load_policy_source(f"{root}/examples/bigram_ensemble.py:bigram_ensemble")
    assert ens.name == "bigram-ensemble" and source["file"] == "bigram_ensemble.py"
    want = np.mean([plan(m, obs) for m in members], axis=0)
    np.testing.assert_allclose(plan(ens, obs), want, rtol=1e-5, atol=1e-5)
    for seed in (0, 1, 2):  # the same models as the half-stated variant's chains
        where = tmp_path / "runs/train/bigram_stated_half" / f"bigram_s{seed}" / "closed"
        where.mkdir(parents=True)
        name = "learned-closed-loop-rig-bigram-stated-half"
        save_model(new_model(bigram, seed=seed), where / name)
    med, _ = load_policy_source(
        f"{root}/examples/bigram_ensemble.py:bigram_stated_half_median_ensemble")
    assert med.name == "bigram-stated-half-median-ensemble"
    want = np.median([plan(m, obs) for m in members], axis=0)
    np.testing.assert_allclose(plan(med, obs), want, rtol=1e-5, atol=1e-5)
    (tmp_path / "runs/train/bigram_ensemble/bigram_s1/closed/"
     "learned-closed-loop-rig-bigram.msgpack").unlink()  # fmt: skip
    with pytest.raises(ValueError, match=r"bigram_s1/closed/learned-closed-loop-rig-bigram"):
        load_policy_source(f"{root}/examples/bigram_ensemble.py:bigram_ensemble")
    script = root / "examples" / "train_bigram_ensemble.sh"
    assert subprocess.run(["bash", "-n", str(script)], check=False).returncode == 0
    configs = set(re.findall(r"configs/\S+\.toml", script.read_text()))  # the three stages',
    #               the variant CLOSED_CONFIG its comment names and the max-pooled chain's three
    assert len(configs) == 7 and all((root / c).is_file() for c in configs), configs


def test_the_training_script_runs_each_seeds_stages_in_order_and_names_a_failed_seed(tmp_path):
    """``examples/train_bigram_ensemble.sh`` with a stand-in ``lantern-jax`` that records its
    arguments: each seed's three stages run in order, each from the previous stage's export in
    that seed's folder; the last line names every ensemble member; a failing seed is named and
    the script exits 1."""
    import shutil
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "examples").mkdir()
    shutil.copy(root / "examples" / "train_bigram_ensemble.sh", tmp_path / "examples")
    shutil.copytree(root / "configs", tmp_path / "configs")  # the closed stage's model name
    fake = tmp_path / ".venv" / "bin" / "lantern-jax"
    fake.parent.mkdir(parents=True)
    # argv: train --config CONFIG --seed SEED ...; one log per config and seed
    fake.write_text('#!/usr/bin/env bash\necho "$*" >> "$OUT_LOG.$(basename "$3").$5"\n'
                    '[ "$5" != "$FAIL_SEED" ]\n')  # fmt: skip
    fake.chmod(0o755)
    script = tmp_path / "examples" / "train_bigram_ensemble.sh"

    def run(fail: str, **extra: str):
        env = dict(os.environ, OUT_LOG=str(tmp_path / "calls"), FAIL_SEED=fail, **extra)
        return subprocess.run(["bash", str(script), "out"], env=env, capture_output=True,
                              text=True, timeout=60, check=False)  # fmt: skip

    done = run("none")
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [
        f"out/bigram_s{s}/closed/learned-closed-loop-rig-bigram.msgpack" for s in (0, 1, 2)]
    for s in (0, 1, 2):
        calls = [(tmp_path / f"calls.{c}.{s}").read_text().split()
                 for c in ("train_base_rig_bigram.toml",
                           "train_distance_onset_only_rig_bigram.toml",
                           "train_closed_loop_rig_bigram.toml")]  # fmt: skip
        assert [c[c.index("--out") + 1] for c in calls] == [
            f"out/bigram_s{s}/{stage}" for stage in ("base", "distance", "closed")]
        assert [c[c.index("--init-from") + 1] for c in calls[1:]] == [
            f"out/bigram_s{s}/base/learned-base-rig-bigram.msgpack",
            f"out/bigram_s{s}/distance/learned-distance-onset-only-rig-bigram.msgpack"]
    failed = run("1")
    assert failed.returncode == 1 and "seed 1 failed; see out/bigram_s1.log" in failed.stderr
    assert "seed 0" not in failed.stderr and "seed 2" not in failed.stderr
    # another seed set and a variant's closed-loop config: its seeds, its model's name
    variant = "configs/train_closed_loop_rig_bigram_stated_half_short.toml"
    other = run("none", SEEDS="3 4 5", CLOSED_CONFIG=variant)
    assert other.returncode == 0, other.stderr
    assert other.stdout.split() == [
        f"out/bigram_s{s}/closed/learned-closed-loop-rig-bigram-stated-half-short.msgpack"
        for s in (3, 4, 5)]
    assert (tmp_path / f"calls.{Path(variant).name}.4").is_file()
    # every stage's config given: each stage starts from the export its previous config names
    stages = ("train_base_rig_bigram_max.toml", "train_distance_onset_only_rig_bigram_max.toml",
              "train_closed_loop_rig_bigram_stated_half_short_max.toml")  # fmt: skip
    pooled = run("none", SEEDS="7", **dict(zip(
        ("BASE_CONFIG", "DISTANCE_CONFIG", "CLOSED_CONFIG"), (f"configs/{c}" for c in stages),
        strict=True)))  # fmt: skip
    assert pooled.returncode == 0, pooled.stderr
    assert pooled.stdout.split() == [
        "out/bigram_s7/closed/learned-closed-loop-rig-bigram-stated-half-short-max.msgpack"]
    calls = [(tmp_path / f"calls.{c}.7").read_text().split() for c in stages]
    assert [c[c.index("--init-from") + 1] for c in calls[1:]] == [
        "out/bigram_s7/base/learned-base-rig-bigram-max.msgpack",
        "out/bigram_s7/distance/learned-distance-onset-only-rig-bigram-max.msgpack"]
    nameless = tmp_path / "configs" / "nameless.toml"
    nameless.write_text("[train]\nrecipe = 'base'\n")
    refused = run("none", BASE_CONFIG=str(nameless))
    assert refused.returncode != 0 and "no name in" in refused.stderr
    failed = run("4", SEEDS="3 4 5")
    assert failed.returncode == 1 and "seed 4 failed; see out/bigram_s4.log" in failed.stderr


def _example_module(name: str):
    """``examples/bigram_ensemble.py`` loaded as a fresh module called ``name`` (each test may
    replace its names without touching another's copy)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "bigram_ensemble.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_each_stated_variant_ensemble_reads_what_its_config_trains():
    """``examples/bigram_ensemble.py``'s stated-position variants: each has its closed-loop
    config, whose model name is the checkpoint the ensemble loads, and whose share is the one
    named; a variant not listed is refused."""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    mod = _example_module("_bigram_ensemble")
    shares = {"all": 1.0, "half": 0.5, "a quarter": 0.25}
    for variant, share in mod.STATED_VARIANTS.items():
        cfg = tomllib.loads((root / "configs" / f"train_closed_loop_rig_bigram_{variant}.toml")
                            .read_text())["train"]  # fmt: skip
        assert cfg["name"] == "learned-closed-loop-rig-bigram-" + variant.replace("_", "-")
        assert cfg["counterfactual_positions"] == "stated"
        assert cfg.get("counterfactual_stated_share", 1.0) == shares[share], variant
    short = tomllib.loads((root / "configs" / "train_closed_loop_rig_bigram_stated_half_short.toml")
                          .read_text())["train"]  # fmt: skip
    assert (short["rounds"], short["epochs"]) == (14, 1)
    hard = tomllib.loads((root / "configs" /
                          "train_closed_loop_rig_bigram_stated_half_short_hard.toml").read_text())
    hard = hard["train"]  # the short recipe with its rounds weighted, nothing else changed
    same = {k: v for k, v in hard.items() if k not in ("name", "out", "family_weights")}
    assert same == {k: v for k, v in short.items() if k not in ("name", "out")}
    assert hard["family_weights"] == "LWW=2,RWW=2,RTY=2"
    box = tomllib.loads((root / "configs" /
                         "train_closed_loop_rig_bigram_stated_half_short_box.toml").read_text())
    box = box["train"]  # the short recipe's rounds under the default actors' rule, nothing else
    assert {k: v for k, v in box.items() if k not in ("name", "out", "ego_leader")} == {
        k: v for k, v in short.items() if k not in ("name", "out")}
    assert box["ego_leader"] == "heading_line_or_box" and "ego_leader" not in short
    # the max-pooled and the three-plan chains: each stage its bigram twin's config but the
    # pooling (the head) and its names
    for tail, field, value in (("max", "object_pool", "mean_max"), ("modes", "modes", 3)):
        for plain in ("train_base_rig_bigram", "train_distance_onset_only_rig_bigram",
                      "train_closed_loop_rig_bigram_stated_half_short"):  # fmt: skip
            one, two = (tomllib.loads((root / "configs" / f"{c}.toml").read_text())["train"]
                        for c in (plain, f"{plain}_{tail}"))  # fmt: skip
            named = ("name", "out", "init_from", field)
            assert {k: v for k, v in two.items() if k not in named} == {
                k: v for k, v in one.items() if k not in named}, (plain, tail)
            assert two[field] == value and two["name"] == f"{one['name']}-{tail}"
            if "init_from" in one:  # from the previous stage of the same chain
                assert two["init_from"].endswith(f"-{tail}.msgpack"), (plain, tail)
    with pytest.raises(KeyError):
        mod.stated_variant_ensemble("stated_tenth")
    # another seed set: its own folder, members and name (the loading stood in for)
    mod.ensemble_policy = lambda name, members, what, combine: (name, members, what, combine)
    name, members, what, combine = mod.stated_variant_ensemble(
        "stated_half_short", combine="median", seeds=(3, 4, 5))
    assert name == "bigram-stated-half-short-median-ensemble-s345" and combine == "median"
    assert members == [
        Path(f"runs/train/bigram_stated_half_short_s345/bigram_s{s}/closed/"
             "learned-closed-loop-rig-bigram-stated-half-short.msgpack") for s in (3, 4, 5)]
    assert what.endswith("fourteen closed-loop rounds of one epoch (seeds 3, 4, 5)")


def test_members_are_chosen_by_their_warning_cus_on_the_validation_suite(monkeypatch):
    """``examples/bigram_ensemble.py``'s choice of members: each seed's checkpoint evaluated once
    on the validation suite it is given, the ``keep`` best by overall warning CUS kept (a tie
    keeps the lower seed); a ``keep`` the members cannot fill is refused.  The chosen ensemble
    names the seeds the docs report, from both seed sets' folders."""
    from pathlib import Path
    from types import SimpleNamespace

    import pandas as pd

    mod = _example_module("_bigram_ensemble_choice")
    import lantern_jax.policies.learned.checkpoint as checkpoint

    monkeypatch.setattr(checkpoint, "checkpoint_policy", lambda path, name: name)
    scores = {0: 79.0, 1: 78.7, 2: 77.0, 3: 78.2, 4: 73.3, 5: 79.0}
    calls = []

    def evaluate(policies, suite, progress):
        (name,) = policies
        calls.append((name, suite))
        seed = int(name.split("-")[1])
        table = pd.DataFrame({"condition": ["warning", "no-warning"],
                              "Overall": [scores[seed], 40.0]})  # fmt: skip
        return SimpleNamespace(family_table=table)

    members = {seed: Path(f"s{seed}.msgpack") for seed in scores}
    assert mod.choose_on_validation(members, "val.json", keep=3, evaluate=evaluate) == [0, 5, 1]
    assert calls == [(f"seed-{seed}", "val.json") for seed in range(6)]
    assert mod.choose_on_validation(members, "val.json", keep=1, evaluate=evaluate) == [0]
    for keep in (0, 7):
        with pytest.raises(ValueError, match="keep"):
            mod.choose_on_validation(members, "val.json", keep=keep, evaluate=evaluate)
    mod.ensemble_policy = lambda name, members, what: (name, members, what)
    name, chosen, what = mod.bigram_stated_half_short_chosen_ensemble()
    assert name == "bigram-stated-half-short-chosen-ensemble"
    assert chosen == [mod.stated_half_short_six_members()[s] for s in mod.VALIDATION_CHOSEN]
    assert "bigram_stated_half_short_s345/bigram_s3/" in str(chosen[2])
    assert f"seed {mod.VALIDATION_SEED}" in what
