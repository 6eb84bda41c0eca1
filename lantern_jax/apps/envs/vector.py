"""The benchmark as a Gymnasium-style vector environment over NumPy arrays.

:class:`LanternVectorEnv` runs ``num_envs`` executions of :class:`~lantern_jax.apps.envs.LanternEnv`
side by side with the same batched, jitted ``reset``/``step`` the PPO training uses
(:func:`~lantern_jax.apps.envs.wrap_for_training`: ``VmapWrapper``, brax's ``EpisodeWrapper`` and
:class:`~lantern_jax.apps.envs.SceneResetWrapper`, which starts a *newly drawn* scene of the bank
when an episode ends), and speaks the Gymnasium 1.x ``VectorEnv`` API, so that training loops
written for Gymnasium vector environments (CleanRL, Stable-Baselines3-style loops) run on it::

    from lantern_jax.apps.envs import LanternVectorEnv
    envs = LanternVectorEnv(num_envs=8, pairs_per_family=4, seed=0)
    obs, info = envs.reset(seed=0)                      # (8, OBS_SIZE) float32
    obs, rew, term, trunc, infos = envs.step(actions)   # actions (8, ACTION_SIZE) float32
    envs.close()

Arrays (``B = num_envs``; the observation and action are documented slot by slot in
:mod:`lantern_jax.policies.features`):

* observation: (B, ``OBS_SIZE`` = 276) float32, every slot scaled to roughly [-2, 2]
  (positions / 50 m, speeds / 10 m/s, ...);
* action: (B, ``ACTION_SIZE`` = 2) float32 in [-1, 1]: acceleration (x 3 m/s^2 forward,
  x 8 m/s^2 braking) and path curvature (x ``KAPPA_MAX`` 1/m, + = left); values outside [-1, 1]
  are clipped by the environment, as in training;
* reward: (B,) float32, unitless, the change of the running route score
  (:mod:`lantern_jax.apps.envs.reward`): an episode's undiscounted return is the route's score in
  [0, 1], or ``-GATE_PENALTY`` = -1 when a gate fails;
* terminations, truncations: (B,) bool.

**Autoreset: Gymnasium's ``AutoresetMode.SAME_STEP``** (``metadata["autoreset_mode"]``).  On the
step an episode ends, ``terminations[i] | truncations[i]`` is true, ``rewards[i]`` is the reward
of the episode's last tick, and ``obs[i]`` is already the *first observation of the next
episode* (a new scene drawn from the bank); the ending episode's last observation is in
``infos["final_obs"][i]``.  The next ``step`` acts in the new episode; no action is skipped.
When at least one episode ended, ``infos`` holds (as Gymnasium's ``SyncVectorEnv`` in
``SAME_STEP`` mode and its ``RecordEpisodeStatistics`` wrapper write them, each array with a
``"_<key>"`` (B,) bool mask of the rows that are set; unset rows are zeros):

* ``infos["final_obs"]``: (B, OBS_SIZE) float32, the last observation of each ended episode;
* ``infos["episode"]``: a dict of (B,) arrays over each ended episode: ``"r"`` float32 return
  (unitless), ``"l"`` int32 length (steps, 0.05 s each), ``"t"`` float32 wall-clock seconds
  since the episode started, and the environment's summed metrics ``"progress"`` float32 (route
  completion P in [0, 1]), ``"gate_failure"`` float32 (1 = a gate failed), ``"completed"``
  float32 (1 = the route was completed with every gate passed), plus ``"route_timeout"`` bool
  (the route's clock reached its timeout on the last tick, see below).

**Terminations and truncations.**  Every end of the execution is a *termination*, including the
route's timeout: the benchmark scores an unfinished route at the timeout as a failed gate, the
reward pays ``-GATE_PENALTY`` for it, and that is the episode's true final return -- there is
nothing to bootstrap beyond it.  ``infos["episode"]["route_timeout"]`` says which terminations
were timeouts, for a learner that prefers to treat them otherwise.  A *truncation* is only the
step cap ``max_episode_steps`` (brax's ``EpisodeWrapper``, the ``episode_length`` of the PPO
training), which is not part of the task; with the default (1000 steps = 50 s) it is rarely
reached before a route's timeout.

**Spaces.**  ``single_observation_space``, ``single_action_space``, ``observation_space`` and
``action_space`` are ``gymnasium.spaces.Box`` when ``gymnasium`` can be imported (it is imported
only then, when the environment is built; it is not a dependency of the package), otherwise
:class:`BoxSpec` objects with the same ``shape``, ``dtype``, ``low`` and ``high``.
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
import time

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper

from lantern_jax.apps.envs.bank import TRAIN_SEED, ScenarioBank, build_bank
from lantern_jax.apps.envs.env import METRICS, LanternEnv
from lantern_jax.apps.envs.wrappers import SceneResetWrapper
from lantern_jax.core.constants import FAMILIES
from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings

#: Step cap of an episode (the PPO training's ``episode_length``): 1000 ticks = 50 s.
MAX_EPISODE_STEPS = 1000


@dataclasses.dataclass(frozen=True)
class BoxSpec:
    """A box of arrays, for when ``gymnasium`` is not installed (``gymnasium.spaces.Box``'s
    ``shape``, ``dtype``, ``low`` and ``high``; ``low``/``high`` have the shape ``shape``)."""

    low: np.ndarray
    high: np.ndarray
    shape: tuple[int, ...]
    dtype: np.dtype

    def contains(self, x) -> bool:
        """Whether ``x`` has this box's shape and lies within ``[low, high]``."""
        x = np.asarray(x)
        return x.shape == self.shape and bool(np.all((x >= self.low) & (x <= self.high)))


def _box(low: float, high: float, shape: tuple[int, ...]):
    """A float32 box: ``gymnasium.spaces.Box`` when gymnasium is importable, else a BoxSpec."""
    lo = np.full(shape, low, np.float32)
    hi = np.full(shape, high, np.float32)
    try:
        # deferred: gymnasium is optional (with brax, the rl extra)
        from gymnasium import spaces
    except ImportError:
        return BoxSpec(low=lo, high=hi, shape=tuple(shape), dtype=np.dtype(np.float32))
    return spaces.Box(low=lo, high=hi, shape=tuple(shape), dtype=np.float32)


def _autoreset_mode():
    try:
        # deferred: gymnasium is optional (with brax, the rl extra)
        from gymnasium.vector import AutoresetMode
    except ImportError:  # gymnasium missing, or older than 1.1
        return "SameStep"  # the value of gymnasium.vector.AutoresetMode.SAME_STEP
    return AutoresetMode.SAME_STEP


class _KeepFinal(Wrapper):
    """Keeps what :class:`~lantern_jax.apps.envs.SceneResetWrapper` replaces on a reset: the step's
    observation (``info["final_obs"]``, (B, OBS_SIZE) float32) and whether the execution ended
    at the route's timeout (``info["route_timeout"]``, (B,) bool).  Batched (inside the
    ``VmapWrapper``), between the ``EpisodeWrapper`` and the scene reset."""

    def __init__(self, env, bank: ScenarioBank):
        super().__init__(env)
        self._timeout_s = bank.scenarios.config.timeout_s  # (N,) float32, s

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["final_obs"] = state.obs
        state.info["route_timeout"] = jnp.zeros(state.done.shape, bool)
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = self.env.step(state, action)
        ps = state.pipeline_state
        clock_out = ps.sim.t >= self._timeout_s[ps.index]
        state.info["final_obs"] = state.obs
        state.info["route_timeout"] = ps.sim.done & clock_out & (state.metrics["completed"] == 0)
        return state


def _wrapped(parts: tuple, settings: Settings, max_episode_steps: int) -> Wrapper:
    """wrap_for_training's composition over the bank ``parts`` (its fields, traced arrays), with
    _KeepFinal before the scene reset replaces the observation."""
    bank = ScenarioBank(*parts)
    episodes = EpisodeWrapper(VmapWrapper(LanternEnv(bank, settings)), max_episode_steps, 1)
    return SceneResetWrapper(_KeepFinal(episodes, bank))


# The bank is an argument, not a constant of the program: environments over banks of one size
# (and the same settings and step cap) share one compilation.
@functools.partial(jax.jit, static_argnums=(1, 2))
def _reset(parts: tuple, settings: Settings, max_episode_steps: int, keys: jax.Array) -> State:
    return _wrapped(parts, settings, max_episode_steps).reset(keys)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _step(parts: tuple, settings: Settings, max_episode_steps: int, state: State, action):
    nxt = _wrapped(parts, settings, max_episode_steps).step(state, action)
    info = nxt.info
    truncated = info["truncation"] > 0
    ended = nxt.done > 0
    episode = {k: info["episode_metrics"][k] for k in ("sum_reward", "length", *METRICS)}
    out = dict(
        obs=nxt.obs,
        reward=nxt.reward,
        terminated=ended & ~truncated,
        truncated=truncated,
        final_obs=info["final_obs"],
        route_timeout=info["route_timeout"] & ended,
        episode=episode,
    )
    return nxt, out


class LanternVectorEnv:
    """``num_envs`` executions of the benchmark behind the Gymnasium 1.x vector API (see the
    module docstring for the arrays, the autoreset and the spaces).

    Args:
        num_envs: executions stepped together (B >= 1).
        bank: the scenes to draw from; default: :func:`~lantern_jax.apps.envs.build_bank` with
            ``pairs_per_family``, ``bank_seed`` and ``families`` (as
            ``apps/envs/ppo_training.py`` builds its training scenes).
        settings: scoring, protocol and text bank of the simulation (the reward reads the
            scoring settings).
        seed: seed of the scene draws when :meth:`reset` is first called without one.
        max_episode_steps: step cap of an episode (steps of 0.05 s); reaching it is a
            truncation.
        pairs_per_family, bank_seed, families: the default bank's size, generator seed and
            family codes (ignored when ``bank`` is given).

    Raises:
        ValueError: ``num_envs`` or ``max_episode_steps`` below 1.
    """

    metadata = {"autoreset_mode": _autoreset_mode()}
    render_mode = None
    spec = None

    def __init__(
        self,
        num_envs: int,
        bank: ScenarioBank | None = None,
        settings: Settings = DEFAULT_SETTINGS,
        seed: int = 0,
        max_episode_steps: int = MAX_EPISODE_STEPS,
        pairs_per_family: int = 16,
        bank_seed: int = TRAIN_SEED,
        families: tuple[str, ...] | list[str] = FAMILIES,
    ):
        for name, value in (("num_envs", num_envs), ("max_episode_steps", max_episode_steps)):
            whole = isinstance(value, numbers.Integral) and not isinstance(value, bool)
            if not whole:
                raise TypeError(f"LanternVectorEnv: {name} must be a whole number, got {value!r}")
        if int(num_envs) < 1:
            raise ValueError(f"LanternVectorEnv: num_envs must be >= 1, got {num_envs}")
        if int(max_episode_steps) < 1:
            raise ValueError(
                f"LanternVectorEnv: max_episode_steps must be >= 1, got {max_episode_steps}"
            )
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.bank = build_bank(pairs_per_family, bank_seed, families) if bank is None else bank
        self.settings = settings.validate()
        b = self.bank
        self._parts = (b.scenarios, b.states, jnp.asarray(b.family), jnp.asarray(b.route))
        self._key = jax.random.PRNGKey(int(seed))
        self._state: State | None = None
        self._started = np.zeros(self.num_envs, np.float64)  # wall clock at episode start, s
        self.closed = False
        self.single_observation_space = _box(-np.inf, np.inf, (OBS_SIZE,))
        self.single_action_space = _box(-1.0, 1.0, (ACTION_SIZE,))
        self.observation_space = _box(-np.inf, np.inf, (self.num_envs, OBS_SIZE))
        self.action_space = _box(-1.0, 1.0, (self.num_envs, ACTION_SIZE))

    @property
    def unwrapped(self) -> LanternVectorEnv:
        """This environment (there are no wrappers)."""
        return self

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Start a new episode in every slot, each on a scene drawn from the bank.

        Args:
            seed: re-seeds the scene draws (an int); ``None`` continues from the current key
                (the constructor's ``seed`` on the first call).
            options: not used; must be ``None`` or empty.

        Returns:
            ``(obs, info)``: obs (num_envs, OBS_SIZE) float32 (see the module docstring), and an
            empty info dict.

        Raises:
            ValueError: ``seed`` is not an int, or ``options`` is not empty.
            RuntimeError: the environment is closed.
        """
        self._check_open()
        if options:
            raise ValueError(f"LanternVectorEnv.reset: no options are supported, got {options!r}")
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
                raise ValueError(f"LanternVectorEnv.reset: seed must be an int, got {seed!r}")
            self._key = jax.random.PRNGKey(int(seed))
        self._key, sub = jax.random.split(self._key)
        keys = jax.random.split(sub, self.num_envs)
        self._state = _reset(self._parts, self.settings, self.max_episode_steps, keys)
        self._started[:] = time.perf_counter()
        return np.array(self._state.obs, np.float32), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every slot by one 0.05 s tick; ended episodes restart on a new scene.

        Args:
            actions: (num_envs, ACTION_SIZE) float array (any float dtype, used as float32),
                finite, in [-1, 1] (clipped): acceleration, curvature.

        Returns:
            ``(obs, rewards, terminations, truncations, infos)``: obs (num_envs, OBS_SIZE)
            float32 (the next episode's first observation where one ended); rewards
            (num_envs,) float32; terminations and truncations (num_envs,) bool; infos with
            ``"final_obs"`` and ``"episode"`` (and their masks) when an episode ended -- see
            the module docstring.

        Raises:
            ValueError: ``actions`` has the wrong shape or a non-float dtype, or is not finite.
            RuntimeError: :meth:`reset` has not been called, or the environment is closed.
        """
        self._check_open()
        if self._state is None:
            raise RuntimeError("LanternVectorEnv.step: call reset() first")
        act = self._check_actions(actions)
        static = (self.settings, self.max_episode_steps)
        self._state, out = _step(self._parts, *static, self._state, jnp.asarray(act))
        out = jax.device_get(out)
        now = time.perf_counter()
        terminated = np.asarray(out["terminated"], bool)
        truncated = np.asarray(out["truncated"], bool)
        ended = terminated | truncated
        infos: dict = {}
        if ended.any():
            keep = ended[:, None]
            infos["final_obs"] = np.where(keep, out["final_obs"], 0.0).astype(np.float32)
            infos["_final_obs"] = ended.copy()
            ep = out["episode"]
            episode = {
                "r": np.where(ended, ep["sum_reward"], 0.0).astype(np.float32),
                "l": np.where(ended, ep["length"], 0).astype(np.int32),
                "t": np.where(ended, now - self._started, 0.0).astype(np.float32),
            }
            for name in METRICS:
                episode[name] = np.where(ended, ep[name], 0.0).astype(np.float32)
            episode["route_timeout"] = np.asarray(out["route_timeout"], bool) & ended
            infos["episode"] = episode
            infos["_episode"] = ended.copy()
            self._started[ended] = now
        obs = np.array(out["obs"], np.float32)
        rewards = np.array(out["reward"], np.float32)
        return obs, rewards, terminated, truncated, infos

    def close(self) -> None:
        """Release the batched state; later calls to reset or step raise (idempotent)."""
        self._state = None
        self.closed = True

    def __enter__(self) -> LanternVectorEnv:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"LanternVectorEnv(num_envs={self.num_envs}, scenes={self.bank.size})"

    # --- checks -----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("LanternVectorEnv: the environment is closed")

    def _check_actions(self, actions) -> np.ndarray:
        expected = (self.num_envs, ACTION_SIZE)
        try:
            act = np.asarray(actions)
        except Exception as err:  # ragged lists and the like
            raise ValueError(f"LanternVectorEnv.step: actions must be a {expected} float "
                             f"array, got {type(actions).__name__}") from err  # fmt: skip
        if act.shape != expected:
            raise ValueError(
                f"LanternVectorEnv.step: actions must have shape {expected} "
                f"(num_envs, ACTION_SIZE), got {act.shape}"
            )
        if not np.issubdtype(act.dtype, np.floating):
            raise ValueError(f"LanternVectorEnv.step: actions must be a {expected} float array "
                             f"(float32), got dtype {act.dtype}")  # fmt: skip
        if not np.all(np.isfinite(act)):
            bad = sorted({int(i) for i in np.nonzero(~np.isfinite(act))[0]})
            raise ValueError(f"LanternVectorEnv.step: actions of shape {expected} must be "
                             f"finite; rows {bad} are not")  # fmt: skip
        return act.astype(np.float32)
