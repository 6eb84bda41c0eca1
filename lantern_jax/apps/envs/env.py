"""The benchmark as a brax environment: one execution of a scene per episode, one tick per step.

``LanternEnv`` subclasses :class:`brax.envs.Env` directly (there is no physics pipeline):

* ``reset(rng)`` draws a scene from a :class:`~lantern_jax.apps.envs.bank.ScenarioBank` (``rng`` is
  a raw ``jax.random.PRNGKey``) and starts its execution;
* ``step(state, action)`` maps the action (acceleration and curvature in [-1, 1]) to waypoints
  (:func:`lantern_jax.policies.features.action_to_waypoints`) and advances the world one 20 Hz
  tick (:func:`lantern_jax.sim.step.transition`: the world's half of the tick the evaluation
  runs; the agent is the policy);
* the observation is :func:`lantern_jax.policies.features.observation_vector` of what the
  sensors :data:`SENSORS` deliver (front camera and warning text; ``OBS_SIZE`` slots, each
  documented there), built once per step; the reward is documented in
  :mod:`lantern_jax.apps.envs.reward`;
* ``done`` = the execution is over (route completed, timeout, 30 m off the route, 20 s
  blocked) or a gate has failed.

The whole simulator state lives in ``pipeline_state`` (:class:`EnvState`: the bank index of the
scene, the simulator :class:`~lantern_jax.sim.state.State` and the running score), so brax's
``AutoResetWrapper``, which copies back ``pipeline_state`` and ``obs`` of the first state,
restarts a consistent execution -- but always the same scene per slot.
:class:`~lantern_jax.apps.envs.wrappers.SceneResetWrapper` resets to a newly drawn scene instead.

``info`` carries no simulator state.  ``metrics`` (summed over an episode by brax's
``EpisodeWrapper``): ``progress`` (route completion gained this tick, so the sum is ``P``),
``gate_failure`` (1 on the tick a gate fails), ``completed`` (1 on the tick the route is
completed without a gate failure).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env
from brax.envs.base import State as BraxState
from flax import struct

from lantern_jax.apps.envs.bank import ScenarioBank, build_bank
from lantern_jax.apps.envs.reward import running_score
from lantern_jax.policies.features import ACTION_SIZE, OBS_SIZE, action_to_waypoints
from lantern_jax.policies.features import observation_vector as flat
from lantern_jax.scoring.components import progress
from lantern_jax.sim.observe import observe
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.state import State
from lantern_jax.sim.step import transition
from lantern_jax.types.observation import FRONT_CAMERA, WARNING

Array = jax.Array

METRICS = ("progress", "gate_failure", "completed")
SENSORS = (FRONT_CAMERA, WARNING)  # what the agent's observation vector is built from


@struct.dataclass
class EnvState:
    """The environment's ``pipeline_state``: everything needed to continue an execution."""

    index: Array  # () int32, bank index of the scene
    sim: State  # simulator state
    score: Array  # () float32, running route score R (see lantern_jax.apps.envs.reward)
    failed: Array  # () bool, a gate has failed


class LanternEnv(Env):
    """Driving through the benchmark's scenes (see the module docstring).

    Args:
        bank: the scenes to draw from (default: :func:`~lantern_jax.apps.envs.bank.build_bank` with
            its defaults, 16 pairs per family).
        settings: scoring, protocol and text bank of the simulation (the reward reads the
            scoring settings).
        **bank_kwargs: passed to :func:`~lantern_jax.apps.envs.bank.build_bank` when ``bank`` is
            not given (``pairs_per_family``, ``seed``, ``families``).
    """

    def __init__(
        self,
        bank: ScenarioBank | None = None,
        settings: Settings = DEFAULT_SETTINGS,
        **bank_kwargs,
    ):
        self.bank = build_bank(**bank_kwargs) if bank is None else bank
        self.settings = settings.validate()

    def start(self, index: Array) -> BraxState:
        """The first state of the execution of bank scene ``index`` (() int32)."""
        scenario, sim = self.bank.take(index)
        zero = jnp.zeros((), jnp.float32)
        pipeline = EnvState(index=index, sim=sim, score=zero, failed=jnp.asarray(False))
        return BraxState(
            pipeline_state=pipeline,
            obs=flat(observe(scenario, sim, SENSORS, self.settings.bank)),
            reward=zero,
            done=zero,
            metrics={k: zero for k in METRICS},
            info={},
        )

    def reset(self, rng: Array) -> BraxState:
        """Draw a scene uniformly from the bank and start it (``rng``: raw PRNGKey, (2,) uint32)."""
        index = jax.random.randint(rng, (), 0, self.bank.size, dtype=jnp.int32)
        return self.start(index)

    def step(self, state: BraxState, action: Array) -> BraxState:
        """One tick under ``action`` ((2,) float32 in [-1, 1]: acceleration, curvature)."""
        ps: EnvState = state.pipeline_state
        scenario, _ = self.bank.take(ps.index)
        waypoints = action_to_waypoints(action, ps.sim.ego.speed)
        sim, _ = transition(scenario, ps.sim, waypoints, self.settings)
        score, failed = running_score(
            sim.telemetry, sim.done, scenario.config.d_safe, self.settings.scoring
        )
        # Once over, an episode stays over (brax may step a done state before a reset).
        over = ps.failed | ps.sim.done
        score = jnp.where(over, ps.score, score)
        failed = ps.failed | failed
        done = sim.done | failed
        p_old = progress.hard(ps.sim.telemetry.context, self.settings.scoring)[0]
        p_new = progress.hard(sim.telemetry.context, self.settings.scoring)[0]
        completed = done & ~failed & ~ps.sim.done
        metrics = {
            "progress": jnp.where(over, 0.0, p_new - p_old),
            "gate_failure": (failed & ~ps.failed).astype(jnp.float32),
            "completed": completed.astype(jnp.float32),
        }
        return state.replace(
            pipeline_state=EnvState(index=ps.index, sim=sim, score=score, failed=failed),
            obs=flat(observe(scenario, sim, SENSORS, self.settings.bank)),
            reward=(score - ps.score).astype(jnp.float32),
            done=done.astype(jnp.float32),
            # other keys (e.g. a wrapper's ``reward``) are kept, as brax environments do
            metrics={
                **state.metrics,
                **{k: jnp.asarray(v, jnp.float32) for k, v in metrics.items()},
            },  # fmt: skip
        )

    @property
    def observation_size(self) -> int:
        return OBS_SIZE

    @property
    def action_size(self) -> int:
        return ACTION_SIZE

    @property
    def backend(self) -> str:
        return "jax"
