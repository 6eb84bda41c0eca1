"""The six LANTERN scenario families as matched Route A / Route B worlds.

Usage::

    rng = np.random.default_rng(0)
    params = sample_params("PE", rng, "wet_day")      # flat, JSON-friendly dict
    world_a, world_b, meta = build_pair(params)        # World pytrees at t = 0

A frozen suite stores only the parameter dicts (and their
:func:`~lantern_jax.scenarios.spec.content_hash`); building is deterministic.

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
  otherwise, ``template_id = text_id = family index``, ``timeout_s = 20 + route_length / 3``,
  ablation fields off, ``noise_seed`` from ``params["seed"]``.

Family geometry is documented in :mod:`~lantern_jax.scenarios.families_straight` (PE, VC, OR) and
:mod:`~lantern_jax.scenarios.families_junction` (LWW, RWW, RTY).
"""

from __future__ import annotations

import numpy as np

from lantern_jax.constants import FAMILIES, WEATHERS
from lantern_jax.scenarios import families_junction as fj
from lantern_jax.scenarios import families_straight as fs
from lantern_jax.scenarios.spec import family_of, validate_params
from lantern_jax.world import World

_SAMPLERS = {
    "PE": fs.sample_pe,
    "VC": fs.sample_vc,
    "OR": fs.sample_or,
    "LWW": lambda rng, w: fj.sample_junction("LWW", rng, w),
    "RWW": lambda rng, w: fj.sample_junction("RWW", rng, w),
    "RTY": lambda rng, w: fj.sample_junction("RTY", rng, w),
}
_CHECKS = {
    "PE": fs.check_pe,
    "VC": fs.check_vc,
    "OR": fs.check_or,
    "LWW": fj.check_junction,
    "RWW": fj.check_junction,
    "RTY": fj.check_junction,
}
_BUILDERS = {
    "PE": fs.build_pe,
    "VC": fs.build_vc,
    "OR": fs.build_or,
    "LWW": fj.build_junction,
    "RWW": fj.build_junction,
    "RTY": fj.build_junction,
}


def family_name(family: int | str) -> str:
    """Family abbreviation from an index or an abbreviation."""
    if isinstance(family, str):
        if family not in FAMILIES:
            raise ValueError(f"family: {family!r} not one of {{{', '.join(FAMILIES)}}}")
        return family
    i = int(family)
    if not 0 <= i < len(FAMILIES):
        raise ValueError(f"family: {i} outside 0..{len(FAMILIES) - 1}")
    return FAMILIES[i]


def sample_params(family: int | str, rng: np.random.Generator, weather: str = "clear_day") -> dict:
    """Sample a valid parameter dict of one family.

    Args:
        family: index or abbreviation (``"PE"``, ...).
        rng: NumPy generator; the same generator state gives the same dict.
        weather: one of ``constants.WEATHERS``.

    Returns:
        flat dict (``family``, ``seed``, ``bg_seed``, ``weather``, ``rotation_deg``, ``v_ref``,
        ``route_length`` and the family's fields of ``spec.PARAM_RANGES``), floats rounded to
        1e-3.
    """
    fam = family_name(family)
    if weather not in WEATHERS:
        raise ValueError(f"weather: {weather!r} not one of {{{', '.join(WEATHERS)}}}")
    params = _SAMPLERS[fam](rng, weather)
    validate_params(params)
    return params


def check_feasible(params: dict) -> None:
    """Cross-field feasibility of a range-checked parameter dict (``ValueError`` naming a field)."""
    _CHECKS[family_of(params)](params)


def build_pair(params: dict) -> tuple[World, World, dict]:
    """Build the Route A and Route B worlds of one scenario pair.

    Args:
        params: a parameter dict (as from :func:`sample_params`); validated first.

    Returns:
        ``(world_a, world_b, meta)``: two :class:`World` pytrees with identical shapes (capacities
        of :mod:`lantern_jax.scenarios.road`) and a JSON-friendly dict with the family, the
        content hash, the markers, the conflict point (world frame), the lane names, the number
        of background vehicles and family-specific canonical-frame details.

    Raises:
        ValueError: naming the offending field for invalid or infeasible parameters.
    """
    validate_params(params)
    return _BUILDERS[params["family"]](params)
