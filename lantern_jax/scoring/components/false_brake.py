"""Route B false-brake gate ``G_FB`` (paper appendix "Complete Cooperative Unified Score",
paragraph "Hard gates", Route B).

Fails when the ego stands still (``speed <= 0.1 m/s``) without ``justified_stop`` (a light, stop
sign, lead vehicle, obstacle, conflict or route end; a warning is no justification) on 20
consecutive ticks (1 s) inside ``[t_ref, t_event]`` -- on Route B the stretch matched by arc
length to Route A's warning-to-event approach.  Soft:
``sigmoid((19.5 ticks - longest such stop) * DT / T)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.constants import DT
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components.accumulate import first_time, run
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import soft_gate
from lantern_jax.times import NEVER, happened

Array = jax.Array


@struct.dataclass
class FalseBrakeState:
    """Unjustified-stop record of one execution (scalars)."""

    run: Array  # () int32, consecutive unjustified stopped ticks in [t_ref, t_event]
    max_run: Array  # () int32, longest such run
    t_fail: Array  # () float32, s, tick at which such a stop reached 1 s (NEVER)


def init() -> FalseBrakeState:
    """No stop yet."""
    i0 = jnp.asarray(0, jnp.int32)
    return FalseBrakeState(run=i0, max_run=i0, t_fail=jnp.asarray(NEVER, jnp.float32))


def update(
    state: FalseBrakeState, sample: TickSample, tick: Tick, temperature: Array
) -> FalseBrakeState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``justified_stop``).
        tick: shared per-tick context.
        temperature: unused (the soft gate is decoded from the final record).

    Returns:
        The record after the tick.
    """
    in_window = tick.post_ref & (tick.t <= tick.t_event)
    stopped = tick.speed <= thresholds.FALSE_BRAKE_SPEED_MPS
    n_run = run(state.run, in_window & stopped & ~jnp.asarray(sample.justified_stop, bool))
    failed = n_run >= thresholds.FALSE_BRAKE
    return FalseBrakeState(
        run=n_run,
        max_run=jnp.maximum(state.max_run, n_run),
        t_fail=first_time(happened(state.t_fail), failed, tick.t, state.t_fail),
    )


def max_stop_s(state: FalseBrakeState) -> Array:
    """() float32, s: longest unjustified stop in ``[t_ref, t_event]``."""
    return state.max_run.astype(jnp.float32) * DT


def hard(state: FalseBrakeState, ctx: Context) -> tuple[Array, Array]:
    """Hard gate.

    Args:
        state: final record.
        ctx: final shared context.

    Returns:
        ``(passed, valid)``: () bool, no unjustified 1 s stop in ``[t_ref, t_event]``;
        () bool (always True).
    """
    return state.max_run < thresholds.FALSE_BRAKE, jnp.asarray(True)


def soft(state: FalseBrakeState, ctx: Context, temperature: Array) -> tuple[Array, Array]:
    """Smooth gate.

    Args:
        state: final record.
        ctx: final shared context.
        temperature: () float32, s, of the sigmoid of the margin.

    Returns:
        ``(passed, valid)``: () float32 in [0, 1]; () bool (always True).
    """
    margin = (
        thresholds.FALSE_BRAKE - thresholds.COUNT_HALF - state.max_run.astype(jnp.float32)
    ) * DT
    return soft_gate(margin, temperature), jnp.asarray(True)
