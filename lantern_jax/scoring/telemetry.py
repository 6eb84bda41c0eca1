"""Running telemetry of ONE execution, folded tick by tick inside ``lax.scan``.

The measurement side of the paper appendix "Complete Cooperative Unified Score": the shared
context and one accumulator state per score component (see :mod:`lantern_jax.scoring.components`
for the definitions).  No trajectory is stored: every quantity is a running minimum, a
first-crossing time, a counter or a short ring buffer of the last few ticks.
:func:`lantern_jax.scoring.metrics.finalize` turns the final :class:`Telemetry` into
per-execution outputs and :mod:`lantern_jax.scoring.cus` into the (soft) score.

Durations on the tick grid are counted in ticks (``duration = ticks * DT``): the reaction window
is 10 ticks (0.5 s), the recovery window 20 ticks (1 s), the lane debounce 20 ticks (1 s in
total), the Route B false brake 20 consecutive ticks (1 s), blocking 400 consecutive ticks (20 s).

The soft accumulators (log-sum-exp soft minima, soft first crossings) are built with the
temperature of the :class:`~lantern_jax.scoring.thresholds.ScoringSettings` given to
:func:`update_telemetry`, recorded in ``Telemetry.context.temperature``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.scoring import user_metrics
from lantern_jax.scoring.components import (
    COMPONENTS,
    anticipation,
    block,
    clearance,
    collision,
    context,
    efficiency,
    false_brake,
    lane,
    recovery,
    route_deviation,
    rule,
    ttc,
)
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings

Array = jax.Array


@struct.dataclass
class Telemetry:
    """Accumulators of one execution: the shared context and one state per component."""

    context: context.Context  # tick counter, protocol times, progress, rings, v_pre
    ttc: ttc.TTCState  # S_TTC over [t_ref, t_clear]
    clearance: clearance.ClearanceState  # S_clear over [t_event, t_clear]
    anticipation: anticipation.AnticipationState  # S_ant, incl. the coincident-onset check
    recovery: recovery.RecoveryState  # S_rec after max(t_warn_off, t_clear)
    collision: collision.CollisionState  # G_coll
    route_deviation: route_deviation.RouteDeviationState  # G_road
    lane: lane.LaneState  # G_lane
    rule: rule.RuleState  # G_rule
    block: block.BlockState  # G_block: standstill, controller fault (timeout from the context)
    false_brake: false_brake.FalseBrakeState  # G_FB (Route B)
    efficiency: efficiency.EfficiencyState  # completion time, unjustified slow time (not CUS)
    metrics: tuple = ()  # the accumulators of ``settings.metrics`` (user metrics, not CUS)


def init_telemetry(settings: ScoringSettings = DEFAULT_SCORING) -> Telemetry:
    """Accumulators before the first tick (ring lengths from ``settings``)."""
    return Telemetry(context=context.init(settings),
                     **{name: unit.init(settings) for name, unit in _UNITS.items()},
                     metrics=user_metrics.init_states(settings.metrics, settings))  # fmt: skip


#: Every component's module by Telemetry field, in the table's order (``context`` apart: it
#: runs first).
_UNITS = {c.field: c.module for c in COMPONENTS}


def _step(tel: Telemetry, s: TickSample, settings: ScoringSettings) -> Telemetry:
    """Every component's ``update`` with the shared context of this tick."""
    ctx, tick = context.update(tel.context, s, settings)
    return Telemetry(
        context=ctx,
        **{
            name: unit.update(getattr(tel, name), s, tick, settings)
            for name, unit in _UNITS.items()
        },
        metrics=user_metrics.update_states(settings.metrics, tel.metrics, s, tick, settings),
    )


def update_telemetry(
    tel: Telemetry,
    sample: TickSample,
    settings: ScoringSettings = DEFAULT_SCORING,
    active: Array = True,
) -> Telemetry:
    """Fold one 20 Hz tick into the accumulators (jittable; one execution, ``vmap`` outside).

    Args:
        tel: accumulators before the tick.
        sample: the tick's measurement (see :class:`~lantern_jax.scoring.sample.TickSample`).
        settings: thresholds and the temperature of the soft accumulators (in the unit of each
            relaxed quantity: s, m, m/s, m/s^2, samples; > 0).
        active: () bool, ``False`` leaves ``tel`` unchanged (ticks after an execution has ended
            -- route completed, timed out -- in a fixed-length batched scan).

    Returns:
        The updated :class:`Telemetry`.
    """
    new = _step(tel, sample, settings)
    on = jnp.asarray(active, bool)
    return jax.tree.map(lambda n, o: jnp.where(on, n, o), new, tel)


def fold_telemetry(
    samples: TickSample,
    settings: ScoringSettings = DEFAULT_SCORING,
    active: Array | None = None,
) -> Telemetry:
    """Fold a whole stacked sequence of ticks (leading axis = time) with ``lax.scan``.

    Convenience for tests and offline scoring; the rollout calls :func:`update_telemetry` inside
    its own scan instead.

    Args:
        samples: :class:`~lantern_jax.scoring.sample.TickSample` with a leading (N,) time axis.
        settings: thresholds and the soft accumulators' temperature.
        active: (N,) bool, ticks to fold (default: all).

    Returns:
        The :class:`Telemetry` after the last tick.
    """
    n = jax.tree.leaves(samples)[0].shape[0]
    act = jnp.ones(n, bool) if active is None else jnp.asarray(active, bool)

    def body(tel, xs):
        s, a = xs
        return update_telemetry(tel, s, settings, a), None

    tel, _ = jax.lax.scan(body, init_telemetry(settings), (samples, act))
    return tel
