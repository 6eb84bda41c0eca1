"""Training end to end on a tiny recorded dataset: determinism, resume, fine-tuning from a base
checkpoint, the recipes' frame selection, and the trained model in the closed loop.

Recording the dataset and compiling the training step dominate the cost, so the module runs
with the slow tests (CI runs them too).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from lantern_jax.apps.dataset.generation import generate_dataset
from lantern_jax.apps.dataset.store import dataset_sha256, load_frames, read_card
from lantern_jax.apps.training.behaviour_cloning import train
from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.apps.training.data import examples_from_frames, recipe_examples, split_by_sequence
from lantern_jax.cli import main
from lantern_jax.core.constants import FAMILIES
from lantern_jax.policies.learned.checkpoint import checkpoint_policy, read_meta
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scenarios.warnings import text_tables
from lantern_jax.types.language import PAD_ID

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ds") / "tiny"
    # chunks of three pairs: the recording program of tests/test_dataset.py's chunks (one
    # compilation for the session)
    generate_dataset(folder, pairs_per_family=1, seed=5, chunk_pairs=3, progress=False)
    return folder


def tiny(dataset, out, **kw) -> TrainConfig:
    base = dict(name="learned-tiny", recipe="base", dataset=str(dataset), out=str(out), width=16,
                heads=2, epochs=1, batch_size=32, val_fraction=0.2, seed=3)  # fmt: skip
    return TrainConfig(**{**base, **kw})


def test_recipes_select_the_frames_they_promise(dataset):
    frames = load_frames(dataset, include_crossing=False)
    card = read_card(dataset)
    every = examples_from_frames(frames, card)
    base = recipe_examples(frames, card, tiny(dataset, "x"))
    warned = np.any(every.obs["warning_tokens"] != PAD_ID, axis=-1)  # a text was delivered
    assert warned.any() and not warned.all()
    assert len(base) == int(np.sum(~warned))
    assert np.all(base.obs["warning_tokens"] == PAD_ID)
    coop = recipe_examples(frames, card, tiny(dataset, "x", recipe="coop", init_from="b"))
    assert len(coop) == len(every)
    assert np.any(coop.obs["warning_tokens"] != PAD_ID, axis=-1).sum() == warned.sum()
    far = recipe_examples(frames, card, tiny(dataset, "x", recipe="distance", init_from="b"))
    n_b = int(np.sum(frames["route"].to_numpy(str) == "B"))
    assert len(far) == len(every) + n_b
    added = far.take(np.arange(len(every), len(far)))
    assert np.any(added.obs["warning_tokens"] != PAD_ID, axis=-1).all()  # a text on every one
    # ... its family's canonical sentence, the hazard told at 100 m ahead, 0.5 m to the side
    tables = text_tables()
    fam = np.asarray([FAMILIES.index(f) for f in frames["family"].to_numpy(str)[
        frames["route"].to_numpy(str) == "B"]])  # fmt: skip
    np.testing.assert_array_equal(added.obs["warning_tokens"], tables.tokens[fam])
    rows = np.arange(len(added))
    np.testing.assert_allclose(added.obs["warning_values"][rows, tables.x_slot[fam]], 100.0)
    np.testing.assert_allclose(added.obs["warning_values"][rows, tables.y_slot[fam]], 0.5)


def test_validation_split_holds_out_whole_sequences(dataset):
    frames = load_frames(dataset, include_crossing=False)
    ex = examples_from_frames(frames, read_card(dataset))
    tr, va = split_by_sequence(ex, 0.3, seed=1)
    assert len(tr) + len(va) == len(ex) and len(va) > 0
    assert not set(ex.sequence[tr]) & set(ex.sequence[va])


def test_same_seed_same_checkpoint_and_resume(dataset, tmp_path):
    a = train(tiny(dataset, tmp_path / "a"), progress=False)
    b = train(tiny(dataset, tmp_path / "b"), progress=False)
    sha = [read_meta(tmp_path / d / "learned-tiny")["params_sha256"] for d in "ab"]
    assert sha[0] == sha[1]
    # the description names the data it was trained on: the dataset's content digest
    meta = read_meta(tmp_path / "a" / "learned-tiny")
    assert meta["dataset_sha256"] == dataset_sha256(read_card(dataset)) == a["dataset_sha256"]
    assert meta["dataset_frames"] == read_card(dataset)["frames"] == a["dataset_frames"]
    assert a["best_val_l1_m"] == b["best_val_l1_m"] and np.isfinite(a["best_val_l1_m"])
    # a rerun with more epochs resumes from the orbax checkpoint instead of starting over
    more = train(tiny(dataset, tmp_path / "a", epochs=2), progress=False)
    curve = pd.read_csv(tmp_path / "a" / "curve.csv")
    assert list(curve["epoch"]) == [0, 1] and more["epochs"] == 2
    assert (tmp_path / "a" / "curve.png").stat().st_size > 0


def test_coop_fine_tunes_the_base_and_runs_in_the_closed_loop(dataset, tmp_path, capsys):
    train(tiny(dataset, tmp_path / "base"), progress=False)
    base_path = tmp_path / "base" / "learned-tiny.msgpack"
    cfg = tiny(dataset, tmp_path / "coop", name="learned-tiny-coop", recipe="coop",
               init_from=str(base_path))  # fmt: skip
    train(cfg, progress=False)
    meta = read_meta(tmp_path / "coop" / "learned-tiny-coop")
    assert meta["train_config"]["init_from"] == str(base_path)
    assert meta["train_config"] == dataclasses.asdict(cfg)
    pol = checkpoint_policy(tmp_path / "coop" / "learned-tiny-coop.msgpack")
    assert pol.name == "learned-tiny-coop" and pol.reads_warning
    rc = main(["evaluate", "--checkpoint", str(tmp_path / "coop" / "learned-tiny-coop.msgpack"),
               "--pairs-per-family", "1", "--out", str(tmp_path / "res"), "--rollout", "split",
               "--quiet"])  # fmt: skip
    assert rc == 0
    route = pd.read_csv(tmp_path / "res" / "route_level_results.csv")
    assert set(route["model"]) == {"learned-tiny-coop"} and len(route) == 12
    assert np.isfinite(route["CUS"]).all()
    assert "learned-tiny-coop" in capsys.readouterr().out


def test_train_command_names_a_bad_config(tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text("[train]\nname = 'x'\nrecipe = 'coop'\n")
    assert main(["train", "--config", str(p)]) == 2
    assert "init_from" in capsys.readouterr().err


def test_surround_recipe_trains_on_the_rig_and_drives(dataset, tmp_path):
    """The surround recipe reads the dataset's six-camera columns (every frame, no language)
    and its checkpoint runs in the closed loop with the simulator's 360-degree view."""
    from lantern_jax.apps.evaluation import evaluate

    cfg = tiny(dataset, tmp_path / "sur", name="learned-tiny-surround", recipe="surround")
    train(cfg, progress=False)
    pol = checkpoint_policy(tmp_path / "sur" / "learned-tiny-surround.msgpack")
    assert pol.surround and not pol.reads_warning
    # the split path: the session's world program, only the policy's own is compiled
    pairs = load_suite().select(["pe_0001", "vc_0001"])
    res = evaluate([pol], suite=pairs, progress=False, path="split")
    assert np.isfinite(res.route_table["CUS"]).all() and len(res.route_table) == 4


def test_steps_in_groups_give_the_weights_of_one_step_per_call(dataset, tmp_path, monkeypatch,
                                                                 capsys):
    """Training runs :data:`~lantern_jax.apps.training.fit.STEPS_PER_CALL` steps per compiled
    call, the epoch's last group padded with steps that change nothing: the exported weights
    and every epoch's losses are the bits of one step per call (two epochs, a padded group in
    each)."""
    from lantern_jax.apps.training import fit

    cfg = tiny(dataset, tmp_path / "grouped", epochs=2, batch_size=48)
    per_epoch = len(fit.Batches(*_train_split(dataset, cfg), cfg).epoch(0))
    assert per_epoch % fit.STEPS_PER_CALL != 0, per_epoch  # the last group is padded
    grouped = train(cfg, progress=True)  # the bar counts every real step
    assert f"{2 * per_epoch}/{2 * per_epoch}" in capsys.readouterr().err
    monkeypatch.setattr(fit, "STEPS_PER_CALL", 1)
    single = train(dataclasses.replace(cfg, out=str(tmp_path / "single")), progress=False)
    sha = [read_meta(tmp_path / d / "learned-tiny")["params_sha256"] for d in ("grouped", "single")]
    assert sha[0] == sha[1]
    curves = [pd.read_csv(tmp_path / d / "curve.csv") for d in ("grouped", "single")]
    for column in ("train_l1_m", "val_l1_m"):
        np.testing.assert_array_equal(curves[0][column], curves[1][column])
    assert grouped["frames_per_s"] > 0 and single["best_val_l1_m"] == grouped["best_val_l1_m"]


def _train_split(dataset, cfg: TrainConfig):
    """(examples, training indices) of a base-recipe config, as ``train`` builds them."""
    frames = load_frames(dataset, exclude_crossing=cfg.exclude_crossing)
    ex = recipe_examples(frames, read_card(dataset), cfg)
    return ex, split_by_sequence(ex, cfg.val_fraction, cfg.seed)[0]
