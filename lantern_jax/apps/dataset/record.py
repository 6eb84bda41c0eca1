"""Batched expert rollouts recorded at 4 Hz (every fifth 20 Hz tick).

One frame is kept every :data:`FRAME_TICKS` ticks, so frames are exactly 0.25 s apart — the
spacing of the policy waypoints — and frame ``f + k`` is the expert's actual position ``k``
waypoints after frame ``f``.  A frame holds exactly what a learned policy would observe at its
tick: the observation under :data:`FRONT_SENSORS` (front camera: visible objects, range image
and each ray's semantic class; ego state, navigation; the warning as its token ids and value
channel), and what the six-camera rig changes in it (:class:`RigFrame`: the rig's own view, and
the actors and visibility under front camera plus rig), together with the ego's world pose and
whether the execution was still running.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.dynamics.actors import EARLIER_ACTORS
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios.warnings import TextBank
from lantern_jax.sim.engine import Program, check_texts
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import start_state
from lantern_jax.sim.settings import Settings, default_settings
from lantern_jax.sim.state import State
from lantern_jax.sim.step import step
from lantern_jax.types.observation import (
    FRONT_CAMERA,
    SURROUND_RIG,
    WARNING,
    Observation,
    SurroundView,
)
from lantern_jax.types.world import Scenario

Array = jax.Array

FRAME_TICKS = 5  # 20 Hz ticks per retained frame (4 Hz)
FRONT_SENSORS = (FRONT_CAMERA, WARNING)  # the recorded observation's sensors
RIG_SENSORS = (FRONT_CAMERA, SURROUND_RIG, WARNING)  # ... and those of the rig's variant
#: the observation fields that the six-camera rig changes (besides ``surround``)
RIG_FIELDS = ("visible", "actor_xy", "actor_vel", "actor_dir", "actor_extent", "actor_kind")


@struct.dataclass
class RigFrame:
    """What the observation of a policy with the six-camera rig holds beyond the front one."""

    surround: SurroundView  # the rig's visibility, SURROUND_RAYS ranges and classes
    visible: Array  # (A,) bool, seen by the front camera or the rig
    actor_xy: Array  # (A, 2) float32, m (zero where not seen), as in Observation
    actor_vel: Array  # (A, 2) float32, m/s
    actor_dir: Array  # (A, 2) float32
    actor_extent: Array  # (A, 2) float32, m
    actor_kind: Array  # (A,) int32


@struct.dataclass
class FrameRecord:
    """One retained frame of one execution (a leading frame axis when recorded)."""

    t: Array  # () float32, s
    live: Array  # () bool, the execution had not ended at this frame
    ego_xy: Array  # (2,) float32, m, world frame
    ego_yaw: Array  # () float32, rad
    obs: Observation  # the observation under FRONT_SENSORS (front camera: visible objects,
    #                   range image and each ray's class, ``obs.range_class``; warning text)
    rig: RigFrame  # what the six-camera rig changes in it


def _frame(scenario: Scenario, state: State, bank: TextBank) -> FrameRecord:
    rig_obs = observe(scenario, state, RIG_SENSORS, bank)
    return FrameRecord(
        t=state.t,
        live=~state.done,
        ego_xy=state.ego.xy,
        ego_yaw=state.ego.yaw,
        obs=observe(scenario, state, FRONT_SENSORS, bank),
        rig=RigFrame(surround=rig_obs.surround, **{k: getattr(rig_obs, k) for k in RIG_FIELDS}),
    )


#: How the IDM actors treat the ego while the dataset is recorded and while the closed-loop
#: recipes drive and relabel (:func:`data_settings`): the rule the dataset and every shipped
#: model were made under (:data:`~lantern_jax.dynamics.actors.EARLIER_ACTORS`, the default until
#: 2026-12-08), kept so that the documented commands rebuild the same frames and retrain the
#: same weights.  Evaluations run under the default rule, in which a flow car also brakes for an
#: ego on its path; only Right-Turn Yield's flow and the background cars meet the ego at an
#: angle.
DATA_ACTORS = EARLIER_ACTORS


def data_settings() -> Settings:
    """:func:`~lantern_jax.sim.settings.default_settings` with :data:`DATA_ACTORS`: the
    settings the dataset and the training recipes drive under unless given others."""
    return default_settings().replace(actors=DATA_ACTORS)


def record(
    scenario: Scenario,
    policy: Policy,
    policy_params: Any,
    num_frames: int,
    settings: Settings | None = None,
) -> tuple[FrameRecord, State]:
    """Roll one execution, keeping one frame every :data:`FRAME_TICKS` ticks (the first at
    ``t = 0``), until it ends or ``num_frames`` frames are kept (``settings`` default:
    :func:`data_settings`).

    A ``while_loop`` writes into a preallocated buffer, so a batch (``vmap`` outside) stops as
    soon as every execution has ended; frames after the end keep ``live = False``.

    Returns:
        (frames with a leading axis ``num_frames``, the final state).
    """
    settings = data_settings() if settings is None else settings
    state0 = start_state(scenario, policy, policy_params, settings)
    shapes = jax.eval_shape(lambda sc, st: _frame(sc, st, settings.bank), scenario, state0)
    empty = jax.tree.map(lambda x: jnp.zeros((num_frames, *x.shape), x.dtype), shapes)

    def tick(s, _):
        return step(policy, policy_params, scenario, s, settings)[0], None

    def body(carry):
        i, state, frames = carry
        kept = _frame(scenario, state, settings.bank)
        frames = jax.tree.map(lambda buf, x: buf.at[i].set(x), frames, kept)
        state, _ = jax.lax.scan(tick, state, None, length=FRAME_TICKS)
        return i + 1, state, frames

    def cond(carry):
        i, state, _ = carry
        return (i < num_frames) & ~state.done

    _, final, frames = jax.lax.while_loop(cond, body, (jnp.asarray(0), state0, empty))
    return frames, final


@functools.partial(jax.jit, static_argnames=("program", "num_frames"))
def _record_batch(scenarios, policy_params, settings, *, program: Program, num_frames: int):
    """:func:`record` of a batch (``vmap``); compiled once per program and frame count."""

    def one(sc):
        return record(sc, program.driver, policy_params, num_frames, settings)

    return jax.vmap(one)(scenarios)


def batched_recorder(policy: Policy, num_frames: int, settings: Settings | None = None):
    """``(scenarios, policy_params) -> (frames, final states)`` of a batch, one compiled
    program per (policy program, frame count) (a jitted function with those as static
    arguments).  ``settings`` default: :func:`data_settings` (the bank then holds every
    registered family's texts); a batch reading a text beyond the bank is refused
    (ValueError)."""
    program = Program(policy)
    settings = data_settings() if settings is None else settings

    def run(scenarios, params):
        check_texts(settings, scenarios)
        return _record_batch(scenarios, params, settings, program=program, num_frames=num_frames)

    return run
