"""Scenario parameter ranges, validation, weather profiles and content hashing.

A scenario pair is fully described by a flat, JSON-friendly parameter dict (what a frozen suite
stores); :func:`lantern_jax.scenarios.families.build_pair` turns it into the Route A / Route B
scenarios.  The six families' admissible ranges are written in :data:`PARAM_RANGES` and held by
their entries of the family registry (as a registered family's are); :func:`range_errors` checks
a dict against them, naming each bad field, e.g. ``"PE.route_length: 150.0 outside [68,
135]"`` (:func:`lantern_jax.scenarios.families.validate_params` adds each family's cross-field
feasibility rules).

Ranges follow the paper's "Detailed Scenario Specifications" table; route lengths are the
closed-loop ranges of its data-collection appendix rounded to the nearest metre (PE 68-135 m,
VC 58-164, OR 66-133, LWW 56-80, RWW 52-87, RTY 50-75).  Every pair also samples its own
geometry within documented ranges (lane count and width, road curvature, junction size through
the kerb radius, skewed arms, occluder type, size and set-back, hazard offsets), so that no two
routes of a family are near duplicates (:mod:`lantern_jax.scenarios.duplicates`).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES, WEATHERS
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY


# ------------------------------------------------------------------------------------------------
# weather
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WeatherProfile:
    """What a weather profile changes in this simulator.

    ``carla`` records the paper's CARLA settings (cloudiness, precipitation, wetness, fog, sun
    altitude in degrees; the first four on CARLA's 0-100 scale).  CARLA weather changes neither
    tyre friction nor geometry, so every profile keeps ``friction = 1.0``; what it changes here is
    the camera's ``sensing_range`` (m), this package's stand-in for visual degradation (rain,
    fog, low sun):

    ============  ========  =======  =============================================
    profile       friction  range m  reasoning
    ============  ========  =======  =============================================
    clear_day     1.0       120      full visibility
    cloudy_day    1.0       100      flat light
    wet_day       1.0        90      light fog (fog 5), spray
    light_rain    1.0        70      rain, spray and fog
    dusk          1.0        60      low sun (8 deg)
    ============  ========  =======  =============================================
    """

    name: str
    friction: float
    sensing_range: float  # m
    carla: tuple[float, float, float, float, float]


WEATHER_PROFILES: dict[str, WeatherProfile] = {
    "clear_day": WeatherProfile("clear_day", 1.0, 120.0, (5, 0, 0, 2, 45)),
    "cloudy_day": WeatherProfile("cloudy_day", 1.0, 100.0, (75, 0, 0, 3, 55)),
    "wet_day": WeatherProfile("wet_day", 1.0, 90.0, (65, 0, 70, 5, 35)),
    "light_rain": WeatherProfile("light_rain", 1.0, 70.0, (85, 25, 80, 4, 40)),
    "dusk": WeatherProfile("dusk", 1.0, 60.0, (40, 0, 10, 2, 8)),
}
assert tuple(WEATHER_PROFILES) == WEATHERS


# ------------------------------------------------------------------------------------------------
# range types
# ------------------------------------------------------------------------------------------------
def _num(x: float) -> str:
    return f"{x:g}"


@dataclass(frozen=True)
class FloatRange:
    """A closed float interval ``[lo, hi]``."""

    lo: float
    hi: float

    def check(self, name: str, v: Any) -> None:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number)):
            raise ValueError(f"{name}: expected a number, got {v!r}")
        try:
            f = float(v)
        except OverflowError:  # an integer beyond the float range
            f = math.inf if v > 0 else -math.inf
        if not math.isfinite(f) or not self.lo <= f <= self.hi:
            raise ValueError(f"{name}: {f!r} outside [{_num(self.lo)}, {_num(self.hi)}]")


@dataclass(frozen=True)
class IntRange:
    """A closed integer interval ``[lo, hi]``."""

    lo: int
    hi: int

    def check(self, name: str, v: Any) -> None:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"{name}: expected an integer, got {v!r}")
        if not self.lo <= int(v) <= self.hi:
            raise ValueError(f"{name}: {int(v)} outside [{self.lo}, {self.hi}]")


@dataclass(frozen=True)
class Choice:
    """One of a fixed set of values (numbers compare by value, strings exactly)."""

    options: tuple

    def check(self, name: str, v: Any) -> None:
        ok = not isinstance(v, (bool, np.bool_)) and any(
            (isinstance(o, str) and v == o)
            or (not isinstance(o, str) and isinstance(v, (int, float, np.number)) and v == o)
            for o in self.options
        )
        if not ok:
            opts = ", ".join(map(str, self.options))
            raise ValueError(f"{name}: {v!r} not one of {{{opts}}}")


@dataclass(frozen=True)
class Flag:
    """A boolean."""

    def check(self, name: str, v: Any) -> None:
        if not isinstance(v, (bool, np.bool_)):
            raise ValueError(f"{name}: expected a bool, got {v!r}")


SEED_MAX = 2**31 - 1
MIN_RECOVERY_M = 29.0  # m of route after the conflict point, every family (paper appendix A)
MAX_CURVATURE = 1.0 / 70.0  # 1/m, gentle: < 1.5 m/s^2 lateral acceleration at 10 m/s
MAX_BEND = 1.0 / 30.0  # 1/m, junction arms (v_ref <= 8 m/s: < 2.2 m/s^2)


def route_timeout_s(route_length_m: float) -> float:
    """Route timeout in s of a route ``route_length_m`` m long, ``20 s + length / (3 m/s)``,
    for every family (an execution whose ego has not finished by then ends there)."""
    return 20.0 + route_length_m / 3.0


#: Fields every family's parameter dict has (seeds, weather, scene rotation).
COMMON_RANGES = {
    "seed": IntRange(0, SEED_MAX),  # pair seed: position-noise seed of the ablation
    "bg_seed": IntRange(0, SEED_MAX),  # background-traffic seed (shared by Route A and B)
    "weather": Choice(WEATHERS),
    "rotation_deg": FloatRange(0.0, 360.0),  # rigid rotation of the whole scene
}

#: Road geometry of the straight-road families (scenarios.road_straight).
_STRAIGHT = {
    "lane_width": FloatRange(3.0, 3.75),  # m
    "lanes_back": Choice((1, 2)),  # opposing lanes
    "curvature_1": FloatRange(-MAX_CURVATURE, MAX_CURVATURE),  # 1/m before curve_split, + left
    "curvature_2": FloatRange(-MAX_CURVATURE, MAX_CURVATURE),  # 1/m from curve_split on
    "curve_split": FloatRange(20.0, 80.0),  # m, route arc where the curvature changes
}

#: Junction geometry and occluders of the junction families (scenarios.road_junction).
_JUNCTION = {
    "num_arms": Choice((3, 4)),
    "missing_arm": Choice(("none", "E", "N", "W")),
    "signalized": Flag(),
    "red_s": FloatRange(2.0, 8.0),  # s, initial red of the ego light (unused if unsignalized)
    "approach": FloatRange(12.0, 50.0),  # m, route start to the junction-box edge
    "lanes_per_direction": Choice((1, 2)),
    "lane_width": FloatRange(3.0, 3.75),  # m
    "kerb_radius": FloatRange(6.5, 10.0),  # m, corner fillet radius (sets the junction size)
    "skew_E": FloatRange(-20.0, 20.0),  # deg, counter-clockwise rotation of the E arm
    "skew_N": FloatRange(-20.0, 20.0),  # deg, of the N arm
    "skew_W": FloatRange(-20.0, 20.0),  # deg, of the W arm
    "bend_approach": FloatRange(-MAX_BEND, MAX_BEND),  # 1/m, the ego's approach arm
    "bend_exit": FloatRange(-MAX_BEND, MAX_BEND),  # 1/m, the ego's exit arm
    "corner_kind": Choice(("building", "wall")),  # occluder at every rounded corner
    "corner_setback": FloatRange(1.0, 4.0),  # m, occluder's distance inside the kerb arc
    "corner_size": FloatRange(10.0, 20.0),  # m, building side / wall length
}

#: Parameter ranges per family (paper: "Detailed Scenario Specifications"; geometry ranges are
#: this package's, documented in the family builders).
PARAM_RANGES: dict[str, dict[str, Any]] = {
    "PE": {
        **COMMON_RANGES,
        **_STRAIGHT,
        "v_ref": FloatRange(8.0, 10.0),
        "route_length": FloatRange(68.0, 135.0),
        "conflict_s": FloatRange(33.0, 48.0),  # m, route arc of the pedestrian crossing line
        "lanes_fwd": Choice((1, 2)),  # the ego drives the rightmost one, beside the parking lane
        "parking_width": FloatRange(2.2, 2.8),  # m
        "truck_length": FloatRange(6.0, 10.0),  # m, the parked truck or van hiding the walker
        "truck_width": FloatRange(2.2, 2.6),  # m
        "ped_gap": FloatRange(0.2, 0.8),  # m, truck front to the pedestrian's box
        "ped_offset": FloatRange(0.3, 1.0),  # m, pedestrian centre beyond the kerb
        "parked_count": Choice((0, 1, 2)),  # further parked vehicles beyond the crossing
    },
    "VC": {
        **COMMON_RANGES,
        **_STRAIGHT,
        "v_ref": FloatRange(9.0, 11.0),
        "route_length": FloatRange(58.0, 164.0),
        "cut_frac": FloatRange(0.80, 0.85),  # cut-in speed / v_ref (floored at 6.5 m/s)
        "gap_event": FloatRange(6.0, 10.0),  # m, nominal centre gap at the event
        "warn_lead": Choice((10.0, 17.0)),
        "lanes_fwd": Choice((2, 3)),  # the cut-in comes from the rightmost lane
    },
    "OR": {
        **COMMON_RANGES,
        # straight approach, then a street corner (see families_straight.or_centerline)
        **{k: v for k, v in _STRAIGHT.items() if k not in ("curvature_1", "curve_split")},
        "v_ref": FloatRange(8.0, 10.0),
        "route_length": FloatRange(66.0, 133.0),
        "lead_speed_kmh": FloatRange(12.0, 20.0),
        "lead_gap": FloatRange(15.0, 25.0),  # m, van centre ahead of the ego at t = 0
        "reveal_s": FloatRange(30.0, 104.0),  # m, route arc where the van starts its lane change
        "object_ahead": FloatRange(12.0, 16.0),  # m, object centre ahead of the van then
        "van_length": FloatRange(5.0, 6.0),  # m
        "object_width": FloatRange(1.4, 2.0),  # m, narrower than the van (2.2 m)
        "lanes_fwd": Choice((2, 3)),  # the ego drives the rightmost one; the van moves left
        "turn_side": Choice(("left", "right")),  # the corner 2 m past the object
        "turn_angle": FloatRange(20.0, 90.0),  # deg
        "turn_radius": FloatRange(15.0, 40.0),  # m, of the ego lane's centre line
    },
    "LWW": {
        **COMMON_RANGES,
        **_JUNCTION,
        # single-lane, tight junctions only: with two lanes per direction or a wide kerb radius
        # the left turn is so long that a wrong-way car 25 m along the reversed route from a
        # conflict point within reach of the 10-m warning lead waits at the box edge, in plain
        # view across the junction, where no corner occluder can hide it
        "lanes_per_direction": Choice((1,)),
        "kerb_radius": FloatRange(6.5, 8.5),
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(56.0, 80.0),
        "actor_speed": FloatRange(7.0, 9.0),
        "conflict_offset": FloatRange(6.0, 10.0),  # m, conflict point past the box entry
        "truck_length": FloatRange(6.0, 9.0),  # m, truck waiting at the W arm's stop line
    },
    "RWW": {
        **COMMON_RANGES,
        **_JUNCTION,
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(52.0, 87.0),
        "actor_speed": FloatRange(7.0, 9.0),
        "conflict_offset": FloatRange(6.0, 10.0),  # m, conflict point past the box entry
    },
    "RTY": {
        **COMMON_RANGES,
        **_JUNCTION,
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(50.0, 75.0),
        "actor_speed": FloatRange(8.0, 12.0),
        "source_dist": FloatRange(15.0, 50.0),  # m, first flow vehicle before its crossing point
        "source_interval": FloatRange(10.0, 50.0),  # m, spacing of the flow (paper)
        "flow_size": Choice((2, 3, 4)),  # vehicles in the flow (the first is evaluated)
    },
}
assert tuple(PARAM_RANGES) == FAMILIES


def param_ranges(code: str) -> Mapping[str, Any]:
    """The parameter ranges of a family (built-in or registered): its registry entry's table
    (:data:`lantern_jax.scenarios.family_registry.FAMILY_REGISTRY`; the six's entries hold
    :data:`PARAM_RANGES`).

    Raises:
        ValueError: naming the known families.
    """
    return FAMILY_REGISTRY.entry(code).ranges


def family_of(params: dict) -> str:
    """The family abbreviation of a parameter dict, validated."""
    fam = params.get("family") if isinstance(params, dict) else None
    if not family_codes.is_known(fam):
        raise ValueError(f"family: {fam!r} not one of {{{', '.join(family_codes.codes())}}}")
    return fam


def range_errors(params: Any) -> list[str]:
    """Every type and range problem of a scenario parameter dict, each naming its field.

    Checks the JSON type (a dict), the family, unknown and missing fields, and each field's type
    and range (:data:`PARAM_RANGES`; NaN and infinities are out of every range).  The families'
    cross-field feasibility rules are checked on top of this by
    :func:`lantern_jax.scenarios.families.param_errors`.

    Args:
        params: flat dict with ``family`` and the fields of ``PARAM_RANGES[family]``.

    Returns:
        Messages such as ``"PE.route_length: 150.0 outside [68, 135]"``; empty when valid.
    """
    if not isinstance(params, dict):
        return [f"params: expected a JSON object, got {type(params).__name__} {params!r}"]
    try:
        fam = family_of(params)
    except ValueError as e:
        return [str(e)]
    table = param_ranges(fam)
    errors = [
        f"{fam}.{key}: unknown parameter (known: {', '.join(table)})"
        for key in params
        if key != "family" and key not in table
    ]
    for key, rng in table.items():
        if key not in params:
            errors.append(f"{fam}.{key}: missing")
            continue
        try:
            rng.check(f"{fam}.{key}", params[key])
        except ValueError as e:
            errors.append(str(e))
    return errors


# ------------------------------------------------------------------------------------------------
# canonical form and hashing
# ------------------------------------------------------------------------------------------------
def _canon(v: Any) -> Any:
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"canonical_json: non-finite value {f}")
        return f + 0.0  # exact (shortest round-trip repr); + 0.0 turns -0.0 into 0.0
    if isinstance(v, dict):
        return {str(k): _canon(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_canon(x) for x in v]
    raise ValueError(f"canonical_json: unsupported value {v!r} of type {type(v).__name__}")


def canonical_json(params: dict) -> str:
    """Canonical JSON of a parameter dict: sorted keys, compact, floats exact.

    Floats are written with Python's shortest round-trip representation, so two dicts have
    the same canonical form exactly when they hold the same values (``-0.0`` counts as ``0.0``)
    and therefore build the same worlds; a value with at most six decimals is written as the
    earlier, 1e-6-rounded form wrote it, so existing content hashes are unchanged.
    """
    return json.dumps(_canon(params), sort_keys=True, separators=(",", ":"), allow_nan=False)


def content_hash(params: dict) -> str:
    """SHA-256 hex digest of :func:`canonical_json` (the pair's content hash)."""
    return hashlib.sha256(canonical_json(params).encode("utf-8")).hexdigest()
