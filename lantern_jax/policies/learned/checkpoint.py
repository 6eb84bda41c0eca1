"""Trained driving models as policies, and their portable checkpoint files.

A shipped (exported) model is two files side by side:

* ``<name>.msgpack`` — the model's parameters (:func:`flax.serialization.to_bytes` of the NNX
  parameter state, a few hundred kB);
* ``<name>.json`` — its :class:`~lantern_jax.policies.learned.model.ModelConfig`, the SHA-256
  of the parameter file, how it was trained (dataset, config — with the name the model is
  selected by —, epochs, validation loss) and ``sha256``, the SHA-256 of the rest of the
  description (:func:`description_hash`), so that the name, the architecture and the weights
  are all covered by a hash.

:func:`load_model` checks every field of the description (:func:`check_description`: types,
ranges, finite numbers, a known rig, a selectable name, its hash), rebuilds the model from the
config, refuses a parameter file written for another architecture, naming the mismatching
field, and refuses weights that are not finite.  :func:`model_policy` wraps a model as a
pure ``init/act`` policy; the frozen token-embedding table travels in the policy parameters
(not as a constant baked into the compiled rollout).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx, serialization, struct

from lantern_jax.io.files import atomic_write
from lantern_jax.policies.base import Policy
from lantern_jax.policies.learned.features import RIGS, features, nav_token_table
from lantern_jax.policies.learned.model import (
    OBJECT_POOLS,
    TEXT_ENCODERS,
    DrivingModel,
    ModelConfig,
)
from lantern_jax.policies.learned.shipped import SHIPPED_MODELS
from lantern_jax.policies.names import name_problem
from lantern_jax.types.language import load_embedding
from lantern_jax.types.observation import FRONT_CAMERA, SURROUND_RIG, WARNING, Observation

#: Field of a description holding the SHA-256 of the rest of it.
DESCRIPTION_HASH = "sha256"

Array = jax.Array


class CheckpointError(ValueError):
    """A checkpoint that does not fit the model it is loaded into; names the file and field."""


class CheckpointNameTaken(CheckpointError):
    """A checkpoint whose name is already registered for another policy."""


@struct.dataclass
class LearnedParams:
    """Parameters of a learned policy: trained weights plus the frozen text inputs.

    The architecture (graph and configuration) is a static part of the tree, so every model
    runs through the one act function :func:`learned_act`: models of one architecture and
    sensors are one compiled program (their weights are arguments).
    """

    model: Any  # nnx.State of the model's parameters
    embedding: Array  # (V, D) float32, frozen token-embedding table
    nav_tokens: Array  # (3, L) int32, token ids of the navigation instructions
    graphdef: Any = struct.field(pytree_node=False, default=None)  # nnx graph of the model
    config: ModelConfig = struct.field(pytree_node=False, default=None)


def new_model(config: ModelConfig, seed: int = 0) -> DrivingModel:
    """A freshly initialised model."""
    return DrivingModel(config, nnx.Rngs(seed))


def learned_act(params: LearnedParams, obs: Observation) -> Array:
    """The act function of every learned model: ``(10, 2)`` waypoints of the model in
    ``params`` (its graph, configuration and weights) for one observation."""
    model = nnx.merge(params.graphdef, params.model)
    return model(features(obs, params.config.rig, params.embedding, params.nav_tokens))


def make_act(config: ModelConfig, graphdef: Any):
    """The pure ``act(params, obs) -> (10, 2)`` of a model architecture, for parameters whose
    weights are ``params.model`` (a plain :class:`LearnedParams` of that architecture)."""

    def act(params: LearnedParams, obs: Observation) -> Array:
        return learned_act(params.replace(graphdef=graphdef, config=config), obs)

    return act


def model_sensors(config: ModelConfig) -> tuple[str, ...]:
    """The sensors a model architecture reads: the front camera, the six-camera rig for the
    surround rig, the warning text for a language model."""
    sensors = [FRONT_CAMERA]
    if config.rig == "surround":
        sensors.append(SURROUND_RIG)
    if config.language:
        sensors.append(WARNING)
    return tuple(sensors)


def learned_params(model: DrivingModel, embedding: Array | None = None) -> LearnedParams:
    """The policy parameters of a model (loads the shipped embedding table when not given)."""
    if embedding is None:
        embedding = load_embedding()
    graphdef, state = nnx.split(model)
    return LearnedParams(state, jnp.asarray(embedding, jnp.float32),
                         jnp.asarray(nav_token_table()), graphdef, model.config)  # fmt: skip


def model_policy(name: str, model: DrivingModel, description: str = "",
                 embedding: Array | None = None) -> Policy:  # fmt: skip
    """A trained model as a :class:`~lantern_jax.policies.base.Policy` (act:
    :func:`learned_act`)."""
    params = learned_params(model, embedding)
    return Policy(name, lambda key: params, learned_act, description,
                  sensors=model_sensors(model.config))  # fmt: skip


def description_hash(meta: dict) -> str:
    """SHA-256 of a checkpoint description without its own ``sha256`` field (canonical JSON:
    sorted keys, no spaces)."""
    body = {k: v for k, v in meta.items() if k != DESCRIPTION_HASH}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def save_model(model: DrivingModel, path: str | Path, info: dict | None = None) -> Path:
    """Write ``<path>.msgpack`` and ``<path>.json``; returns the msgpack path.

    The description is written second: a kill between the two writes leaves a pair whose
    hashes disagree, which :func:`load_model` refuses.
    """

    path = Path(path).with_suffix("")
    _, state = nnx.split(model)
    data = serialization.to_bytes(state.to_pure_dict())
    weights = path.with_suffix(".msgpack")
    atomic_write(weights, data)
    meta = dict(config=dataclasses.asdict(model.config),
                params_sha256=hashlib.sha256(data).hexdigest(), **(info or {}))  # fmt: skip
    meta[DESCRIPTION_HASH] = description_hash(meta)
    atomic_write(path.with_suffix(".json"), json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return weights


def read_meta(path: str | Path) -> dict:
    """The JSON description of a checkpoint (``<path>.json``), as written (unchecked)."""
    meta_path = Path(path).with_suffix(".json")
    try:
        return json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{meta_path}: not a readable checkpoint description ({e})") from None


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _is_sha256(v: object) -> bool:
    return isinstance(v, str) and len(v) == 64 and set(v) <= set("0123456789abcdef")


#: ModelConfig fields added after checkpoints were first written: a description without one
#: describes a model built with the field's default (the architecture of that time).
LATER_CONFIG_FIELDS = ("text_encoder", "text_layers", "object_pool", "modes")
#: The accepted values of a ModelConfig field of type str.
_CHOICES = {"rig": RIGS, "text_encoder": TEXT_ENCODERS, "object_pool": OBJECT_POOLS}


def _config_problem(raw: object) -> tuple[str, str] | None:
    """(field, problem) of a description's ``config`` object, or None when it is valid."""
    if not isinstance(raw, dict):
        return "config", f"expected a JSON object, got {type(raw).__name__} {raw!r}"
    fields = {f.name: f for f in dataclasses.fields(ModelConfig)}
    for key in raw:
        if key not in fields:
            return f"config.{key}", f"unknown field (known: {', '.join(fields)})"
    for key, f in fields.items():
        if key not in raw:
            if key in LATER_CONFIG_FIELDS:
                continue
            return f"config.{key}", "missing"
        v = raw[key]
        choices = _CHOICES.get(key)
        if choices is not None and v not in choices:
            return f"config.{key}", f"{v!r} not one of {', '.join(choices)}"
        if f.type == "bool" and not isinstance(v, bool):
            return f"config.{key}", f"expected true or false, got {v!r}"
        if f.type == "int" and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            return f"config.{key}", f"expected a whole number >= 1, got {v!r}"
    if raw["width"] % raw["heads"]:
        return "config.heads", f"{raw['heads']} does not divide width {raw['width']}"
    return None


def _description_problem(meta: object) -> tuple[str, str] | None:
    """(field, problem) of a checkpoint description, or None when every field is valid."""
    if not isinstance(meta, dict):
        return "(top level)", f"expected a JSON object, got {type(meta).__name__}"
    for key in ("config", "params_sha256", DESCRIPTION_HASH):
        if key not in meta:
            return key, "missing" + (
                " (written by an earlier lantern-jax: export the model again with save_model)"
                if key == DESCRIPTION_HASH
                else ""
            )
    problem = _config_problem(meta["config"])
    if problem:
        return problem
    for key in ("params_sha256", DESCRIPTION_HASH):
        if not _is_sha256(meta[key]):
            return key, f"expected a 64-digit lowercase hex string, got {meta[key]!r}"
    for key in ("dataset", "recipe"):
        if key in meta and not isinstance(meta[key], str):
            return key, f"expected a string, got {meta[key]!r}"
    if "epoch" in meta and (isinstance(meta["epoch"], bool) or not isinstance(meta["epoch"], int)
                            or meta["epoch"] < 0):  # fmt: skip
        return "epoch", f"expected a whole number >= 0, got {meta['epoch']!r}"
    if "val_l1_m" in meta and not (_is_number(meta["val_l1_m"]) and meta["val_l1_m"] >= 0):
        return "val_l1_m", f"expected a finite number >= 0, got {meta['val_l1_m']!r}"
    trained = meta.get("train_config", {})
    if not isinstance(trained, dict):
        return "train_config", f"expected a JSON object, got {type(trained).__name__}"
    if "name" in trained and name_problem(trained["name"]):
        return "train_config.name", name_problem(trained["name"])
    try:
        digest = description_hash(meta)
    except ValueError as e:  # NaN or infinity somewhere
        return "(values)", f"not representable in strict JSON ({e})"
    if digest != meta[DESCRIPTION_HASH]:
        return DESCRIPTION_HASH, "does not match the description (edited after it was written?)"
    return None


def check_description(path: str | Path, meta: object) -> ModelConfig:
    """Check every field of a checkpoint description; returns its architecture.

    Args:
        path: the checkpoint (for the messages).
        meta: the parsed ``.json``.

    Raises:
        CheckpointError: naming the file and the first bad field: a missing config, hash or
            name field, a wrong type, a number out of range or not finite, an unknown rig or
            config field, a name the command line cannot select, a description whose
            ``sha256`` does not match it.
    """
    problem = _description_problem(meta)
    if problem:
        raise CheckpointError(f"{Path(path).with_suffix('.json')}: {problem[0]}: {problem[1]}")
    return ModelConfig(**meta["config"])


def load_model(path: str | Path, expect: ModelConfig | None = None) -> DrivingModel:
    """Rebuild a saved model.

    Raises:
        CheckpointError: naming the file and field when the description is not valid
            (:func:`check_description`), its architecture differs from ``expect``, the weights
            do not match their recorded hash, their shapes do not fit the architecture or they
            are not finite.
    """
    path = Path(path).with_suffix("")
    meta = read_meta(path)
    config = check_description(path, meta)
    fields = {f.name for f in dataclasses.fields(ModelConfig)}
    if expect is not None:
        for f in fields:
            if getattr(expect, f) != getattr(config, f):
                raise CheckpointError(
                    f"{path.with_suffix('.json')}: config.{f}: checkpoint has "
                    f"{getattr(config, f)!r}, expected {getattr(expect, f)!r}"
                )
    weights = path.with_suffix(".msgpack")
    data = weights.read_bytes()
    if hashlib.sha256(data).hexdigest() != meta.get("params_sha256"):
        raise CheckpointError(f"{weights}: content does not match params_sha256 of its .json")
    # The architecture's shapes only: a random initialisation would compile and run every
    # initialiser op by op, to be overwritten (0.4 s a model with JAX's cache, 2 s without, on
    # a 2-core CPU; ``benchmarks/bench_model_load.py``).
    graphdef, state = nnx.split(nnx.eval_shape(lambda: new_model(config)))
    template = state.to_pure_dict()
    try:
        loaded = serialization.from_bytes(template, data)
    except Exception as e:  # noqa: BLE001 - any decoding problem is a mismatch
        raise CheckpointError(f"{weights}: does not fit the architecture ({e})") from None
    bad = [jax.tree_util.keystr(p) for (p, a), (_, b) in zip(
        jax.tree_util.tree_leaves_with_path(template), jax.tree_util.tree_leaves_with_path(loaded),
        strict=True) if tuple(a.shape) != np.shape(b)]  # fmt: skip
    if bad:
        raise CheckpointError(f"{weights}: parameter {bad[0]} has another shape")
    bad = [jax.tree_util.keystr(p) for p, a in jax.tree_util.tree_leaves_with_path(loaded)
           if not np.isfinite(np.asarray(a)).all()]  # fmt: skip
    if bad:
        raise CheckpointError(f"{weights}: parameter {bad[0]} holds values that are not finite "
                              "(NaN or infinity)")  # fmt: skip
    state.replace_by_pure_dict(loaded)
    return nnx.merge(graphdef, state)


SHIPPED_DIR = "data/models"  # inside the package: the default checkpoints of the learned rows


def shipped_path(name: str) -> Path:
    """Where the package ships the default checkpoint of ``name``."""

    return Path(str(resources.files("lantern_jax") / SHIPPED_DIR / f"{name}.msgpack"))


def checkpoint_policy(path: str | Path, name: str | None = None) -> Policy:
    """The policy of a saved model (name: the one it was trained under, unless given).

    Raises:
        CheckpointError: for a missing or mismatching checkpoint (see :func:`load_model`).
    """
    path = Path(path)
    if not path.with_suffix(".msgpack").exists():
        raise CheckpointError(f"{path.with_suffix('.msgpack')}: no such checkpoint "
                              "(train one with 'lantern-jax train --config ...')")  # fmt: skip
    meta = read_meta(path)
    model = load_model(path)
    trained = meta.get("train_config", {})
    label = name or trained.get("name") or path.stem
    if name_problem(label):
        where = "name" if name else "train_config.name" if trained.get("name") else "file name"
        raise CheckpointError(f"{path.with_suffix('.msgpack')}: {where}: {name_problem(label)}")
    desc = SHIPPED_MODELS.get(label, f"learned {trained.get('recipe', '')} model from {path.name}")
    return model_policy(label, model, desc)
