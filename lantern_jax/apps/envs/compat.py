"""Compatibility of brax's training code with the installed JAX.

``brax.training.agents.ppo.train`` (brax 0.14.2) calls ``jax.device_put_replicated``, which JAX
removed in 0.10 (open upstream: google/brax issue 671).  :func:`install` puts an equivalent
function on the ``jax`` module when it is missing: the value broadcast along a new leading axis
of one entry per device and placed with a ``NamedSharding`` over those devices, which is what
``pmap`` expects of its replicated inputs.  Call it before brax's training modules run (importing
:mod:`lantern_jax.apps.envs` does).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def device_put_replicated(x: Any, devices: Sequence[jax.Device]) -> Any:
    """Replicate every leaf of ``x`` on ``devices`` along a new leading axis (one per device)."""
    devices = list(devices)
    sharding = NamedSharding(Mesh(np.asarray(devices), ("replica",)), PartitionSpec("replica"))

    def put(leaf):
        a = jnp.asarray(leaf)
        return jax.device_put(jnp.broadcast_to(a[None], (len(devices), *a.shape)), sharding)

    return jax.tree.map(put, x)


def install() -> None:
    """Provide ``jax.device_put_replicated`` when the installed JAX lacks it."""
    if not hasattr(jax, "device_put_replicated"):
        jax.device_put_replicated = device_put_replicated
