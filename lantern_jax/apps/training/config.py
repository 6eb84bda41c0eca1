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
  family's warning at a far position (``far_m`` ahead) with the ordinary expert trajectory;
* ``closed_loop`` — DAgger from an open-loop model (``init_from``): ``rounds`` times, the
  current model drives training scenes (the dataset's plan), the expert relabels the states it
  visits, and the model trains ``epochs`` epochs on the distance recipe's examples plus every
  relabelled visit so far (``closed_loop_mix`` of every batch) plus counterfactual warnings
  (``counterfactual``: Route B frames told another family's text, a non-actionable message or
  an empty text, with the ordinary trajectory; ``distractors`` of them a training-only negated
  or irrelevant sentence that states a position instead, drawn from the set
  ``distractor_texts`` names; :mod:`lantern_jax.apps.training.counterfactual`).
  ``family_weights`` spreads each round's scene pairs over the families in proportion to
  their weights (``"LWW=2,RWW=2"``; evenly when empty).
  With ``failure_window_s > 0`` each round also keeps the visits of the last seconds before
  every collision of the driven executions, every ``failure_every_s`` (recovery states).
  With ``no_warning > 0`` that share of each round's pairs also drives Route A without its
  warning, and the visits at which the hazard is in the learner's view join the others (the
  reaction to the camera alone; :func:`lantern_jax.apps.training.closed_loop.collect`).
  With ``distractor_drives > 0`` that share also drives Route A told a training distractor
  sentence in place of its warning, each visit labelled with the learner's own plan without
  the sentence (:mod:`lantern_jax.apps.training.distractor_drives`).
  Every drive of the rounds runs under the dataset's actors' rule
  (:data:`~lantern_jax.apps.dataset.record.DATA_ACTORS`) unless ``ego_leader`` names another
  (``"heading_line_or_box"``: the benchmark's default, in which a car also brakes for the ego's
  box on its path).

The text encoder (``text_encoder``) is the pooled bag of words unless given; ``"attention"``
reads the words in order, ``"bigram"`` which word follows which
(:mod:`lantern_jax.policies.learned.model`).  The seen actors' tokens are pooled by their mean
unless ``object_pool = "mean_max"`` adds each feature's largest value.  The head proposes one
plan unless ``modes`` asks for several, each with a score, the model driving the one it scores
highest.  A model fine-tuned from ``init_from`` must have the architecture of that checkpoint.

The camera rig (``rig``) is the recipe's own unless given: the six-camera rig for ``surround``,
the front camera for the others.  A language recipe may take ``rig = "surround"``: its model
then reads the six-camera rig's view (the dataset's ``rig.*`` and ``surround.*`` columns in
training, the ``surround_rig`` sensor in the simulator) beside the warning text.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from lantern_jax.apps.dataset.store import EXCLUDE_CROSSING
from lantern_jax.core.constants import FAMILIES
from lantern_jax.dynamics.actors import EGO_LEADER_RULES
from lantern_jax.io.config_file import ConfigFileError, check_keys, read_table, typed_value
from lantern_jax.policies.learned.features import RIGS
from lantern_jax.policies.learned.model import OBJECT_POOLS, TEXT_ENCODERS
from lantern_jax.policies.names import name_problem
from lantern_jax.scenarios.warning_texts import DISTRACTOR_SETS

RECIPES = ("base", "coop", "surround", "distance", "closed_loop")
#: The table of a training config.
TABLE = "train"

#: A training config that cannot be used; names the file and key (the error of every
#: configuration file, :class:`lantern_jax.io.config_file.ConfigFileError`).
ConfigError = ConfigFileError


#: Where a counterfactual's stated position is drawn (``TrainConfig.counterfactual_positions``):
#: ``"near"``, uniformly in the box ``counterfactual.NEAR_X_M`` x ``NEAR_Y_M`` (10-60 m ahead,
#: within 4 m of the lane); ``"stated"``, among the positions that the true warnings of the
#: frame's family state in the examples (``counterfactual.stated_positions``).  The box holds
#: 18 % of PE's and 49 % of VC's stated positions and none of LWW's, RWW's or RTY's
#: (lantern-v3, the expert driving, every tick a warning is delivered; the turning families'
#: hazards are stated 14-48 m to the side): a position where only true warnings ever state one
#: can be a cue of its own.
POSITION_SOURCES = ("near", "stated")

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
    # how the model reads the text (policies.learned.model.TEXT_ENCODERS): "pooled" (the mean
    # of the words' embeddings), "attention" (the words in order, text_layers attention layers)
    # or "bigram" (every ordered pair of adjacent words)
    text_encoder: str = "pooled"
    text_layers: int = 1
    # how the seen actors' tokens are pooled (policies.learned.model.OBJECT_POOLS): "mean", or
    # "mean_max" (the mean beside each feature's largest value, so one actor can set a feature)
    object_pool: str = "mean"
    # plans the model's head proposes (policies.learned.model.ModelConfig.modes): 1, one plan
    # trained by its L1; K > 1, K plans and their scores trained winner-takes-all, the model
    # driving the one it scores highest (the curve's train_l1_m is then that training loss, its
    # val_l1_m the L1 of the plans driven)
    modes: int = 1
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
    # closed_loop (DAgger) only:
    rounds: int = 3  # collect-relabel-train rounds
    scenes_per_round: int = 96  # dataset-plan scene pairs driven per round (A and B each)
    # how a round's scene pairs are spread over the families: "FAMILY=WEIGHT,..." (a family
    # not named weighs 1; "": evenly); closed_loop.round_specs
    family_weights: str = ""
    visit_every_s: float = 2.0  # s, simulated time between two relabelled visits
    max_seconds: float = 40.0  # s, visits are kept until this time of an execution
    beta: float = 0.5  # round 0: probability that the expert drives a segment between visits
    beta_decay: float = 0.5  # beta of round r: beta * beta_decay**r
    closed_loop_mix: float = 0.3  # share of every batch drawn from the relabelled visits
    counterfactual: float = 0.5  # counterfactual warning frames per Route B frame
    distractors: float = 0.0  # share of those told a training distractor sentence instead
    # which sentences: a key of scenarios.warning_texts.DISTRACTOR_SETS ("position": the twelve
    # position statements; "position_and_lane": those and eight in the templates' own phrases;
    # "position_lane_negations": those and seven negations in other words than "no")
    distractor_texts: str = "position"
    # where the counterfactual frames' stated positions are drawn (counterfactual.POSITION_SOURCES):
    # "near", uniformly ahead within 4 m of the lane; "stated", among the positions the true
    # warnings of the frame's family state in the dataset
    counterfactual_positions: str = "near"
    # with "stated": the share of those frames drawn among the stated positions, the others
    # in the near box (1: all of them; another value only with "stated")
    counterfactual_stated_share: float = 1.0
    # s: also keep the visits this long before each driven execution's first collision, every
    # failure_every_s (the states that lead the learner into a failure); 0 keeps none
    failure_window_s: float = 0.0
    failure_every_s: float = 0.5  # s, spacing of those visits; divides visit_every_s
    # share of each round's scene pairs whose Route A is also driven without its warning (the
    # learner alone); of those executions only the visits at which the hazard actor is in the
    # learner's view are kept, every no_warning_every_s (the camera's own reaction); 0: none
    no_warning: float = 0.0
    no_warning_every_s: float = 0.5  # s, spacing of those visits
    # share of each round's scene pairs whose Route A is also driven told a training distractor
    # sentence (distractor_texts) in place of its warning, the learner alone; the visits at
    # which the sentence is in the learner's observation, every distractor_drive_every_s, are
    # labelled with the learner's own plan without the sentence (training.distractor_drives);
    # 0: none
    distractor_drives: float = 0.0
    distractor_drive_every_s: float = 0.5  # s, spacing of those visits
    # how the IDM cars treat the ego while the learner drives and the expert relabels its visits
    # (dynamics.actors.EGO_LEADER_RULES); "" is the dataset's rule (apps.dataset.record
    # .DATA_ACTORS, the earlier one, under which the dataset and every shipped model were made);
    # "heading_line_or_box", the benchmark's default since 2026-12-08, drives the rounds in the
    # world the model is evaluated in
    ego_leader: str = ""
    # the camera rig the model reads (features.RIGS); "" is the recipe's own: "surround" for
    # the surround recipe, "front" for the others
    rig: str = ""

    def __post_init__(self) -> None:
        if self.rig == "":
            object.__setattr__(self, "rig", "surround" if self.recipe == "surround" else "front")

    @property
    def language(self) -> bool:
        """Whether the model conditions on the text channel."""
        return self.recipe != "surround"


_FIELDS = {f.name: f for f in dataclasses.fields(TrainConfig)}
#: The accepted types of a field by its annotation.
_TYPES = {"float": (float,), "int": (int,), "str": (str,)}


def load_config(path: str | Path, **overrides: Any) -> TrainConfig:
    """Read a training config (TOML, one ``[train]`` table), with optional overrides.

    Raises:
        ConfigError: naming the file and key for unreadable TOML, keys outside ``[train]``,
            unknown keys, wrong types, missing required keys or out-of-range values.
    """
    path = str(path)
    given = {k: v for k, v in overrides.items() if v is not None}
    table = {**read_table(path, TABLE), **given}
    check_keys(path, TABLE, table, tuple(_FIELDS))
    values = {
        key: typed_value(value, _TYPES[_FIELDS[key].type], _where(path, key, overrides))
        for key, value in table.items()
    }
    for key in ("name", "recipe"):
        if key not in values:
            raise ConfigError(f"config {path}: train.{key}: missing")
    cfg = TrainConfig(**values)
    problem = _range_problem(cfg)
    if problem:
        raise ConfigError(f"{_where(path, problem[0], overrides)}: {problem[1]}")
    return cfg


def _where(path: str, key: str, overrides: dict[str, Any]) -> str:
    """Where a value came from: the command line's ``--key`` or the file's ``train.key``."""
    if overrides.get(key) is not None:
        return f"--{key.replace('_', '-')}"
    return f"config {path}: train.{key}"


def _range_problem(cfg: TrainConfig) -> tuple[str, str] | None:
    """(key, problem) of the first value out of range, or None."""
    problems = []
    name = name_problem(cfg.name)
    if name:
        problems.append(("name", f"{name} (it names the exported files and the policy)"))
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if isinstance(value, float) and not math.isfinite(value):
            problems.append((f.name, f"must be a finite number, got {value}"))
    if cfg.recipe not in RECIPES:
        problems.append(("recipe", f"{cfg.recipe!r} not one of {', '.join(RECIPES)}"))
    if cfg.recipe in ("coop", "distance", "closed_loop") and not cfg.init_from:
        problems.append(("init_from", f"the {cfg.recipe} recipe fine-tunes a base model; give it"))
    for key in ("epochs", "batch_size", "width", "heads", "layers", "text_layers", "rounds",
                "scenes_per_round", "modes"):  # fmt: skip
        if getattr(cfg, key) < 1:
            problems.append((key, f"must be >= 1, got {getattr(cfg, key)}"))
    for key in ("lr", "max_minutes", "far_m", "visit_every_s", "max_seconds", "failure_every_s",
                "no_warning_every_s", "distractor_drive_every_s"):  # fmt: skip
        if not getattr(cfg, key) > 0:
            problems.append((key, f"must be > 0, got {getattr(cfg, key)}"))
    if not cfg.failure_window_s >= 0:
        problems.append(("failure_window_s", f"must be >= 0, got {cfg.failure_window_s}"))
    ratio = cfg.visit_every_s / cfg.failure_every_s if cfg.failure_every_s > 0 else 0.0
    if cfg.failure_window_s > 0 and (ratio < 1 or abs(ratio - round(ratio)) > 1e-6):
        problems.append(("failure_every_s", f"must divide visit_every_s {cfg.visit_every_s}, "
                                            f"got {cfg.failure_every_s}"))  # fmt: skip
    if not cfg.weight_decay >= 0:
        problems.append(("weight_decay", f"must be >= 0, got {cfg.weight_decay}"))
    for key in ("base_mix", "warmup", "closed_loop_mix"):
        if not 0.0 <= getattr(cfg, key) < 1.0:
            problems.append((key, f"must be in [0, 1), got {getattr(cfg, key)}"))
    for key in ("beta", "beta_decay", "counterfactual", "distractors", "no_warning",
                "distractor_drives"):
        if not 0.0 <= getattr(cfg, key) <= 1.0:
            problems.append((key, f"must be in [0, 1], got {getattr(cfg, key)}"))
    if cfg.recipe == "closed_loop" and cfg.base_mix + cfg.closed_loop_mix >= 1.0:
        problems.append(("closed_loop_mix", "base_mix + closed_loop_mix must be < 1"))
    if not 0.0 < cfg.val_fraction < 1.0:
        why = "the best model is chosen on the held-out sequences"
        problems.append(("val_fraction", f"must be in (0, 1) ({why}), got {cfg.val_fraction}"))
    if cfg.exclude_crossing not in EXCLUDE_CROSSING:
        problems.append(("exclude_crossing", f"{cfg.exclude_crossing!r} not one of "
                                             f"{', '.join(EXCLUDE_CROSSING)}"))  # fmt: skip
    if cfg.distractor_texts not in DISTRACTOR_SETS:
        problems.append(("distractor_texts", f"{cfg.distractor_texts!r} not one of "
                                             f"{', '.join(DISTRACTOR_SETS)}"))  # fmt: skip
    if cfg.counterfactual_positions not in POSITION_SOURCES:
        problems.append(("counterfactual_positions", f"{cfg.counterfactual_positions!r} not "
                         f"one of {', '.join(POSITION_SOURCES)}"))  # fmt: skip
    if not 0.0 <= cfg.counterfactual_stated_share <= 1.0:
        problems.append(("counterfactual_stated_share",
                         f"must be in [0, 1], got {cfg.counterfactual_stated_share}"))
    elif cfg.counterfactual_stated_share != 1.0 and cfg.counterfactual_positions != "stated":
        problems.append(("counterfactual_stated_share", "a share of the positions drawn where "
                         "true warnings state theirs: only with counterfactual_positions = "
                         "\"stated\""))  # fmt: skip
    try:
        parse_family_weights(cfg.family_weights)
    except ValueError as e:
        problems.append(("family_weights", str(e)))
    if cfg.rig not in RIGS:
        problems.append(("rig", f"{cfg.rig!r} not one of {', '.join(RIGS)}"))
    elif cfg.recipe == "surround" and cfg.rig != "surround":
        problems.append(("rig", "the surround recipe is the six-camera rig's; leave rig out"))
    if cfg.text_encoder not in TEXT_ENCODERS:
        problems.append(("text_encoder", f"{cfg.text_encoder!r} not one of "
                                         f"{', '.join(TEXT_ENCODERS)}"))  # fmt: skip
    elif cfg.text_encoder != "pooled" and not cfg.language:
        problems.append(("text_encoder", f"the {cfg.recipe} recipe reads no text; leave it out"))
    if cfg.object_pool not in OBJECT_POOLS:
        problems.append(("object_pool", f"{cfg.object_pool!r} not one of "
                                        f"{', '.join(OBJECT_POOLS)}"))  # fmt: skip
    if cfg.ego_leader and cfg.ego_leader not in EGO_LEADER_RULES:
        rules = ", ".join(EGO_LEADER_RULES)
        problems.append(("ego_leader", f"{cfg.ego_leader!r} not one of {rules} "
                                       "(or \"\", the dataset's rule)"))  # fmt: skip
    elif cfg.ego_leader and cfg.recipe != "closed_loop":
        problems.append(("ego_leader", f"the {cfg.recipe} recipe drives nothing (it reads the "
                                       "dataset's frames); leave it out"))  # fmt: skip
    if cfg.width % cfg.heads:
        problems.append(("heads", f"{cfg.heads} does not divide width {cfg.width}"))
    return problems[0] if problems else None


def parse_family_weights(text: str) -> dict[str, float]:
    """``"LWW=2,RWW=2"`` -> ``{"LWW": 2.0, "RWW": 2.0}`` (the ``family_weights`` setting; ``""``:
    no weights).

    Raises:
        ValueError: naming the entry that is not ``FAMILY=WEIGHT`` with a built-in family and a
            finite weight > 0, or a family named twice.
    """
    out: dict[str, float] = {}
    if not text.strip():
        return out
    for entry in (e.strip() for e in text.split(",")):
        family, sep, value = entry.partition("=")
        family = family.strip()
        try:
            weight = float(value) if sep else float("nan")
        except ValueError:
            weight = float("nan")
        if family not in FAMILIES or not (math.isfinite(weight) and weight > 0):
            raise ValueError(f"{entry!r} is not FAMILY=WEIGHT with FAMILY one of "
                             f"{', '.join(FAMILIES)} and WEIGHT a number > 0")  # fmt: skip
        if family in out:
            raise ValueError(f"{family} is given twice")
        out[family] = weight
    return out
