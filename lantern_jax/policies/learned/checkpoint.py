"""Trained driving models as policies, and their portable checkpoint files.

A shipped (exported) model is two files side by side:

* ``<name>.msgpack`` — the model's parameters (:func:`flax.serialization.to_bytes` of the NNX
  parameter state, a few hundred kB);
* ``<name>.json`` — its :class:`~lantern_jax.policies.learned.model.ModelConfig`, the SHA-256
  of the parameter file, and how it was trained (dataset, config, epochs, validation loss).

:func:`load_model` rebuilds the model from the config and refuses a parameter file written for
another architecture, naming the mismatching field.  :func:`model_policy` wraps a model as a
pure ``init/act`` policy; the frozen token-embedding table travels in the policy parameters
(not as a constant baked into the compiled rollout).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
from flax import nnx, serialization, struct

from lantern_jax.observation import FRONT_CAMERA, SURROUND_RIG, WARNING, Observation
from lantern_jax.policies.base import Policy
from lantern_jax.policies.learned.features import features, nav_token_table
from lantern_jax.policies.learned.model import DrivingModel, ModelConfig
from lantern_jax.policies.learned.shipped import SHIPPED_MODELS

Array = jax.Array


class CheckpointError(ValueError):
    """A checkpoint that does not fit the model it is loaded into; names the file and field."""


@struct.dataclass
class LearnedParams:
    """Parameters of a learned policy: trained weights plus the frozen text inputs."""

    model: Any  # nnx.State of the model's parameters
    embedding: Array  # (V, D) float32, frozen token-embedding table
    nav_tokens: Array  # (3, L) int32, token ids of the navigation instructions


def new_model(config: ModelConfig, seed: int = 0) -> DrivingModel:
    """A freshly initialised model."""
    return DrivingModel(config, nnx.Rngs(seed))


def make_act(config: ModelConfig, graphdef: Any):
    """The pure ``act(params, obs) -> (10, 2)`` of a model architecture."""

    def act(params: LearnedParams, obs: Observation) -> Array:
        model = nnx.merge(graphdef, params.model)
        return model(features(obs, config.rig, params.embedding, params.nav_tokens))

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
        from lantern_jax.language import load_embedding

        embedding = load_embedding()
    _, state = nnx.split(model)
    return LearnedParams(state, jnp.asarray(embedding, jnp.float32),
                         jnp.asarray(nav_token_table()))  # fmt: skip


def model_policy(name: str, model: DrivingModel, description: str = "",
                 embedding: Array | None = None) -> Policy:  # fmt: skip
    """A trained model as a :class:`~lantern_jax.policies.base.Policy`."""
    graphdef, _ = nnx.split(model)
    params = learned_params(model, embedding)
    return Policy(name, lambda key: params, make_act(model.config, graphdef), description,
                  sensors=model_sensors(model.config))  # fmt: skip


def save_model(model: DrivingModel, path: str | Path, info: dict | None = None) -> Path:
    """Write ``<path>.msgpack`` and ``<path>.json``; returns the msgpack path."""
    from lantern_jax.files import atomic_write

    path = Path(path).with_suffix("")
    _, state = nnx.split(model)
    data = serialization.to_bytes(state.to_pure_dict())
    weights = path.with_suffix(".msgpack")
    atomic_write(weights, data)
    meta = dict(config=dataclasses.asdict(model.config),
                params_sha256=hashlib.sha256(data).hexdigest(), **(info or {}))  # fmt: skip
    atomic_write(path.with_suffix(".json"), json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return weights


def read_meta(path: str | Path) -> dict:
    """The JSON description of a checkpoint (``<path>.json``)."""
    meta_path = Path(path).with_suffix(".json")
    try:
        return json.loads(meta_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{meta_path}: not a readable checkpoint description ({e})") from None


def load_model(path: str | Path, expect: ModelConfig | None = None) -> DrivingModel:
    """Rebuild a saved model.

    Raises:
        CheckpointError: naming the file and field when the description's architecture differs
            from ``expect``, the weights do not match their recorded hash, or their shapes do
            not fit the architecture.
    """
    path = Path(path).with_suffix("")
    meta = read_meta(path)
    fields = {f.name for f in dataclasses.fields(ModelConfig)}
    raw = meta.get("config", {})
    unknown = sorted(set(raw) - fields)
    if unknown:
        raise CheckpointError(f"{path.with_suffix('.json')}: config.{unknown[0]}: unknown field")
    config = ModelConfig(**raw)
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
    model = new_model(config)
    graphdef, state = nnx.split(model)
    template = state.to_pure_dict()
    try:
        loaded = serialization.from_bytes(template, data)
    except Exception as e:  # noqa: BLE001 - any decoding problem is a mismatch
        raise CheckpointError(f"{weights}: does not fit the architecture ({e})") from None
    bad = [jax.tree_util.keystr(p) for (p, a), (_, b) in zip(
        jax.tree_util.tree_leaves_with_path(template), jax.tree_util.tree_leaves_with_path(loaded),
        strict=True) if jnp.shape(a) != jnp.shape(b)]  # fmt: skip
    if bad:
        raise CheckpointError(f"{weights}: parameter {bad[0]} has another shape")
    state.replace_by_pure_dict(loaded)
    return nnx.merge(graphdef, state)


SHIPPED_DIR = "data/models"  # inside the package: the default checkpoints of the learned rows


def shipped_path(name: str) -> Path:
    """Where the package ships the default checkpoint of ``name``."""
    from importlib import resources

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
    desc = SHIPPED_MODELS.get(label, f"learned {trained.get('recipe', '')} model from {path.name}")
    return model_policy(label, model, desc)
