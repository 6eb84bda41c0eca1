"""``ppo``: an MLP driving policy trained with brax's PPO on :mod:`lantern_jax.apps.envs`.

The policy reads :func:`~lantern_jax.policies.features.observation_vector`, normalises it with
the observation statistics gathered during training, runs brax's default PPO policy network
(fully connected, swish between layers, no activation after the last) and takes the mode of
its tanh-squashed Gaussian, ``tanh(loc)``, as the action (acceleration, curvature), which
:func:`~lantern_jax.policies.features.action_to_waypoints` turns into waypoints.  It reads the
warning's words only as an exact match against twelve known texts (the one-hot slots of the
observation vector) and its position from the numbers the text writes.

Parameters come from a checkpoint file (msgpack written with ``flax.serialization``; no brax
needed to run the policy): the one shipped in ``lantern_jax/data`` (:data:`SHIPPED_CHECKPOINT`),
or the file named by the environment variable ``LANTERN_JAX_PPO_CHECKPOINT`` (e.g. written by
``lantern-jax train --config configs/train_ppo.toml``).  The layout (:func:`save_checkpoint`)::

    {"obs_mean": (D,), "obs_std": (D,),            float32, observation statistics
     "policy": {"hidden_0": {"kernel": (D, H), "bias": (H,)}, ..., "hidden_K": {...}},
     "meta": JSON text (observation size, action size, training summary)}
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from lantern_jax.io.files import atomic_write
from lantern_jax.policies.base import Policy
from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE, action_to_waypoints
from lantern_jax.policies.features import observation_vector as flat
from lantern_jax.types.observation import FRONT_CAMERA, WARNING, Observation

SHIPPED_CHECKPOINT = Path(__file__).resolve().parent.parent / "data" / "ppo_lantern.msgpack"
CHECKPOINT_ENV = "LANTERN_JAX_PPO_CHECKPOINT"


def checkpoint_path() -> Path:
    """The checkpoint the ``ppo`` policy loads (the environment variable wins)."""
    return Path(os.environ.get(CHECKPOINT_ENV) or SHIPPED_CHECKPOINT)


def save_checkpoint(path: str | Path, obs_mean, obs_std, policy_params: dict, meta: dict) -> None:
    """Write a checkpoint (atomically).

    Args:
        path: file to write.
        obs_mean, obs_std: (OBS_SIZE,) observation statistics.
        policy_params: ``{"hidden_i": {"kernel", "bias"}}`` of the policy MLP (brax's
            ``params["params"]``).
        meta: JSON-serialisable description (training settings and results).
    """
    tree = {
        "obs_mean": np.asarray(obs_mean, np.float32),
        "obs_std": np.asarray(obs_std, np.float32),
        "policy": jax.tree.map(lambda x: np.asarray(x, np.float32), dict(policy_params)),
        "meta": json.dumps({"obs_size": OBS_SIZE, "action_size": ACTION_SIZE, **meta}),
    }
    atomic_write(Path(path), serialization.msgpack_serialize(tree))


def load_checkpoint(path: str | Path | None = None) -> dict:
    """Read a checkpoint and check it fits the observation and action of this version.

    Raises:
        FileNotFoundError: naming the file and how to produce one.
        ValueError: naming the mismatching size.
    """
    path = checkpoint_path() if path is None else Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"ppo checkpoint {path} not found; train one with `lantern-jax train --config "
            f"configs/train_ppo.toml` or point {CHECKPOINT_ENV} at one"
        )
    where = f" (from {CHECKPOINT_ENV})" if os.environ.get(CHECKPOINT_ENV) and path == \
        checkpoint_path() else ""  # fmt: skip
    try:
        tree = serialization.msgpack_restore(path.read_bytes())
        meta = json.loads(tree["meta"])
        layers = [tree["policy"][f"hidden_{i}"] for i in range(len(tree["policy"]))]
        layers[0]["kernel"].shape, layers[-1]["kernel"].shape  # noqa: B018  (present)
    except Exception as e:  # noqa: BLE001  (any unreadable file: one message naming it)
        raise ValueError(f"ppo checkpoint {path}{where}: not a PPO checkpoint this project "
                         f"wrote ({type(e).__name__}: {e})") from None  # fmt: skip
    if meta.get("obs_size") != OBS_SIZE or layers[0]["kernel"].shape[0] != OBS_SIZE:
        raise ValueError(f"ppo checkpoint {path}: observation size {meta.get('obs_size')}, "
                         f"this version has {OBS_SIZE}")  # fmt: skip
    if layers[-1]["kernel"].shape[1] != 2 * ACTION_SIZE:
        raise ValueError(f"ppo checkpoint {path}: output size {layers[-1]['kernel'].shape[1]}, "
                         f"expected {2 * ACTION_SIZE} (loc and scale per action)")  # fmt: skip
    return {"obs_mean": tree["obs_mean"], "obs_std": tree["obs_std"], "layers": layers,
            "meta": meta}  # fmt: skip


def network_action(params: dict, x: jax.Array) -> jax.Array:
    """Deterministic action ``tanh(loc)`` of the policy MLP.

    Args:
        params: ``{"obs_mean", "obs_std", "layers": [{"kernel", "bias"}, ...]}``.
        x: (..., OBS_SIZE) float32 observation vector(s).

    Returns:
        (..., ACTION_SIZE) float32 in [-1, 1].
    """
    h = (x - params["obs_mean"]) / params["obs_std"]
    layers = params["layers"]
    for i, layer in enumerate(layers):
        h = h @ layer["kernel"] + layer["bias"]
        if i < len(layers) - 1:
            h = jax.nn.swish(h)
    loc = h[..., :ACTION_SIZE]
    return jnp.tanh(loc)


def ppo_act(params: dict, obs: Observation) -> jax.Array:
    """(10, 2) float32 waypoints of the trained policy for one observation."""
    action = network_action(params, flat(obs))
    return action_to_waypoints(action, obs.ego_speed)


def ppo_init(key: jax.Array) -> dict[str, Any]:
    """Parameters from the checkpoint (``key`` unused: the policy is trained, not sampled)."""
    del key
    ck = load_checkpoint()
    to = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    return {
        "obs_mean": to(ck["obs_mean"]),
        "obs_std": to(ck["obs_std"]),
        "layers": [{"kernel": to(l["kernel"]), "bias": to(l["bias"])} for l in ck["layers"]],
    }


def ppo_policy() -> Policy:
    """The PPO-trained MLP policy (front camera, warning text; see the module docstring)."""
    return Policy(
        "ppo",
        ppo_init,
        ppo_act,
        "MLP trained with PPO on the brax environment (acceleration, curvature); "
        f"checkpoint {checkpoint_path().name}",
        sensors=(FRONT_CAMERA, WARNING),
    )
