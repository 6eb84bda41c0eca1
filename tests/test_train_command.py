"""One ``train`` command family: ``lantern-jax train --config`` runs PPO for a ``[ppo]`` config
(the brax trainer receives the config's values, with the command line's overrides) and the
dataset recipes for a ``[train]`` config; options of the other kind are refused by name."""

from __future__ import annotations

import pytest

pytest.importorskip("brax")

import lantern_jax.apps.envs.ppo_training as ppo_train  # noqa: E402
from lantern_jax.cli import main  # noqa: E402


@pytest.fixture
def calls(monkeypatch):
    seen: list[dict] = []

    def fake_train(**kwargs):
        seen.append(kwargs)
        return [{"env_steps": 10, "eval_return": 0.5}]

    monkeypatch.setattr(ppo_train, "train", fake_train)
    return seen


def _config(tmp_path, body: str):
    path = tmp_path / "ppo.toml"
    path.write_text(body)
    return str(path)


def test_a_ppo_config_runs_ppo_with_its_values(tmp_path, calls, capsys):
    cfg = _config(tmp_path, f'[ppo]\nout = "{tmp_path}/run"\nminutes = 2\nnum_evals = 3\n')
    assert main(["train", "--config", cfg]) == 0
    assert calls == [{"out": f"{tmp_path}/run", "minutes": 2, "num_evals": 3,
                      "checkpoint": f"{tmp_path}/run/ppo_lantern.msgpack"}]  # fmt: skip
    assert "eval_return: 0.5" in capsys.readouterr().out


def test_command_line_overrides_the_ppo_config(tmp_path, calls):
    cfg = _config(tmp_path, f'[ppo]\nout = "{tmp_path}/a"\nseed = 1\nminutes = 9\n')
    argv = ["train", "--config", cfg, "--out", str(tmp_path / "b"), "--seed", "7",
            "--minutes", "0.5"]  # fmt: skip
    assert main(argv) == 0
    assert calls[0]["out"] == str(tmp_path / "b") and calls[0]["seed"] == 7
    assert calls[0]["minutes"] == 0.5
    assert calls[0]["checkpoint"] == f"{tmp_path / 'b'}/ppo_lantern.msgpack"


def test_out_on_the_command_line_moves_the_configs_checkpoint_too(tmp_path, calls, capsys):
    """A run moved with ``--out`` keeps nothing at the config's paths: the checkpoint the
    config names keeps its file name and is written under the new folder."""
    cfg = _config(tmp_path, f'[ppo]\nout = "{tmp_path}/a"\n'
                            f'checkpoint = "{tmp_path}/a/mine.msgpack"\n')  # fmt: skip
    assert main(["train", "--config", cfg, "--out", str(tmp_path / "b")]) == 0
    assert calls[0]["checkpoint"] == str(tmp_path / "b" / "mine.msgpack")
    assert f"checkpoint: {tmp_path / 'b' / 'mine.msgpack'}" in capsys.readouterr().out
    assert main(["train", "--config", cfg]) == 0  # without --out, the config's own path
    assert calls[1]["checkpoint"] == f"{tmp_path}/a/mine.msgpack"


@pytest.mark.parametrize(
    ("body", "extra", "message"),
    [
        ("[ppo]\n", ["--epochs", "2"], "--epochs: config"),
        ("[ppo]\n", ["--dataset", "data/x"], "--dataset: config"),
        ("[ppo]\n", ["--init-from", "a.msgpack"], "--init-from: config"),
        ("[ppo]\nminutes = 0\n", [], "minutes must be > 0"),
        ("[ppo]\nminutes = 'x'\n", [], "minutes must be int or float"),
        ("[ppo]\nlearning_rate = 1.0\n", [], "unknown key 'learning_rate' in [ppo]"),
    ],
)
def test_bad_ppo_configs_are_refused_by_name(tmp_path, calls, capsys, body, extra, message):
    assert main(["train", "--config", _config(tmp_path, body), *extra]) == 2
    assert message in capsys.readouterr().err
    assert calls == []


def test_minutes_is_refused_for_a_dataset_recipe(capsys, calls):
    assert main(["train", "--config", "configs/train_base.toml", "--minutes", "3"]) == 2
    assert "--minutes: config configs/train_base.toml trains on the dataset" in (
        capsys.readouterr().err
    )


def test_the_shipped_ppo_config_is_valid(calls, tmp_path):
    assert main(["train", "--config", "configs/train_ppo.toml", "--out", str(tmp_path)]) == 0
    assert calls[0]["num_timesteps"] == 200_000_000 and calls[0]["pairs_per_family"] == 16
    assert calls[0]["checkpoint"] == str(tmp_path / "ppo_lantern.msgpack")


def test_init_from_overrides_a_dataset_config_and_is_named_when_wrong(tmp_path):
    """``--init-from`` replaces the config's checkpoint (a chain's later stage from another
    seed's earlier one), and a bad value is named as the option, not the file's key."""
    from lantern_jax.apps.training.config import ConfigError, load_config

    cfg = load_config("configs/train_closed_loop_rig_bigram.toml", init_from="runs/s1.msgpack")
    assert cfg.init_from == "runs/s1.msgpack" and cfg.text_encoder == "bigram"
    with pytest.raises(ConfigError, match=r"^--init-from must be str"):
        load_config("configs/train_closed_loop_rig_bigram.toml", init_from=3)
