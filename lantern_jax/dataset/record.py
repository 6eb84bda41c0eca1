"""Batched expert rollouts recorded at 4 Hz (every fifth 20 Hz tick).

One frame is kept every :data:`FRAME_TICKS` ticks, so frames are exactly 0.25 s apart — the
spacing of the policy waypoints — and frame ``f + k`` is the expert's actual position ``k``
waypoints after frame ``f``.  A frame holds the policy :class:`~lantern_jax.observation.Observation`
of its tick (front camera: visible objects, range image and each ray's semantic class; ego
state, navigation, the warning as text ids and numbers), the six-camera rig's view
(:func:`lantern_jax.sim.sense.camera_view` at 360 deg, the same fields as
``Observation.surround``), the ego's world pose, and whether the execution was still running.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.constants import SURROUND_FOV
from lantern_jax.observation import Observation
from lantern_jax.sim.observe import observe
from lantern_jax.sim.sense import SURROUND_RAYS, CameraView, camera_view
from lantern_jax.sim.state import State, init_state
from lantern_jax.sim.step import step
from lantern_jax.world import Scenario

Array = jax.Array

FRAME_TICKS = 5  # 20 Hz ticks per retained frame (4 Hz)


@struct.dataclass
class FrameRecord:
    """One retained frame of one execution (a leading frame axis when recorded)."""

    t: Array  # () float32, s
    live: Array  # () bool, the execution had not ended at this frame
    ego_xy: Array  # (2,) float32, m, world frame
    ego_yaw: Array  # () float32, rad
    obs: Observation  # the policy observation of this tick (front camera: visible objects,
    #                   range image and each ray's class, ``obs.range_class``)
    surround: CameraView  # the six-camera rig: visibility, SURROUND_RAYS ranges and classes


def _frame(scenario: Scenario, state: State) -> FrameRecord:
    around = camera_view(scenario, state.ego, state.actors, SURROUND_FOV, SURROUND_RAYS)
    return FrameRecord(
        t=state.t,
        live=~state.done,
        ego_xy=state.ego.xy,
        ego_yaw=state.ego.yaw,
        obs=observe(scenario, state),
        surround=around,
    )


def record(
    scenario: Scenario, act: Callable[[Any, Any], Array], policy_params: Any, num_frames: int
) -> tuple[FrameRecord, State]:
    """Roll one execution, keeping one frame every :data:`FRAME_TICKS` ticks (the first at
    ``t = 0``), until it ends or ``num_frames`` frames are kept.

    A ``while_loop`` writes into a preallocated buffer, so a batch (``vmap`` outside) stops as
    soon as every execution has ended; frames after the end keep ``live = False``.

    Returns:
        (frames with a leading axis ``num_frames``, the final state).
    """
    temperature = jnp.asarray(0.05, jnp.float32)
    state0 = init_state(scenario)
    shapes = jax.eval_shape(_frame, scenario, state0)
    empty = jax.tree.map(lambda x: jnp.zeros((num_frames, *x.shape), x.dtype), shapes)

    def tick(s, _):
        return step(act, policy_params, scenario, s, temperature)[0], None

    def body(carry):
        i, state, frames = carry
        kept = _frame(scenario, state)
        frames = jax.tree.map(lambda buf, x: buf.at[i].set(x), frames, kept)
        state, _ = jax.lax.scan(tick, state, None, length=FRAME_TICKS)
        return i + 1, state, frames

    def cond(carry):
        i, state, _ = carry
        return (i < num_frames) & ~state.done

    _, final, frames = jax.lax.while_loop(cond, body, (jnp.asarray(0), state0, empty))
    return frames, final


_RECORDERS: dict[tuple, Callable] = {}


def batched_recorder(act: Callable[[Any, Any], Array], num_frames: int) -> Callable:
    """``jit(vmap(record))``: ``(scenarios, policy_params) -> (frames, final states)``; one
    compiled function per (policy act, frame count), reused by later calls."""
    key = (act, num_frames)
    if key not in _RECORDERS:
        _RECORDERS[key] = jax.jit(
            jax.vmap(lambda sc, params: record(sc, act, params, num_frames), in_axes=(0, None))
        )
    return _RECORDERS[key]
