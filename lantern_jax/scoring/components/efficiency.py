"""Route efficiency: a diagnostic reported beside the Cooperative Unified Score, never inside it.

The paper's Route B gate catches only full stops (a false brake is a stop of at least 1 s, see
:mod:`lantern_jax.scoring.components.false_brake`), so a policy that slows unconditionally to a
crawl wherever it might be warned passes it and keeps its Route B progress.  This record shows
what such slowing costs, on any route (the tables report Route B):

* **time to route completion**: the time stamp of the first tick at which the ego reached the
  route's end zone (``route_length - 2 m``, as :mod:`lantern_jax.scoring.components.progress`
  counts completion); never, when the route was not completed;
* **unjustified slow time**: ticks at which the ego drove below ``SLOW_SPEED_FRACTION`` of the
  route's reference speed while nothing justified it -- no light holding it, no actor in its
  path within the false-brake gate's reach, not near the route end (the same excuses as the
  false brake, :func:`lantern_jax.scoring.measure.justified_stop`; a warning is none).  The
  per-tick decision is :attr:`~lantern_jax.scoring.sample.TickSample.slow_unjustified`.

Not a score component: it has no soft form and no weight, and no gate reads it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import DT
from lantern_jax.core.times import NEVER, happened, time_or_nan
from lantern_jax.scoring.components.accumulate import count, first_time
from lantern_jax.scoring.components.context import Context, Tick
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import ScoringSettings

Array = jax.Array


@struct.dataclass
class EfficiencyState:
    """Efficiency record of one execution (scalars)."""

    slow_ticks: Array  # () int32, ticks below the slow speed with nothing justifying it
    t_complete: Array  # () float32, s, first tick in the route's end zone (NEVER)


def init(settings: ScoringSettings) -> EfficiencyState:
    """Nothing recorded yet. (no shape depends on ``settings``)"""
    del settings
    return EfficiencyState(
        slow_ticks=jnp.asarray(0, jnp.int32), t_complete=jnp.asarray(NEVER, jnp.float32)
    )


def update(
    state: EfficiencyState, sample: TickSample, tick: Tick, settings: ScoringSettings
) -> EfficiencyState:
    """Fold one tick.

    Args:
        state: record before the tick.
        sample: the tick's measurement (``slow_unjustified``).
        tick: shared per-tick context (time, progress, route length).
        settings: thresholds; temperature: unused (no soft form).

    Returns:
        The record after the tick.
    """
    done = tick.progress >= settings.completion_length(tick.route_length)
    return EfficiencyState(
        slow_ticks=count(state.slow_ticks, jnp.asarray(sample.slow_unjustified, bool)),
        t_complete=first_time(happened(state.t_complete), done, tick.t, state.t_complete),
    )


def slow_s(state: EfficiencyState) -> Array:
    """() float32, s: time spent below the slow speed with nothing justifying it."""
    return state.slow_ticks.astype(jnp.float32) * DT


#: Its columns of the route-level table: column -> (route, ExecutionMetrics field), the
#: route ``"A"`` (the warning-side route) or ``"B"`` (the matched normal route).
COLUMNS: dict[str, tuple[str, str]] = {
    "B_time_s": ("B", "t_complete_s"),
    "B_slow_s": ("B", "slow_unjustified_s"),
}

#: The :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` fields :func:`outputs` gives.
OUTPUTS = ("t_complete_s", "slow_unjustified_s")


def outputs(state: EfficiencyState, ctx: Context, t_fail: Array, settings: ScoringSettings
            ) -> dict[str, Array]:  # fmt: skip
    """Its per-execution outputs: the :data:`OUTPUTS` fields of
    :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (``t_fail``: () float32, s, the
    first Route A gate failure)."""
    return {"t_complete_s": time_or_nan(state.t_complete), "slow_unjustified_s": slow_s(state)}
