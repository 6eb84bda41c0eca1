"""Cooperative Unified Score of a matched Route A/B pair (paper appendix "Complete Cooperative
Unified Score", Eq. supp_cus_complete)::

    S_TTC  = clip(TTC_min / 3 s)                  no closing trend -> 1, overlap -> 0
    S_clear = clip(d_min / d_safe)                d_safe = 2 m (PE, OR), 3 m otherwise
    S_ant  = clip((t_event - t_react) / (t_event - t_ref))
             no response, or response at/after the event -> 0; coincident onset (RTY):
             1 iff a response was already present at the event, else 0
    S_rec  = clip(1 - RL / 8 s)                   no recovery -> 0
    S_A = (S_TTC + S_clear) / 2      T_A = (S_ant + S_rec) / 2
    Q_A = 0.40 P_A + 0.35 S_A + 0.25 T_A
    CUS = 100 G_coll G_road G_lane G_rule G_block (Route A) G_FB (Route B) (0.85 Q_A + 0.15 P_B)

A component that is unavailable (``NaN``) contributes 0 inside the formula and stays ``NaN`` in
the returned components.  Every hard function is elementwise, so it works on scalars and on
batched arrays alike.

The components themselves live in :mod:`lantern_jax.scoring.components` (one module each); this
module composes them: the hard score from the per-execution outputs of
:func:`~lantern_jax.scoring.metrics.finalize` through each hazard term's ``score_of`` (named by
its ``SCORE``, in the component table's order), the soft score
(:func:`soft_pair_cus`) from each component's ``soft`` -- the same formula with sigmoid gates of
signed margins, soft minima and softplus clips, converging to the hard score as the temperature
goes to 0.
"""

from __future__ import annotations

import types
import warnings
from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.core.constants import FAMILIES, GATE_NAMES, ROUTE_A_GATE_NAMES
from lantern_jax.scoring import thresholds
from lantern_jax.scoring.components import (
    HAZARD_COMPONENTS,
    ROUTE_A_GATES,
    anticipation,
    clearance,
    false_brake,
    progress,
    recovery,
    ttc,
)
from lantern_jax.scoring.metrics import ExecutionMetrics, first_failure_time
from lantern_jax.scoring.telemetry import Telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings

Array = jax.Array


def d_safe_for_family(family: Any) -> Array:
    """Clearance normaliser in m of a built-in family: 2 m for PE and OR, 3 m otherwise.

    Deprecated (kept for one release): a family's ``d_safe`` lives in its entry of the family
    registry (``lantern_jax.scenarios.families.family(code).d_safe``), and every scene carries
    its own (``ExecutionConfig.d_safe``), which the scorer reads.

    Args:
        family: family index (int or int array, ``constants.FAMILIES`` order) or code string.
    """
    warnings.warn(
        "d_safe_for_family is deprecated: read a scene's ExecutionConfig.d_safe, or the "
        "family's registry entry (lantern_jax.scenarios.families.family(code).d_safe)",
        DeprecationWarning,
        stacklevel=2,
    )
    if isinstance(family, str):
        return jnp.asarray(thresholds.D_SAFE_BY_FAMILY[FAMILIES.index(family)], jnp.float32)
    table = jnp.asarray(thresholds.D_SAFE_BY_FAMILY, jnp.float32)
    return table[jnp.asarray(family, jnp.int32)]


# ---------------------------------------------------------------------------------------------
# hard components (elementwise)
# ---------------------------------------------------------------------------------------------
def _f(x: Any) -> Array:
    return jnp.asarray(x, jnp.float32)


def _nz(x: Array) -> Array:
    """NaN (unavailable) -> 0 for use inside the formula."""
    return jnp.where(jnp.isnan(x), 0.0, x)


# the components' elementwise hard scores (see their modules for the definitions)
s_clear = clearance.score
s_ant = anticipation.score


def s_ttc(ttc_min_s: Any, settings: ScoringSettings = DEFAULT_SCORING) -> Array:
    """``S_TTC`` elementwise (:func:`lantern_jax.scoring.components.ttc.score`)."""
    return ttc.score(ttc_min_s, settings)


def s_rec(
    recovery_latency_s: Any, available: Any = True, settings: ScoringSettings = DEFAULT_SCORING
) -> Array:
    """``S_rec`` elementwise (:func:`lantern_jax.scoring.components.recovery.score`)."""
    return recovery.score(recovery_latency_s, settings, available)


def quality_a(p_a: Any, s_a: Any, t_a: Any, settings: ScoringSettings = DEFAULT_SCORING) -> Array:
    """Route A quality ``Q_A = w_P P_A + w_S S_A + w_T T_A`` (the paper's weights 0.40 / 0.35 /
    0.25), elementwise; the one home of the formula (the soft score, the stress objective and
    the RL reward use it too).

    Args:
        p_a: (...) progress in [0, 1].
        s_a: (...) safety ``(S_TTC + S_clear) / 2``.
        t_a: (...) temporal ``(S_ant + S_rec) / 2``.
        settings: the weights.
    """
    return settings.w_progress_a * p_a + settings.w_safety_a * s_a + settings.w_temporal_a * t_a


def cus_of(
    q_a: Any, p_b: Any, gate_product: Any, settings: ScoringSettings = DEFAULT_SCORING
) -> Array:
    """``CUS = 100 * G * (w_A Q_A + w_B P_B)``, elementwise (the paper's 0.85 / 0.15)."""
    return settings.cus_scale * gate_product * (settings.w_route_a * q_a + settings.w_route_b * p_b)


def combine(
    p_a: Any,
    p_b: Any,
    s_ttc_: Any,
    s_clear_: Any,
    s_ant_: Any,
    s_rec_: Any,
    gate_product: Any,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> dict[str, Array]:
    """Weighted quality and CUS from normalised components (``NaN`` components count as 0).

    Returns:
        dict with ``S_A``, ``T_A``, ``Q_A`` and ``CUS`` (0..100).
    """
    s_a = 0.5 * (_nz(_f(s_ttc_)) + _nz(_f(s_clear_)))
    t_a = 0.5 * (_nz(_f(s_ant_)) + _nz(_f(s_rec_)))
    q_a = quality_a(_nz(_f(p_a)), s_a, t_a, settings)
    return {
        "S_A": s_a,
        "T_A": t_a,
        "Q_A": q_a,
        "CUS": cus_of(q_a, _nz(_f(p_b)), _f(gate_product), settings),
    }


def components_from_values(
    P_A: Any,
    P_B: Any,
    ttc_min: Any,
    d_min: Any,
    d_safe: Any,
    t_ref: Any,
    t_event: Any,
    t_react: Any,
    RL: Any,
    *,
    gate_collision: Any = True,
    gate_route_deviation: Any = True,
    gate_lane: Any = True,
    gate_rule: Any = True,
    gate_block: Any = True,
    gate_false_brake: Any = True,
    coincident: Any = None,
    anticipation_available: Any = True,
    recovery_available: Any = True,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> dict[str, Array]:
    """All components, gates and the CUS from plain values (units: s, m; gates: True = passed).

    ``ttc_min``: ``inf`` = no closing trend, ``NaN`` = unavailable.  ``d_min``: ``NaN`` =
    unavailable.  ``t_react`` / ``RL``: ``NaN`` or ``inf`` = no response / no recovery.
    """
    passed = (gate_collision, gate_route_deviation, gate_lane, gate_rule, gate_block,
              gate_false_brake)  # fmt: skip
    gates = {name: jnp.asarray(v, bool) for name, v in zip(GATE_NAMES, passed, strict=True)}
    product = jnp.ones((), jnp.float32)
    for name in GATE_NAMES:
        product = product * gates[name].astype(jnp.float32)
    # the Route A values under the ExecutionMetrics field names the hazard terms read
    route_a = types.SimpleNamespace(
        ttc_min_s=ttc_min, clearance_min_m=d_min, t_ref_s=t_ref, t_event_s=t_event,
        t_react_s=t_react, coincident_onset=coincident,
        anticipation_available=anticipation_available, recovery_latency_s=RL,
        recovery_available=recovery_available,
    )  # fmt: skip
    comps = {
        "P_A": _f(P_A),
        "P_B": _f(P_B),
        **{m.SCORE: m.score_of(route_a, d_safe, settings) for m in HAZARD_COMPONENTS.values()},
    }
    out = combine(
        comps["P_A"], comps["P_B"], comps["S_ttc"], comps["S_clear"], comps["S_ant"],
        comps["S_rec"], product, settings,
    )  # fmt: skip
    return {**comps, **gates, "gate_product": product, **out}


def cus_from_values(*args: Any, **kwargs: Any) -> Array:
    """CUS (0..100) from plain values; same arguments as :func:`components_from_values`."""
    return components_from_values(*args, **kwargs)["CUS"]


def pair_components(
    metrics_a: ExecutionMetrics,
    metrics_b: ExecutionMetrics,
    d_safe: Any,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> dict[str, Array]:
    """Hard components, gates and CUS of matched pairs (elementwise over any batch shape).

    Args:
        metrics_a: Route A execution outputs (from :func:`~lantern_jax.scoring.metrics.finalize`).
        metrics_b: Route B execution outputs; only ``progress`` and ``gate_false_brake`` are used.
        d_safe: clearance normaliser in m (a scene's ``ExecutionConfig.d_safe``).
        settings: scoring thresholds and weights.

    Returns:
        dict: ``P_A, P_B, S_ttc, S_clear, S_ant, S_rec`` (float, ``NaN`` = unavailable), the six
        ``gate_*`` pass flags (bool), ``gate_product``, ``S_A, T_A, Q_A`` and ``CUS`` (0..100).
    """
    a, b = metrics_a, metrics_b
    return components_from_values(
        a.progress, b.progress, a.ttc_min_s, a.clearance_min_m, d_safe,
        a.t_ref_s, a.t_event_s, a.t_react_s, a.recovery_latency_s,
        **{name: getattr(a, name) for name in ROUTE_A_GATE_NAMES},
        gate_false_brake=b.gate_false_brake,
        coincident=a.coincident_onset,
        anticipation_available=a.anticipation_available,
        recovery_available=a.recovery_available,
        settings=settings,
    )  # fmt: skip


#: :func:`pair_components` as one compiled program, for callers on the host (the route table,
#: the stress verifier), so that their scores agree to the bit.  Run op by op it compiled some
#: 25 small programs (about 1 s on a 2-core CPU) in every fresh process; whole, it is one
#: program, kept in JAX's persistent cache.  Its weighted sums may be contracted (fused
#: multiply-add), so its ``CUS`` can differ from the op-by-op one in the last float32 place.
compiled_pair_components = jax.jit(pair_components)


# ---------------------------------------------------------------------------------------------
# soft (differentiable) score
# ---------------------------------------------------------------------------------------------
def _or_zero(value_valid: tuple[Array, Array]) -> Array:
    """A soft ``(value, valid)`` pair as one value; an unavailable component contributes 0."""
    value, valid = value_valid
    return jnp.where(valid, value, 0.0)


def soft_execution_terms(
    tel: Telemetry,
    d_safe: Any,
    temperature: Any = None,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> dict[str, Array]:
    """Smooth components and gates of one execution.

    The log-sum-exp and first-crossing accumulators were built with the accumulator temperature
    ``tel.context.temperature`` and are decoded with it; ``temperature`` (default: the same)
    sets the smooth clips and the gate sigmoids.  Availability masks are the hard ones (an
    unavailable component contributes 0).

    Args:
        tel: final telemetry of one execution.
        d_safe: () float32, m, clearance normaliser.
        temperature: () float32 for gates and clips.
        settings: scoring thresholds (the accumulators' own, of :func:`update_telemetry`).

    Returns:
        dict of () float32: ``P, S_ttc, S_clear, S_ant, S_rec`` and the six soft gates
        ``gate_collision, gate_route_deviation, gate_lane, gate_rule, gate_block,
        gate_false_brake`` in [0, 1].
    """
    ctx = tel.context
    t = ctx.temperature if temperature is None else jnp.asarray(temperature, jnp.float32)
    s = settings
    t_fail = first_failure_time(tel, s)
    d_safe = _f(d_safe)
    terms = {
        "P": progress.soft(ctx, t, s)[0],
        "S_ttc": _or_zero(ttc.soft(tel.ttc, ctx, t_fail, t, s, d_safe)),
        "S_clear": _or_zero(clearance.soft(tel.clearance, ctx, t_fail, t, s, d_safe)),
        "S_ant": _or_zero(anticipation.soft(tel.anticipation, ctx, t_fail, t, s, d_safe)),
        "S_rec": _or_zero(recovery.soft(tel.recovery, ctx, t_fail, t, s, d_safe)),
    }
    for name, gate in ROUTE_A_GATES.items():
        terms["gate_" + name] = gate.soft(getattr(tel, name), ctx, t, s)[0]
    terms["gate_false_brake"] = false_brake.soft(tel.false_brake, ctx, t, s)[0]
    return terms


def soft_pair_components(
    tel_a: Telemetry,
    tel_b: Telemetry,
    d_safe: Any,
    temperature: Any = None,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> dict[str, Array]:
    """Soft counterpart of :func:`pair_components` (same keys; all values in [0, 1] / 0..100)."""
    a = soft_execution_terms(tel_a, d_safe, temperature, settings)
    b = soft_execution_terms(tel_b, d_safe, temperature, settings)
    gates = {name: a[name] for name in ROUTE_A_GATE_NAMES}
    gates["gate_false_brake"] = b["gate_false_brake"]
    product = jnp.ones((), jnp.float32)
    for name in GATE_NAMES:
        product = product * gates[name]
    comps = {
        "P_A": a["P"],
        "P_B": b["P"],
        "S_ttc": a["S_ttc"],
        "S_clear": a["S_clear"],
        "S_ant": a["S_ant"],
        "S_rec": a["S_rec"],
    }
    out = combine(
        comps["P_A"], comps["P_B"], comps["S_ttc"], comps["S_clear"], comps["S_ant"],
        comps["S_rec"], product, settings,
    )  # fmt: skip
    return {**comps, **gates, "gate_product": product, **out}


def soft_pair_cus(
    tel_a: Telemetry,
    tel_b: Telemetry,
    d_safe: Any,
    temperature: Any = None,
    settings: ScoringSettings = DEFAULT_SCORING,
) -> Array:
    """Differentiable CUS (0..100) of one pair; converges to the hard CUS as temperature -> 0.

    Args:
        tel_a, tel_b: final Route A / Route B telemetry, folded with the same temperature.
        d_safe: () float32, m.
        temperature: () float32 for gates and clips (default: the accumulators' temperature).
    """
    return soft_pair_components(tel_a, tel_b, d_safe, temperature, settings)["CUS"]
