"""The six LANTERN scenario families, one record each, and matched Route A / Route B pairs.

Usage::

    rng = np.random.default_rng(0)
    params = sample_params("PE", rng, "wet_day")           # flat, JSON-friendly dict
    scenario_a, scenario_b, meta = build_pair(params)       # Scenario pytrees

A frozen suite stores only the parameter dicts (and their
:func:`~lantern_jax.scenarios.spec.content_hash`); building is deterministic.

Every family is one entry of the family registry
(:data:`~lantern_jax.scenarios.family_registry.FAMILY_REGISTRY`,
:class:`~lantern_jax.scenarios.family_registry.FamilyEntry`) — its sampler, cross-field
feasibility check, builder, parameter ranges, stress knobs, premise rule, clearance normaliser
and what its warning asks the ego to do.  This module registers the six
(:data:`BUILTIN_FAMILIES`); families written outside the package are registered through
:mod:`lantern_jax.scenarios.registry` (the public way; ``docs/families.md``), whose
:func:`~lantern_jax.scenarios.registry.register_family` ends in the same registry call.

Shared conventions of every family:

* markers (route arcs, m): ``s_warn = s_conflict - warn_lead``, ``s_event = s_conflict -
  event_lead``; the hazard is the controlled actor in slot ``hazard_index`` (= 0);
* Route A and Route B share waypoints, map, lights, weather, ``v_ref``, route length, background
  traffic and every actor except the hazard behaviour (slots listed in ``meta["scenario_slots"]``);
* Route A has ``warning_enabled=True`` (the evaluator flips it for the no-warning run); Route B
  has ``is_route_a=False`` and ``warning_enabled=False``;
* execution starts at ``t = 0`` with the ego at route arc 0, on its lane centre, heading along the
  route, already moving at ``v_ref`` (zero steer and acceleration);
* ``force_event`` True except RTY, ``force_delay`` 2 s, ``d_safe`` 2 m for PE/OR and 3 m
  otherwise, ``template_id = text_id = family index``, ``timeout_s`` from the route length
  (:func:`~lantern_jax.scenarios.spec.route_timeout_s`), ablation fields off, ``noise_seed``
  from ``params["seed"]``.

A parameter dict may carry an optional ``knobs`` object (knob name -> value, inside the family's
:data:`KNOB_RANGES`), applied to the built pair with
:func:`~lantern_jax.scenarios.knobs.apply_knobs`, and an optional ``adversary`` object (actor
tracks, :mod:`lantern_jax.scenarios.adversary`), applied after the knobs: that is how a scenario
found by stress testing is written as an ordinary suite pair, hashed and validated like any
other.

Family geometry is documented in :mod:`~lantern_jax.scenarios.families_straight` (PE, VC, OR) and
:mod:`~lantern_jax.scenarios.families_junction` (LWW, RWW, RTY).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES, FAMILY_NAMES, WEATHERS
from lantern_jax.scenarios import families_junction as junction
from lantern_jax.scenarios import families_straight as straight
from lantern_jax.scenarios.adversary import (
    ADVERSARY_FIELD,
    adversary_errors,
    apply_adversary,
    slot_errors,
)
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY, FamilyEntry
from lantern_jax.scenarios.knobs import apply_knobs
from lantern_jax.scenarios.premise import PREMISE_AT_WARNING, PREMISE_NONE, PREMISE_WHOLE_APPROACH
from lantern_jax.scenarios.spec import PARAM_RANGES, content_hash, range_errors
from lantern_jax.scoring.thresholds import D_SAFE_LARGE_M, D_SAFE_SMALL_M
from lantern_jax.types.world import Scenario

# What a family's warning asks the ego to do (read by warning-aware policies).
RESPONSE_LANE_OBSTACLE = "lane_obstacle"  # a stopped obstacle in the ego lane at the position
RESPONSE_CUT_IN = "cut_in"  # a vehicle entering the ego lane at the position
RESPONSE_YIELD_TURN = "yield_turn"  # yield before the turn
RESPONSES = (RESPONSE_LANE_OBSTACLE, RESPONSE_CUT_IN, RESPONSE_YIELD_TURN)

Sampler = Callable[[np.random.Generator, str], dict]
Builder = Callable[[dict], tuple[Scenario, Scenario, dict]]

#: A family's record: :class:`~lantern_jax.scenarios.family_registry.FamilyEntry` (the one record
#: type of the family registry; the name is kept for code written against this module).
Family = FamilyEntry


def _junction_sampler(code: str) -> Sampler:
    return functools.partial(junction.sample_junction, code)


#: Stress-testing search spaces (knob -> (lo, hi), units of :mod:`lantern_jax.scenarios.knobs`).
#: Each range contains the paper's nominal value (the frozen suite's own value) and stays
#: physically plausible: pedestrian speeds from a slow walk to a run (the paper: 3 m/s;
#: Bench2Drive's walker: 2 m/s), cut-in speeds from the paper's 6.5 m/s floor to 85 % of the
#: fastest reference speed, lane changes of 1.2-3 s (paper 2 s, Bench2Drive's static cut-in 3 s),
#: the paper's 12-20 km/h lead van and 7-9 / 8-12 m/s junction actors, triggers up to 1.5 s after
#: the event, and a junction actor starting up to 8 m further along its path (closer to the
#: conflict than the paper's spawn offset).
KNOB_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "PE": {"hazard_speed": (1.5, 4.5), "hazard_delay": (0.0, 1.5)},
    "VC": {"hazard_speed": (6.5, 9.5), "hazard_delay": (0.0, 1.0),
           "hazard_manoeuvre": (1.2, 3.0)},
    "OR": {"scene_speed": (12.0 / 3.6, 20.0 / 3.6)},
    "LWW": {"hazard_speed": (7.0, 9.0), "hazard_delay": (0.0, 1.5), "hazard_start": (0.0, 8.0)},
    "RWW": {"hazard_speed": (7.0, 9.0), "hazard_delay": (0.0, 1.5), "hazard_start": (0.0, 8.0)},
    "RTY": {"hazard_speed": (8.0, 12.0), "hazard_delay": (0.0, 1.5), "hazard_start": (0.0, 8.0)},
}  # fmt: skip

#: The premise rule of each of the six (:mod:`lantern_jax.scenarios.premise`): the hazard hidden
#: at the warning point and from the whole approach where nothing that could hide it moves
#: before the event (PE, LWW, RWW), at the warning point for Obstacle Reveal (the lead van
#: moves), none for Vehicle Cut-In (its vehicle is meant to be visible; the warning adds the
#: intent) and Right-Turn Yield (its cross traffic is often visible, as the paper says).
PREMISES = {
    "PE": PREMISE_WHOLE_APPROACH,
    "VC": PREMISE_NONE,
    "OR": PREMISE_AT_WARNING,
    "LWW": PREMISE_WHOLE_APPROACH,
    "RWW": PREMISE_WHOLE_APPROACH,
    "RTY": PREMISE_NONE,
}
#: The clearance normaliser of each of the six (paper): 2 m for the pedestrian and the revealed
#: obstacle, 3 m for the vehicle interactions.
D_SAFE = {
    "PE": D_SAFE_SMALL_M,
    "VC": D_SAFE_LARGE_M,
    "OR": D_SAFE_SMALL_M,
    "LWW": D_SAFE_LARGE_M,
    "RWW": D_SAFE_LARGE_M,
    "RTY": D_SAFE_LARGE_M,
}
_BEHAVIOUR = {
    "PE": (straight.sample_pe, straight.check_pe, straight.build_pe, RESPONSE_LANE_OBSTACLE),
    "VC": (straight.sample_vc, straight.check_vc, straight.build_vc, RESPONSE_CUT_IN),
    "OR": (straight.sample_or, straight.check_or, straight.build_or, RESPONSE_LANE_OBSTACLE),
    **{code: (_junction_sampler(code), junction.check_junction, junction.build_junction,
              RESPONSE_YIELD_TURN) for code in ("LWW", "RWW", "RTY")},
}  # fmt: skip

#: The six built-in families' entries, registered below exactly as a registered family's
#: entry is (:meth:`FamilyRegistry.register`).
BUILTIN_FAMILIES: tuple[FamilyEntry, ...] = tuple(
    FamilyEntry(
        code=code,
        name=FAMILY_NAMES[i],
        ranges=PARAM_RANGES[code],
        knobs=KNOB_RANGES[code],
        premise=PREMISES[code],
        d_safe=D_SAFE[code],
        sample=_BEHAVIOUR[code][0],
        check=_BEHAVIOUR[code][1],
        build=_BEHAVIOUR[code][2],
        response=_BEHAVIOUR[code][3],
    )  # fmt: skip
    for i, code in enumerate(FAMILIES)
)
for _entry in BUILTIN_FAMILIES:
    FAMILY_REGISTRY.register(_entry)


def family(code_or_index: int | str) -> Family:
    """The entry of a family given by abbreviation (``"PE"``) or index.

    Raises:
        ValueError: naming the valid families.
    """
    if isinstance(code_or_index, str):
        return FAMILY_REGISTRY.entry(code_or_index)
    return FAMILY_REGISTRY.entry(family_codes.code(code_or_index))


def sample_params(family_: int | str, rng: np.random.Generator, weather: str = "clear_day") -> dict:
    """Sample a valid parameter dict of one family.

    Args:
        family_: index or abbreviation (``"PE"``, ...).
        rng: NumPy generator; the same generator state gives the same dict.
        weather: one of ``constants.WEATHERS``.

    Returns:
        flat dict (``family``, ``seed``, ``bg_seed``, ``weather``, ``rotation_deg``, ``v_ref``,
        ``route_length`` and the family's fields of :func:`~lantern_jax.scenarios.spec.
        param_ranges`), floats rounded to 1e-3.
    """
    rec = family(family_)
    if weather not in WEATHERS:
        raise ValueError(f"weather: {weather!r} not one of {{{', '.join(WEATHERS)}}}")
    params = rec.sample(rng, weather)
    validate_params(params)
    return params


def check_feasible(params: dict) -> None:
    """Cross-field feasibility of a range-checked parameter dict (``ValueError`` naming a field)."""
    family(params.get("family")).check(params)


KNOBS_FIELD = "knobs"  # optional parameter: knob name -> value, applied after building


def knob_errors(params: dict) -> list[str]:
    """Problems of a parameter dict's optional ``knobs`` field: a JSON object mapping knobs of
    the family's search space (:data:`KNOB_RANGES`) to finite numbers inside their ranges."""
    if KNOBS_FIELD not in params:
        return []
    fam, knobs = params.get("family"), params[KNOBS_FIELD]
    if not isinstance(knobs, dict) or not knobs:
        return [f"{fam}.{KNOBS_FIELD}: expected a non-empty JSON object, got {knobs!r}"]
    errors = []
    space = FAMILY_REGISTRY.entry(fam).knobs if fam in FAMILY_REGISTRY else {}
    for name, value in knobs.items():
        where = f"{fam}.{KNOBS_FIELD}.{name}"
        if name not in space:
            errors.append(f"{where}: not a knob of {fam} (known: {', '.join(space)})")
        elif isinstance(value, bool) or not isinstance(value, int | float):
            errors.append(f"{where}: expected a number, got {value!r}")
        elif not space[name][0] <= float(value) <= space[name][1]:
            lo, hi = space[name]
            errors.append(f"{where}: {float(value)!r} outside [{lo:g}, {hi:g}]")
    return errors


def param_errors(params: Any, feasibility: bool = True) -> list[str]:
    """Every problem of a scenario parameter dict, each naming its field: types and ranges
    (:func:`~lantern_jax.scenarios.spec.range_errors`), the optional knob overrides
    (:func:`knob_errors`) and, when those pass and ``feasibility`` is set, the family's
    cross-field geometry checks."""
    extras = (KNOBS_FIELD, ADVERSARY_FIELD)
    if isinstance(params, dict) and any(k in params for k in extras):
        errors = range_errors({k: v for k, v in params.items() if k not in extras})
        errors += knob_errors(params) + adversary_errors(params) if not errors else []
    else:
        errors = range_errors(params)
    if feasibility and not errors:
        try:
            check_feasible(params)
        except ValueError as e:
            errors.append(str(e))
    if feasibility and not errors and ADVERSARY_FIELD in params:
        a, _, _ = family(params["family"]).build(_scene(params))
        errors += slot_errors(a, params[ADVERSARY_FIELD], params["family"])
    return errors


def _scene(params: dict) -> dict:
    """The parameters that build the scene (without the knob overrides and tracks)."""
    return {k: v for k, v in params.items() if k not in (KNOBS_FIELD, ADVERSARY_FIELD)}


def validate_params(params: dict, feasibility: bool = True) -> dict:
    """Check a scenario parameter dict; return it unchanged.

    Args:
        params: flat dict with ``family`` and the fields of ``PARAM_RANGES[family]``.
        feasibility: also run the family's cross-field geometry checks (route long enough for
            the recovery, marker ordering, arm layout...).

    Raises:
        ValueError: naming the field of the first problem of :func:`param_errors`
            (``"PE.route_length: 150.0 outside [68, 135]"``).
    """
    errors = param_errors(params, feasibility)
    if errors:
        raise ValueError(errors[0])
    return params


def build_pair(params: dict, validate: bool = True) -> tuple[Scenario, Scenario, dict]:
    """Build the Route A and Route B scenarios of one pair.

    Args:
        params: a parameter dict (as from :func:`sample_params`).
        validate: check it first (:func:`validate_params`); False only for a dict just
            validated by the caller.

    Returns:
        ``(scenario_a, scenario_b, meta)``: two :class:`~lantern_jax.types.world.Scenario` pytrees
        with identical shapes (capacities of :mod:`lantern_jax.scenarios.road`) and a JSON-friendly
        dict with the family, the content hash, the markers, the conflict point (world frame),
        the lane names, the number of background vehicles and family-specific canonical-frame
        details.

    Raises:
        ValueError: naming the offending field for invalid or infeasible parameters.
    """
    if validate:
        validate_params(params)
    a, b, meta = family(params["family"]).build(_scene(params))
    if KNOBS_FIELD in params:
        values = {k: float(v) for k, v in params[KNOBS_FIELD].items()}
        a, b = apply_knobs(a, b, values)
        meta["knobs"] = values
    if ADVERSARY_FIELD in params:
        a, b = apply_adversary(a, b, params[ADVERSARY_FIELD])
        meta["adversary_slots"] = [int(t["slot"]) for t in params[ADVERSARY_FIELD]["tracks"]]
    if KNOBS_FIELD in params or ADVERSARY_FIELD in params:
        meta["content_hash"] = content_hash(params)
        meta["params"] = dict(params)
    return a, b, meta
