"""Training wrappers: brax's episode and batching wrappers with resets to NEW scenes.

brax's ``AutoResetWrapper`` restores the ``pipeline_state`` and ``obs`` of an environment slot's
*first* state, so every slot would replay one scene for the whole training run.
:class:`SceneResetWrapper` takes its place: when an episode ends it draws a new scene from the
bank with a per-slot key carried in ``info["scene_rng"]`` (jittable: a reset is a gather from
the bank).  :func:`wrap_for_training` has the signature of ``brax.envs.training.wrap`` and can
be passed as ``wrap_env_fn`` to ``brax.training.agents.ppo.train``.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper


class SceneResetWrapper(Wrapper):
    """Resets a finished episode to a newly drawn scene (a batched env: ``VmapWrapper`` inside)."""

    def reset(self, rng: jax.Array) -> State:
        keys = jax.vmap(jax.random.split)(rng)  # (B, 2, 2): one for the scene, one to carry
        state = self.env.reset(keys[:, 0])
        state.info["scene_rng"] = keys[:, 1]
        return state

    def step(self, state: State, action: jax.Array) -> State:
        if "steps" in state.info:
            state.info["steps"] = jnp.where(state.done, 0, state.info["steps"])
        state = state.replace(done=jnp.zeros_like(state.done))
        state = self.env.step(state, action)
        keys = jax.vmap(jax.random.split)(state.info["scene_rng"])
        fresh = self.env.reset(keys[:, 0])
        done = state.done

        def where_done(new, old):
            mask = jnp.reshape(done, done.shape + (1,) * (old.ndim - done.ndim)) > 0
            return jnp.where(mask, new, old)

        state.info["scene_rng"] = keys[:, 1]
        return state.replace(
            pipeline_state=jax.tree.map(where_done, fresh.pipeline_state, state.pipeline_state),
            obs=where_done(fresh.obs, state.obs),
        )


def wrap_for_training(
    env: Env,
    episode_length: int = 1000,
    action_repeat: int = 1,
    randomization_fn: Callable | None = None,
) -> Wrapper:
    """``VmapWrapper`` + ``EpisodeWrapper`` + :class:`SceneResetWrapper` (brax's ``wrap`` with
    true resets).  ``randomization_fn`` is not supported (scenes come from the bank)."""
    if randomization_fn is not None:
        raise ValueError("wrap_for_training: domain randomization is not supported; "
                         "scenes are drawn from the environment's bank")  # fmt: skip
    env = VmapWrapper(env)
    env = EpisodeWrapper(env, episode_length, action_repeat)
    return SceneResetWrapper(env)
