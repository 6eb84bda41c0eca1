"""The environment's reward, from the same telemetry the CUS is computed from.

Every tick the environment evaluates a *running route score* ``R`` of the execution from its
telemetry (:class:`~lantern_jax.scoring.telemetry.Telemetry`) and rewards the change::

    r_t = R_t - R_{t-1},        R_0 = 0

    R = -GATE_PENALTY                         a gate has failed (the episode ends there)
      = route score                           the execution has ended, every gate passed
      = W_PROGRESS * P                        otherwise (P = route completion so far)

    route score = 0.40 P + 0.35 S_A + 0.25 T_A     Route A (Q_A of the CUS)
                = P                                Route B (P_B of the CUS)

so the undiscounted return of an episode is exactly the route's hard score when it passes every
gate, and ``-GATE_PENALTY`` when it fails one; progress pays as it is made (``W_PROGRESS = 0.40``
of ``Q_A`` on Route A, all of ``P_B`` on Route B) and the safety and timing terms ``S_A, T_A``
(TTC, clearance, anticipation, recovery) are paid when the execution ends.

Gates (paper appendix "Complete Cooperative Unified Score"), on every route: collision, route
deviation (30 m), lane (1 s outside the lanes), red light, a 20 s standstill, a controller
fault, an unfinished route when the execution ends (timeout), and on Route B the false brake
(an unjustified 1 s stop where Route A had its approach).  The CUS gates a pair on Route A's
gates and Route B's false brake only; the environment applies the safety gates on Route B as
well, because the policy cannot tell the routes apart and a crash is never acceptable driving.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from lantern_jax.core.times import happened
from lantern_jax.scoring.components import ROUTE_A_GATES, block, false_brake, progress
from lantern_jax.scoring.cus import pair_components, quality_a
from lantern_jax.scoring.metrics import ExecutionMetrics, finalize
from lantern_jax.scoring.telemetry import Telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings

Array = jax.Array

GATE_PENALTY = 1.0  # return of an episode that fails a gate (a CUS of 0 for its pair)


def gate_failed(tel: Telemetry, ended: Array, settings: ScoringSettings = DEFAULT_SCORING) -> Array:
    """() bool: a gate has failed so far (a timeout counts only once the execution has ended).

    Args:
        tel: telemetry after the latest tick.
        ended: () bool, the execution is over (route completed, timed out, deviated, blocked).
        settings: the scoring settings the telemetry was folded with.
    """
    times = []
    for name, gate in ROUTE_A_GATES.items():
        found = gate.failure_times(getattr(tel, name), tel.context, settings)
        times += list(found[:2]) if gate is block else list(found)  # block: (stall, fault)
    failed = jnp.any(happened(jnp.stack(times)))
    s = settings
    completed = progress.is_completed(tel.context.progress_m, tel.context.route_length_m, s)
    braked = ~tel.context.is_route_a & ~false_brake.hard(tel.false_brake, tel.context, s)[0]
    return failed | (ended & ~completed) | braked


def route_score(
    tel: Telemetry, d_safe: Array, settings: ScoringSettings = DEFAULT_SCORING
) -> Array:
    """() float32: the hard score of a finished route (``Q_A`` on Route A, ``P`` on Route B).

    Args:
        tel: final telemetry of the execution.
        d_safe: () float32, m, the family's clearance normaliser.
        settings: the scoring settings the telemetry was folded with.
    """
    m: ExecutionMetrics = finalize(tel, settings)
    comps = pair_components(m, m, d_safe, settings)  # Route A's own components
    q_a = quality_a(comps["P_A"], comps["S_A"], comps["T_A"], settings)
    return jnp.where(m.is_route_a, q_a, m.progress).astype(jnp.float32)


def running_score(
    tel: Telemetry, ended: Array, d_safe: Array, settings: ScoringSettings = DEFAULT_SCORING
) -> tuple[Array, Array]:
    """The running route score ``R`` (see the module docstring) and whether a gate failed.

    Args:
        tel: telemetry after the latest tick.
        ended: () bool, the execution is over.
        d_safe: () float32, m.
        settings: the scoring settings the telemetry was folded with.

    Returns:
        ``(R, failed)``: () float32, () bool.
    """
    failed = gate_failed(tel, ended, settings)
    p = progress.hard(tel.context, settings)[0]
    w = jnp.where(tel.context.is_route_a, settings.w_progress_a, 1.0)
    value = jnp.where(ended, route_score(tel, d_safe, settings), w * p)
    return jnp.where(failed, -GATE_PENALTY, value).astype(jnp.float32), failed
