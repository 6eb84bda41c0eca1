"""Training configuration: one ``[train]`` table of a TOML file, checked key by key.

Recipes (``recipe``) choose which dataset frames a model learns from and what its text channel
carries — the paper's three learned rows:

* ``base`` (the SimLingo analogue) — ordinary driving: Route B frames and the Route A frames
  without an active warning; the text channel always carries the navigation instruction, so
  the model has a language interface but never sees a warning;
* ``coop`` (the Coop-SimLingo analogue) — fine-tuned from a ``base`` checkpoint
  (``init_from``) on the LANTERN frames (Route A with its warnings, Route B controls), mixed
  with base-style frames (``base_mix``: their share of every batch);
* ``surround`` (the VAD analogue) — every frame, the six-camera rig, no language;
* ``distance`` — like ``coop``, plus far-position counterexamples: Route B frames given the
  family's warning at a far position (``far_m`` ahead) with the ordinary expert trajectory.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

from lantern_jax.dataset.store import EXCLUDE_CROSSING

RECIPES = ("base", "coop", "surround", "distance")


class ConfigError(ValueError):
    """A training config that cannot be used; names the file and key."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on (defaults in brackets)."""

    name: str  # the policy name the trained model is registered and exported under
    recipe: str  # one of RECIPES
    dataset: str = "data/lantern"  # dataset folder (lantern-jax dataset --out)
    out: str = "runs/train"  # run folder: checkpoints, curves, the exported model
    init_from: str = ""  # exported model to start from (coop, distance: the base model)
    base_mix: float = 0.3  # coop/distance: share of base-style frames in every batch
    far_m: float = 100.0  # distance: forward distance of the far counterexample warnings, m
    width: int = 64
    heads: int = 4
    layers: int = 1
    epochs: int = 6
    batch_size: int = 256
    lr: float = 1e-3  # peak learning rate (one-cycle: warm-up then cosine decay)
    warmup: float = 0.1  # share of steps spent warming up
    weight_decay: float = 1e-4  # AdamW
    val_fraction: float = 0.1  # share of sequences held out for validation (split by sequence)
    seed: int = 0
    max_minutes: float = 30.0  # stop (after the current epoch) when exceeded
    # frames whose 2.5-s waypoint horizon crosses a warning mark that are left out: "both" (onset
    # or termination, the paper's rule), "onset" or "none" (dataset.store.EXCLUDE_CROSSING)
    exclude_crossing: str = "both"

    @property
    def rig(self) -> str:
        """The camera rig the recipe uses."""
        return "surround" if self.recipe == "surround" else "front"

    @property
    def language(self) -> bool:
        """Whether the model conditions on the text channel."""
        return self.recipe != "surround"


_FIELDS = {f.name: f for f in dataclasses.fields(TrainConfig)}


def _check_type(path: str, key: str, value: Any) -> Any:
    want = _FIELDS[key].type
    if want == "float" and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if want == "int" and isinstance(value, int) and not isinstance(value, bool):
        return value
    if want == "str" and isinstance(value, str):
        return value
    raise ConfigError(f"config {path}: train.{key} must be {want}, got {value!r}")


def load_config(path: str | Path, **overrides: Any) -> TrainConfig:
    """Read a training config (TOML, one ``[train]`` table), with optional overrides.

    Raises:
        ConfigError: naming the file and key for unreadable TOML, keys outside ``[train]``,
            unknown keys, wrong types, missing required keys or out-of-range values.
    """
    path = str(path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except OSError as e:
        raise ConfigError(f"cannot read config {path}: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"config {path}: not valid TOML ({e})") from None
    outside = sorted(k for k in raw if k != "train")
    if outside or not isinstance(raw.get("train"), dict):
        raise ConfigError(f"config {path}: needs one [train] table; found {outside or 'none'}")
    table = {**raw["train"], **{k: v for k, v in overrides.items() if v is not None}}
    for key in table:
        if key not in _FIELDS:
            raise ConfigError(f"config {path}: train.{key}: unknown key; valid: "
                              f"{', '.join(_FIELDS)}")  # fmt: skip
    values = {k: _check_type(path, k, v) for k, v in table.items()}
    for key in ("name", "recipe"):
        if key not in values:
            raise ConfigError(f"config {path}: train.{key}: missing")
    cfg = TrainConfig(**values)
    _check_ranges(path, cfg)
    return cfg


def _check_ranges(path: str, cfg: TrainConfig) -> None:
    problems = []
    if cfg.recipe not in RECIPES:
        problems.append(f"recipe: {cfg.recipe!r} not one of {', '.join(RECIPES)}")
    if cfg.recipe in ("coop", "distance") and not cfg.init_from:
        problems.append(f"init_from: the {cfg.recipe} recipe fine-tunes a base model; give it")
    for key in ("epochs", "batch_size", "width", "heads", "layers"):
        if getattr(cfg, key) < 1:
            problems.append(f"{key}: must be >= 1")
    for key in ("lr", "max_minutes", "far_m"):
        if not getattr(cfg, key) > 0:
            problems.append(f"{key}: must be > 0")
    for key in ("base_mix", "warmup", "val_fraction"):
        if not 0.0 <= getattr(cfg, key) < 1.0:
            problems.append(f"{key}: must be in [0, 1)")
    if cfg.exclude_crossing not in EXCLUDE_CROSSING:
        problems.append(f"exclude_crossing: {cfg.exclude_crossing!r} not one of "
                        f"{', '.join(EXCLUDE_CROSSING)}")  # fmt: skip
    if cfg.width % cfg.heads:
        problems.append(f"heads: {cfg.heads} does not divide width {cfg.width}")
    if problems:
        raise ConfigError(f"config {path}: train.{problems[0]}")
