"""What counts as a plausible failure, checked the same way for every search method.

A verified candidate is a **failure** when the policy under test fails a Route A gate or its
pair CUS is below :data:`FAIL_BELOW_CUS` (the hard evaluation), and it counts only when it is
**plausible**:

1. **the privileged expert passes with margin** on the same scene: every Route A gate passed,
   its hard clearance to the hazard (the benchmark's ``clearance_min_m``, where available)
   at least :data:`EXPERT_MARGIN_M`, and no near miss — its box never within
   :data:`EXPERT_MARGIN_M` of a watched actor (the hazard and every actor with a track) at any
   tick.  A hazard that only a driver who cuts it close could avoid is not the policy's
   failure;
2. **no actor with a track stops in the ego's path** for longer than
   :data:`STOP_IN_PATH_LIMIT_S`: slower than :data:`STOP_SPEED_MPS` with its box within the
   ego half width + 0.5 m of the route centre line (the benchmark's in-path rule,
   ``ScoringSettings.justify_lateral_margin_m``) and ahead of the ego's rear.  A walker who
   freezes in the lane until the policy gives up is not a failure of the policy;
3. **no actor with a track leaves the road**: a vehicle's centre stays within some lane (half
   width + ``ScoringSettings.lane_margin_m``, the ego's own lane rule), a walker stays within
   :data:`WALKER_CORRIDOR_M` of its crossing path;
4. **no actor exceeds its kinematic limits** (:data:`lantern_jax.dynamics.adversary.
   KINEMATIC_LIMITS`): by construction of the tracks for every action, and checked on the
   realised speed (:data:`SPEED_TOLERANCE_MPS`).

Rules 2-4 are measured on the policy's own rollout (the failure reported), after each actor's
track has started, by :mod:`lantern_jax.apps.stress.watch`.

The smooth objective the gradient method descends (:mod:`lantern_jax.apps.stress.objective`,
:func:`expert_term`, :func:`plausibility_term`) targets
exactly this: the policy's soft collision margin to the watched actors (the minimum over ticks
of ``max(box distance, 0.1 m/s - ego speed)``, the collision gate's margin — it keeps falling
where the plain clearance saturates at 0 m against a stopped ego), plus a hinge on the
expert's soft distance below :data:`EXPERT_MARGIN_M` + :data:`EXPERT_BUFFER_M`, plus the soft
time in rules 2 and 3 beyond a share of their limits.  What is smoothed: minima over ticks by
log-sum-exp (temperature of the surrogate), the in-path and speed tests by sigmoids
(:data:`SOFT_DIST_M`, :data:`SOFT_SPEED_MPS`), the hinges by softplus.  Black-box methods
minimise the same expression of the hard quantities (:func:`hard_objective`).
"""

from __future__ import annotations

import jax
import numpy as np

from lantern_jax.core.constants import EGO_HALF_WIDTH

Array = jax.Array

FAIL_BELOW_CUS = 50.0  # CUS points: a pair below this counts as a failure (besides any gate)
EXPERT_MARGIN_M = 0.5  # m, the expert's least clearance and distance to any watched actor
EXPERT_BUFFER_M = 0.5  # m, the objective keeps the expert this much beyond the margin
STOP_SPEED_MPS = 0.5  # m/s, an actor slower than this is stopped
STOP_IN_PATH_LIMIT_S = 2.0  # s, longest plausible stop in the ego's path (a hesitation)
IN_PATH_MARGIN_M = 0.5  # m, in the path: box within the ego half width + this of the route
IN_PATH_M = EGO_HALF_WIDTH + IN_PATH_MARGIN_M
WALKER_CORRIDOR_M = 2.0  # m, a walker keeps within this of its crossing path (a crossing's width)
OFF_ROAD_LIMIT_S = 0.0  # s, time off the road an actor with a track may spend
SPEED_TOLERANCE_MPS = 0.05  # m/s, realised speed over the kind's limit still within it
CAP_M = 30.0  # m, soft margins are capped here (farther is just "safe"; below, a gradient)
SOFT_DIST_M = 0.25  # m, temperature of the smooth in-path and road tests
SOFT_SPEED_MPS = 0.25  # m/s, temperature of the smooth stop test
SOFT_HINGE = 0.1  # temperature of the softplus hinges (m, s)
EXPERT_WEIGHT = 2.0  # objective units per m of expert margin missing
PLAUSIBLE_WEIGHT = 2.0  # objective units per s of stop or off-road time beyond the allowance
STOP_ALLOWED_S = 0.5 * STOP_IN_PATH_LIMIT_S  # s of stop in the path the objective lets pass


def _hinge(x: Array) -> Array:
    """Smooth ``max(x, 0)`` (softplus with temperature :data:`SOFT_HINGE`)."""
    return SOFT_HINGE * jax.nn.softplus(x / SOFT_HINGE)


def expert_term(expert_dist: Array, weight: float = EXPERT_WEIGHT) -> Array:
    """() the expert part: ``weight`` x a smooth hinge on the expert's soft distance to the
    watched actors (m) below :data:`EXPERT_MARGIN_M` + :data:`EXPERT_BUFFER_M`."""
    return weight * _hinge(EXPERT_MARGIN_M + EXPERT_BUFFER_M - expert_dist)


def plausibility_term(stop_s: Array, off_road_s: Array) -> Array:
    """() the smooth penalty on the tracked actors' longest soft stop in the ego's path beyond
    :data:`STOP_ALLOWED_S` and their longest soft time off the road (s),
    :data:`PLAUSIBLE_WEIGHT` per second."""
    beyond = _hinge(stop_s - STOP_ALLOWED_S) + _hinge(off_road_s - OFF_ROAD_LIMIT_S)
    return PLAUSIBLE_WEIGHT * beyond


def hard_objective(
    policy_margin: np.ndarray,
    expert_dist: np.ndarray,
    stop_s: np.ndarray,
    off_road_s: np.ndarray,
) -> np.ndarray:
    """(N,) the surrogate's expression of the hard quantities (what black-box methods minimise):
    margins capped at :data:`CAP_M`, hinges exact."""
    relu = lambda x: np.maximum(x, 0.0)  # noqa: E731
    missing = EXPERT_MARGIN_M + EXPERT_BUFFER_M - np.minimum(expert_dist, CAP_M)
    beyond = relu(stop_s - STOP_ALLOWED_S) + relu(off_road_s - OFF_ROAD_LIMIT_S)
    margin = np.minimum(policy_margin, CAP_M)
    return margin + EXPERT_WEIGHT * relu(missing) + PLAUSIBLE_WEIGHT * beyond


def expert_passes_with_margin(
    gates_passed: np.ndarray, clearance_m: np.ndarray, watched_dist_m: np.ndarray
) -> np.ndarray:
    """(N,) bool, rule 1: every Route A gate, clearance (NaN = unavailable) and no near miss.

    Args:
        gates_passed: (N,) bool, the expert passed every Route A gate.
        clearance_m: (N,) float, m, its hard clearance to the hazard (NaN unavailable).
        watched_dist_m: (N,) float, m, its least box distance to any watched actor.
    """
    clear_ok = np.isnan(clearance_m) | (clearance_m >= EXPERT_MARGIN_M)
    return gates_passed & clear_ok & (watched_dist_m >= EXPERT_MARGIN_M)


def speed_limit(v_max: float, lat_max: float, holonomic: bool, v_start: float) -> float:
    """m/s, the highest realised speed (along the path and sideways together) a tracked actor
    may reach: ``hypot(max(v_max, v_start), lateral speed bound)``, the lateral bound ``lat_max``
    for a walker and ``lat_max * max(v_max, v_start)`` for a vehicle; ``v_start`` is the
    actor's own scripted (or desired) speed, which a track never has to undo."""
    v = max(v_max, v_start)
    return float(np.hypot(v, lat_max if holonomic else lat_max * v))


def adversary_plausible(
    stop_max_s: np.ndarray, off_road_s: np.ndarray, max_speed: np.ndarray, limit: np.ndarray
) -> np.ndarray:
    """(N,) bool, rules 2-4 for candidates whose tracked actors' worst values are given.

    Args:
        stop_max_s: (N,) s, longest stop in the ego's path of any actor with a track.
        off_road_s: (N,) s, the longest total time off the road of any of them.
        max_speed: (N, T) m/s, each tracked actor's highest realised speed after its start.
        limit: (T,) m/s, their limits (:func:`speed_limit`).
    """
    within = np.all(max_speed <= np.asarray(limit)[None, :] + SPEED_TOLERANCE_MPS, axis=-1)
    return (stop_max_s <= STOP_IN_PATH_LIMIT_S) & (off_road_s <= OFF_ROAD_LIMIT_S) & within
