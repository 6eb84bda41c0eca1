"""Operational thresholds and weights of the Cooperative Unified Score (paper appendix
"Complete Cooperative Unified Score", DESIGN.md section 8).

Durations that are checked on the 20 Hz tick grid are stated both in seconds and in ticks; the
tick counts are what the accumulators compare against (``duration = ticks * DT``).
"""

from __future__ import annotations

import math

from lantern_jax.constants import DT, FAMILIES


# --- tick bookkeeping --------------------------------------------------------------------------
def ticks(seconds: float) -> int:
    """Number of 20 Hz ticks spanning ``seconds`` (``round(seconds / DT)``)."""
    return int(round(seconds / DT))


COUNT_CAP = 2**30  # ticks, saturation of every tick counter (no int32 overflow on long runs)
COUNT_HALF = 0.5  # ticks, a soft threshold on an integer count sits half a tick below the count
#                   that fails (e.g. 7.5 of 10 flags for "at least 8", 19.5 ticks for "20 ticks")
PROB_EPS = 1e-12  # a soft first-crossing probability at or below this counts as "never crossed"


# --- time-to-collision -------------------------------------------------------------------------
TTC_NORM_S = 3.0  # s, S_TTC = clip(TTC_min / 3 s)
CLOSING_MIN_MPS = 0.05  # m/s, a TTC sample needs a closing speed above this
COINCIDENT_SQ_M2 = 1e-12  # m^2, |r|^2 at or below this: coincident centres, no closing speed

# --- clearance ---------------------------------------------------------------------------------
D_SAFE_SMALL_M = 2.0  # m, Pedestrian Emergence and Obstacle Reveal
D_SAFE_LARGE_M = 3.0  # m, vehicle interactions (VC, LWW, RWW, RTY)
D_SAFE_BY_FAMILY = tuple(
    D_SAFE_SMALL_M if name in ("PE", "OR") else D_SAFE_LARGE_M for name in FAMILIES
)

# --- anticipation ------------------------------------------------------------------------------
REACT_WINDOW_S = 0.5  # s, length of the sustained-response window
REACT_WINDOW = ticks(REACT_WINDOW_S)  # 10 ticks
REACT_FRACTION = 0.8  # share of window samples that must show a response
REACT_MIN_COUNT = int(round(REACT_FRACTION * REACT_WINDOW))  # 8 of 10
REACT_ACCEL_MPS2 = -0.5  # m/s^2, braking response: accel <= this
REACT_SPEED_DROP_MPS = 1.0  # m/s, slowing response: speed <= v_pre - this

# --- recovery ----------------------------------------------------------------------------------
RECOVER_WINDOW_S = 1.0  # s, speed must stay above the threshold for this long
RECOVER_WINDOW = ticks(RECOVER_WINDOW_S)  # 20 ticks
RECOVER_MIN_SPEED_MPS = 2.0  # m/s, threshold = max(2 m/s, 0.5 v_pre)
RECOVER_PRE_FRACTION = 0.5
RECOVER_MIN_PROGRESS_M = 0.5  # m, additional route progress over the window
RECOVER_CAP_S = 8.0  # s, S_rec = clip(1 - RL / 8 s)

# --- gates -------------------------------------------------------------------------------------
COLLISION_MIN_SPEED_MPS = 0.1  # m/s, a contact counts as a collision only at ego speed >= this
ROUTE_DEVIATION_M = 30.0  # m, severe route deviation: distance to route >= this
LANE_DEBOUNCE_S = 1.0  # s, total time outside the driving lanes that fails the lane gate
LANE_DEBOUNCE = ticks(LANE_DEBOUNCE_S)  # 20 ticks
STILL_SPEED_MPS = 0.1  # m/s, "standing still" for the blocking gate: speed < this
BLOCK_STILL_S = 20.0  # s, continuous standstill (route not completed) that fails the block gate
BLOCK_STILL = ticks(BLOCK_STILL_S)  # 400 ticks
COMPLETION_TOL_M = 2.0  # m, route completed when progress >= route_length - this


def completion_length(route_length):
    """Length against which route completion is measured: reaching the route's end zone
    (``route_length - COMPLETION_TOL_M``) counts as 100 % (the leaderboard's > 99 % rule)."""
    return route_length - COMPLETION_TOL_M


FALSE_BRAKE_SPEED_MPS = 0.1  # m/s, Route B stop: speed <= this
FALSE_BRAKE_S = 1.0  # s, continuous unjustified stop touching the matched stretch: gate fails
FALSE_BRAKE = ticks(FALSE_BRAKE_S)  # 20 ticks
FALSE_BRAKE_COINCIDENT_LEAD_M = 10.0  # m, coincident warning/event points (RTY): the matched
#                                       stretch starts this far before the warning point

# --- weights -----------------------------------------------------------------------------------
W_ROUTE_A = 0.85
W_ROUTE_B = 0.15
W_PROGRESS_A = 0.40
W_SAFETY_A = 0.35
W_TEMPORAL_A = 0.25
CUS_SCALE = 100.0  # the CUS is reported in points, 0..100

# --- language diagnostics (paper appendix "Diagnostics with Non-Actionable Language Inputs") ----
NONACTIONABLE_MAX_DV_MPS = 2.0  # m/s, max additional speed reduction vs no warning: below this
NONACTIONABLE_MAX_STOP_S = 1.0  # s, no standstill (speed < STILL_SPEED_MPS) of this length
NONACTIONABLE_MAX_RC_DROP = 5.0  # percentage points, route completion may drop at most this

# --- response to unseen hazards (paper appendix "Protocol Extension to Unseen Hazards") ---------
RESPONSE_BRAKE = 0.5  # brake signal (commanded deceleration / brake limit) of a braking step
RESPONSE_STEPS = 3  # consecutive 20-Hz control steps at or above it: a sustained response

# --- per-tick measurement (scoring/measure.py) -------------------------------------------------
LANE_MARGIN_M = 0.5  # m, outside every lane: centre farther than half a lane width + this
WRONG_WAY_RAD = 2.0 * math.pi / 3.0  # rad, heading difference that counts as driving a lane
#                                      backwards (the leaderboard's junction threshold, 120 deg)
JUSTIFY_LEAD_DIST_M = 15.0  # m, an actor this close ahead in the corridor justifies a stop
JUSTIFY_LEAD_BEHIND_M = -2.0  # m, ... or overlapping the ego front by up to 2 m
JUSTIFY_LATERAL_MARGIN_M = 0.5  # m, an actor whose box comes within ego half width + this of
#                                the route centre line is in the ego's path (a vehicle parked
#                                beside the lane, e.g. Pedestrian Emergence's occluder, is not)
JUSTIFY_ROUTE_END_M = 10.0  # m, standing this close to the route end is justified
