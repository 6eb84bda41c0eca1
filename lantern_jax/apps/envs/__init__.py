"""Reinforcement learning on the benchmark with brax (optional extra ``lantern-jax[rl]``).

Importing this package imports brax, installs the JAX compatibility function brax's PPO needs
(:mod:`lantern_jax.apps.envs.compat`) and registers the environment with brax as ``lantern``::

    import lantern_jax.apps.envs
    from brax import envs
    env = envs.get_environment("lantern", pairs_per_family=4)

:class:`~lantern_jax.apps.envs.vector.LanternVectorEnv` offers the same environment, batched, behind
the Gymnasium vector API over NumPy arrays (for CleanRL- or Stable-Baselines3-style loops).

``import lantern_jax`` alone never imports brax.
"""

from __future__ import annotations

from lantern_jax.apps.envs.quiet import filtered_stdout

try:
    with filtered_stdout():  # MJX's "Failed to import warp" lines (lantern_jax.apps.envs.quiet)
        from brax import envs as _brax_envs
except ModuleNotFoundError as _missing:  # the plain install has no brax
    raise ModuleNotFoundError(
        f"lantern_jax.apps.envs (the brax environment and the Gymnasium vector environment) needs "
        f"the 'rl' extra: pip install -e '.[rl]' (or pip install 'lantern-jax[rl]'); "
        f"{_missing}"
    ) from _missing

from lantern_jax.apps.envs import compat  # noqa: E402
from lantern_jax.apps.envs.bank import ScenarioBank, build_bank
from lantern_jax.apps.envs.env import EnvState, LanternEnv
from lantern_jax.apps.envs.vector import LanternVectorEnv
from lantern_jax.apps.envs.wrappers import SceneResetWrapper, wrap_for_training

compat.install()
ENV_NAME = "lantern"
_brax_envs.register_environment(ENV_NAME, LanternEnv)  # a repeated registration overwrites

__all__ = [
    "ENV_NAME",
    "EnvState",
    "LanternEnv",
    "LanternVectorEnv",
    "ScenarioBank",
    "SceneResetWrapper",
    "build_bank",
    "wrap_for_training",
]
