"""The scoring settings: every threshold and weight of the Cooperative Unified Score (paper
appendix "Complete Cooperative Unified Score") and the soft-score temperature, as one frozen
pytree passed to the scoring functions as an argument.

:class:`ScoringSettings` holds the paper's values as defaults.  A changed threshold is a
different argument: ``ScoringSettings(ttc_norm_s=2.0)`` scores with a 2-s TTC normalisation,
and no compiled program made for the default can answer for it.  Float fields are traced (a
change needs no recompile and can be batched with ``vmap``); the windows counted on the 20 Hz
tick grid are static (``duration = ticks * DT``: a ring buffer's length is a shape), so changing
one compiles again.

Numerical guards of the implementation (not settings) are the module constants below.
"""

from __future__ import annotations

import math

import jax
from flax import struct

from lantern_jax.core.constants import DT, FAMILIES
from lantern_jax.core.times import ticks
from lantern_jax.scoring.user_metrics import Metric, metric_problem

Array = jax.Array

COUNT_CAP = 2**30  # ticks, saturation of every tick counter (no int32 overflow on long runs)
COUNT_HALF = 0.5  # ticks, a soft threshold on an integer count sits half a tick below the count
#                   that fails (e.g. 7.5 of 10 flags for "at least 8", 19.5 ticks for "20 ticks")
PROB_EPS = 1e-12  # a soft first-crossing probability at or below this counts as "never crossed"
COINCIDENT_SQ_M2 = 1e-12  # m^2, |r|^2 at or below this: coincident centres, no closing speed


@struct.dataclass
class ScoringSettings:
    """Thresholds, weights and the soft temperature of the CUS (paper appendix values).

    Every float field is a () float32 leaf when traced; the ``*_s`` fields marked static are
    Python floats that fix tick counts (:func:`ticks`).
    """

    # --- the soft score --------------------------------------------------------------------------
    temperature: float = 0.05  # temperature of the soft accumulators and clips (in each relaxed
    #                            quantity's own unit: s, m, m/s, m/s^2, samples)

    # --- time-to-collision -------------------------------------------------------------------
    ttc_norm_s: float = 3.0  # s, S_TTC = clip(TTC_min / 3 s)
    closing_min_mps: float = 0.05  # m/s, a TTC sample needs a closing speed above this

    # --- anticipation ------------------------------------------------------------------------
    react_window_s: float = struct.field(pytree_node=False, default=0.5)  # s, sustained window
    react_fraction: float = struct.field(pytree_node=False, default=0.8)  # share of the window
    react_accel_mps2: float = -0.5  # m/s^2, braking response: accel <= this
    react_speed_drop_mps: float = 1.0  # m/s, slowing response: speed <= v_pre - this

    # --- recovery ----------------------------------------------------------------------------
    recover_window_s: float = struct.field(pytree_node=False, default=1.0)  # s above threshold
    recover_min_speed_mps: float = 2.0  # m/s, threshold = max(2 m/s, 0.5 v_pre)
    recover_pre_fraction: float = 0.5
    recover_min_progress_m: float = 0.5  # m, additional route progress over the window
    recover_cap_s: float = 8.0  # s, S_rec = clip(1 - RL / 8 s)

    # --- gates -------------------------------------------------------------------------------
    collision_min_speed_mps: float = 0.1  # m/s, a contact is a collision only at or above this
    route_deviation_m: float = 30.0  # m, severe route deviation: distance to route >= this
    lane_debounce_s: float = struct.field(pytree_node=False, default=1.0)  # s outside lanes
    still_speed_mps: float = 0.1  # m/s, "standing still" for the blocking gate: below this
    block_still_s: float = struct.field(pytree_node=False, default=20.0)  # s of standstill
    completion_tol_m: float = 2.0  # m, route completed when progress >= length - this
    false_brake_speed_mps: float = 0.1  # m/s, Route B stop: speed <= this
    false_brake_s: float = struct.field(pytree_node=False, default=1.0)  # s of unjustified stop
    false_brake_coincident_lead_m: float = 10.0  # m, coincident warning/event points (RTY): the
    #                                              matched stretch starts this far before them

    # --- route efficiency (a diagnostic beside the CUS, components/efficiency.py) -----------
    slow_speed_fraction: float = 0.5  # "slow" below this fraction of the reference speed

    # --- weights -----------------------------------------------------------------------------
    w_route_a: float = 0.85
    w_route_b: float = 0.15
    w_progress_a: float = 0.40
    w_safety_a: float = 0.35
    w_temporal_a: float = 0.25
    cus_scale: float = 100.0  # the CUS is reported in points, 0..100

    # --- per-tick measurement (scoring/measure.py) ---------------------------------------------
    lane_margin_m: float = 0.5  # m, outside every lane: farther than half a lane width + this
    wrong_way_rad: float = 2.0 * math.pi / 3.0  # rad, heading difference that counts as driving
    #                                            a lane backwards (the leaderboard's 120 deg)
    justify_lead_dist_m: float = 15.0  # m, an actor this close ahead in the corridor justifies
    #                                    a stop ...
    justify_lead_behind_m: float = -2.0  # m, ... or overlapping the ego front by up to 2 m
    justify_lateral_margin_m: float = 0.5  # m, an actor within ego half width + this of the
    #                                        route centre line is in the ego's path
    justify_route_end_m: float = 10.0  # m, standing this close to the route end is justified

    # --- measurements of your own (static; scoring/user_metrics.py; never in the CUS) --------
    metrics: tuple[Metric, ...] = struct.field(pytree_node=False, default=())

    # --- tick counts (static) ------------------------------------------------------------------
    @property
    def react_window(self) -> int:
        """Ticks of the sustained-response window (10 at the default 0.5 s)."""
        return ticks(self.react_window_s)

    @property
    def react_min_count(self) -> int:
        """Window samples that must show a response (8 of 10 by default)."""
        return int(round(self.react_fraction * self.react_window))

    @property
    def recover_window(self) -> int:
        """Ticks the recovery window spans (20 by default)."""
        return ticks(self.recover_window_s)

    @property
    def lane_debounce(self) -> int:
        """Ticks outside the lanes that fail the lane gate (20 by default)."""
        return ticks(self.lane_debounce_s)

    @property
    def block_still(self) -> int:
        """Ticks of continuous standstill that fail the block gate (400 by default)."""
        return ticks(self.block_still_s)

    @property
    def false_brake(self) -> int:
        """Ticks of unjustified Route B stop that fail the false-brake gate (20 by default)."""
        return ticks(self.false_brake_s)

    def completion_length(self, route_length):
        """Length against which route completion is measured: reaching the route's end zone
        (``route_length - completion_tol_m``) counts as 100 % (the leaderboard's > 99 %
        rule)."""
        return route_length - self.completion_tol_m

    def validate(self) -> ScoringSettings:
        """Check the values outside ``jit`` (finite, positive where they must be); returns self.

        Raises:
            ValueError: naming the field.
        """
        for name in _POSITIVE:
            v = getattr(self, name)
            if isinstance(v, int | float) and not (math.isfinite(v) and v > 0):
                raise ValueError(f"ScoringSettings.{name}: must be a finite number > 0, got {v!r}")
        for name, v in vars(self).items():
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"ScoringSettings.{name}: must be finite, got {v!r}")
        if not 0.0 < self.react_fraction <= 1.0:
            raise ValueError(
                f"ScoringSettings.react_fraction: must be in (0, 1], got {self.react_fraction!r}"
            )
        for name in ("react_window_s", "recover_window_s", "lane_debounce_s", "block_still_s",
                     "false_brake_s"):  # fmt: skip
            if ticks(getattr(self, name)) < 1:
                raise ValueError(
                    f"ScoringSettings.{name}: must span at least one tick ({DT} s), got "
                    f"{getattr(self, name)!r}"
                )
        if not isinstance(self.metrics, tuple):
            raise ValueError(f"ScoringSettings.metrics: expected a tuple of Metric, got "
                             f"{type(self.metrics).__name__}")  # fmt: skip
        taken: set[str] = set()
        for i, metric in enumerate(self.metrics):
            problem = metric_problem(metric, taken)
            if problem:
                raise ValueError(f"ScoringSettings.metrics[{i}]: {problem}")
            taken |= {metric.name, f"B_{metric.name}"}
        return self


_POSITIVE = (
    "temperature", "ttc_norm_s", "closing_min_mps", "react_speed_drop_mps", "recover_cap_s",
    "route_deviation_m", "still_speed_mps", "false_brake_speed_mps", "cus_scale",
)  # fmt: skip

#: The paper's values.
DEFAULT_SCORING = ScoringSettings()

# --- the clearance normaliser of each interaction (paper): part of a scene, not a setting -------
# A family writes it into every scene it builds (``ExecutionConfig.d_safe``), where the suite's
# validation and content hash cover it.
D_SAFE_SMALL_M = 2.0  # m, Pedestrian Emergence and Obstacle Reveal
D_SAFE_LARGE_M = 3.0  # m, vehicle interactions (VC, LWW, RWW, RTY)
#: Deprecated (one release): the built-in families' values by index, read only by the deprecated
#: ``scoring.cus.d_safe_for_family``; a family's value lives in its registry entry.
D_SAFE_BY_FAMILY = tuple(
    D_SAFE_SMALL_M if name in ("PE", "OR") else D_SAFE_LARGE_M for name in FAMILIES
)

# --- language diagnostics (paper appendix "Diagnostics with Non-Actionable Language Inputs") ----
# Host-side criteria of a table (never inside a compiled program).
NONACTIONABLE_MAX_DV_MPS = 2.0  # m/s, max additional speed reduction vs no warning: below this
NONACTIONABLE_MAX_STOP_S = 1.0  # s, no standstill (speed < still_speed_mps) of this length
NONACTIONABLE_MAX_RC_DROP = 5.0  # percentage points, route completion may drop at most this

# --- response to unseen hazards (paper appendix "Protocol Extension to Unseen Hazards") ---------
# Host-side criteria of a table (never inside a compiled program).
RESPONSE_BRAKE = 0.5  # brake signal (commanded deceleration / brake limit) of a braking step
RESPONSE_STEPS = 3  # consecutive 20-Hz control steps at or above it: a sustained response
