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

from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components import ROUTE_A_GATES, block, false_brake, progress
from lantern_jax.scoring.cus import s_ant, s_clear, s_rec, s_ttc
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.telemetry import Telemetry
from lantern_jax.times import happened

Array = jax.Array

GATE_PENALTY = 1.0  # return of an episode that fails a gate (a CUS of 0 for its pair)
W_PROGRESS = thresholds.W_PROGRESS_A  # progress weight of Route A's quality Q_A (0.40)


def gate_failed(tel: Telemetry, ended: Array) -> Array:
    """() bool: a gate has failed so far (a timeout counts only once the execution has ended).

    Args:
        tel: telemetry after the latest tick.
        ended: () bool, the execution is over (route completed, timed out, deviated, blocked).
    """
    times = []
    for name, gate in ROUTE_A_GATES.items():
        found = gate.failure_times(getattr(tel, name), tel.context)
        times += list(found[:2]) if gate is block else list(found)  # block: (stall, fault)
    failed = jnp.any(happened(jnp.stack(times)))
    completed = progress.is_completed(tel.context.progress_m, tel.context.route_length_m)
    braked = ~tel.context.is_route_a & ~false_brake.hard(tel.false_brake, tel.context)[0]
    return failed | (ended & ~completed) | braked


def route_score(tel: Telemetry, d_safe: Array) -> Array:
    """() float32: the hard score of a finished route (``Q_A`` on Route A, ``P`` on Route B).

    Args:
        tel: final telemetry of the execution.
        d_safe: () float32, m, the family's clearance normaliser.
    """
    m = finalize(tel)
    nz = lambda x: jnp.where(jnp.isnan(x), 0.0, x)  # noqa: E731 (unavailable -> 0, as the CUS)
    s_a = 0.5 * (nz(s_ttc(m.ttc_min_s)) + nz(s_clear(m.clearance_min_m, d_safe)))
    t_a = 0.5 * (
        nz(s_ant(m.t_ref_s, m.t_event_s, m.t_react_s, m.anticipation_available,
                 m.coincident_onset))
        + nz(s_rec(m.recovery_latency_s, m.recovery_available))
    )  # fmt: skip
    q_a = W_PROGRESS * m.progress + thresholds.W_SAFETY_A * s_a + thresholds.W_TEMPORAL_A * t_a
    return jnp.where(m.is_route_a, q_a, m.progress).astype(jnp.float32)


def running_score(tel: Telemetry, ended: Array, d_safe: Array) -> tuple[Array, Array]:
    """The running route score ``R`` (see the module docstring) and whether a gate failed.

    Args:
        tel: telemetry after the latest tick.
        ended: () bool, the execution is over.
        d_safe: () float32, m.

    Returns:
        ``(R, failed)``: () float32, () bool.
    """
    failed = gate_failed(tel, ended)
    p = progress.hard(tel.context)[0]
    w = jnp.where(tel.context.is_route_a, W_PROGRESS, 1.0)
    value = jnp.where(ended, route_score(tel, d_safe), w * p)
    return jnp.where(failed, -GATE_PENALTY, value).astype(jnp.float32), failed
