"""Scenario parameter ranges, validation, weather profiles and content hashing.

A scenario pair is fully described by a flat, JSON-friendly parameter dict (what a frozen suite
stores); :func:`lantern_jax.scenarios.families.build_pair` turns it into the Route A / Route B
scenarios.  Every family's admissible ranges live in :data:`PARAM_RANGES`; :func:`range_errors`
checks a dict against them, naming each bad field, e.g. ``"PE.route_length: 150.0 outside [68,
135]"`` (:func:`lantern_jax.scenarios.families.validate_params` adds each family's cross-field
feasibility rules).

Ranges follow the paper's "Detailed Scenario Specifications" table; route lengths are the
closed-loop ranges of its data-collection appendix as rounded in DESIGN.md section 5 (PE 68-135 m,
VC 58-164, OR 66-133, LWW 56-80, RWW 52-87, RTY 50-75).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from lantern_jax.constants import FAMILIES, WEATHERS


# ------------------------------------------------------------------------------------------------
# weather
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WeatherProfile:
    """What a weather profile changes in this simulator.

    ``carla`` records the paper's CARLA settings (cloudiness, precipitation, wetness, fog, sun
    altitude in degrees; the first four on CARLA's 0-100 scale).  The paper gives only those
    settings; ``friction`` (tyre-road coefficient scaling the braking limit) and
    ``sensing_range`` (camera range, m) are this package's mapping of them:

    ============  ========  =======  =============================================
    profile       friction  range m  reasoning
    ============  ========  =======  =============================================
    clear_day     1.00      120      dry road, full visibility
    cloudy_day    1.00      100      dry road, flat light
    wet_day       0.75       90      wet asphalt (wetness 70), light fog
    light_rain    0.70       70      rain on a wet road, spray and fog
    dusk          0.95       60      low sun (8 deg), slightly damp
    ============  ========  =======  =============================================
    """

    name: str
    friction: float
    sensing_range: float  # m
    carla: tuple[float, float, float, float, float]


WEATHER_PROFILES: dict[str, WeatherProfile] = {
    "clear_day": WeatherProfile("clear_day", 1.0, 120.0, (5, 0, 0, 2, 45)),
    "cloudy_day": WeatherProfile("cloudy_day", 1.0, 100.0, (75, 0, 0, 3, 55)),
    "wet_day": WeatherProfile("wet_day", 0.75, 90.0, (65, 0, 70, 5, 35)),
    "light_rain": WeatherProfile("light_rain", 0.7, 70.0, (85, 25, 80, 4, 40)),
    "dusk": WeatherProfile("dusk", 0.95, 60.0, (40, 0, 10, 2, 8)),
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

_COMMON = {
    "seed": IntRange(0, SEED_MAX),  # pair seed: position-noise seed of the ablation
    "bg_seed": IntRange(0, SEED_MAX),  # background-traffic seed (shared by Route A and B)
    "weather": Choice(WEATHERS),
    "rotation_deg": FloatRange(0.0, 360.0),  # rigid rotation of the whole scene
}

_JUNCTION = {
    "num_arms": Choice((3, 4)),
    "missing_arm": Choice(("none", "E", "N", "W")),
    "signalized": Flag(),
    "red_s": FloatRange(2.0, 8.0),  # s, initial red of the ego light (unused if unsignalized)
    "approach": FloatRange(12.0, 50.0),  # m, route start to the junction-box edge
}

#: Parameter ranges per family (paper: "Detailed Scenario Specifications").
PARAM_RANGES: dict[str, dict[str, Any]] = {
    "PE": {
        **_COMMON,
        "v_ref": FloatRange(8.0, 10.0),
        "route_length": FloatRange(68.0, 135.0),
        "conflict_s": FloatRange(33.0, 48.0),  # m, route arc of the pedestrian crossing line
    },
    "VC": {
        **_COMMON,
        "v_ref": FloatRange(9.0, 11.0),
        "route_length": FloatRange(58.0, 164.0),
        "cut_frac": FloatRange(0.80, 0.85),  # cut-in speed / v_ref (floored at 6.5 m/s)
        "gap_event": FloatRange(6.0, 10.0),  # m, nominal centre gap at the event
        "warn_lead": Choice((10.0, 17.0)),
        "num_opposing": Choice((1, 2)),
    },
    "OR": {
        **_COMMON,
        "v_ref": FloatRange(8.0, 10.0),
        "route_length": FloatRange(66.0, 133.0),
        "lead_speed_kmh": FloatRange(12.0, 20.0),
        "lead_gap": FloatRange(15.0, 25.0),  # m, van centre ahead of the ego at t = 0
        "reveal_s": FloatRange(30.0, 104.0),  # m, route arc of the reveal point C
        "object_ahead": FloatRange(12.0, 16.0),  # m, object centre ahead of C
        "num_opposing": Choice((1, 2)),
    },
    "LWW": {
        **_COMMON,
        **_JUNCTION,
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(56.0, 80.0),
        "actor_speed": FloatRange(7.0, 9.0),
    },
    "RWW": {
        **_COMMON,
        **_JUNCTION,
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(52.0, 87.0),
        "actor_speed": FloatRange(7.0, 9.0),
    },
    "RTY": {
        **_COMMON,
        **_JUNCTION,
        "v_ref": FloatRange(6.0, 8.0),
        "route_length": FloatRange(50.0, 75.0),
        "actor_speed": FloatRange(8.0, 12.0),
        "source_dist": FloatRange(10.0, 50.0),  # m, spawn distance before the crossing point
    },
}
assert tuple(PARAM_RANGES) == FAMILIES


def family_of(params: dict) -> str:
    """The family abbreviation of a parameter dict, validated."""
    fam = params.get("family") if isinstance(params, dict) else None
    if not isinstance(fam, str) or fam not in PARAM_RANGES:
        raise ValueError(f"family: {fam!r} not one of {{{', '.join(FAMILIES)}}}")
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
    table = PARAM_RANGES[fam]
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
