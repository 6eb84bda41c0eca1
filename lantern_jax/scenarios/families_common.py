"""Shared machinery of the family builders: actor helpers, background traffic, pair assembly.

Builders work in NumPy in a canonical frame (:mod:`lantern_jax.scenarios.road`) and describe each
actor slot with an :class:`~lantern_jax.scenarios.assemble.ActorSpec`; :func:`finish_pair` adds
the background traffic and packs Route A and Route B with
:func:`~lantern_jax.scenarios.assemble.assemble_scenario`.

Actor slot layout (identical for every family, so Route A/B and all scenarios line up):

* slot 0 (``HAZARD_SLOT``): the controlled hazard on Route A; its Route B stand-in (role
  context) or an invalid slot on Route B;
* slot 1 (``SCENE_SLOT``): the family's scene actor kept on both routes (the OR lead van),
  otherwise invalid;
* slots 2-6: background traffic (0-5 IDM vehicles), identical on both routes;
* slots 7-9 (``FLOW_SLOTS``): the Right-Turn Yield flow behind its first (evaluated) vehicle;
* the rest: padding.

Static scenery — parked trucks and vans, corner buildings, walls — is not an actor: it is part
of the map (:class:`~lantern_jax.scenarios.road.OccluderSpec`, packed into
:class:`~lantern_jax.types.world.Occluders`), identical on Route A and Route B.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import (
    BACKGROUND_SLOTS,
    BIG,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    KIND_VEHICLE,
    MAX_BACKGROUND,
    MOTION_IDM,
    ROLE_BACKGROUND,
)
from lantern_jax.scenarios import road
from lantern_jax.scenarios.assemble import ActorSpec, assemble_scenario, initial_pose
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY
from lantern_jax.scenarios.spec import (
    SEED_MAX,
    WEATHER_PROFILES,
    content_hash,
    param_ranges,
    route_timeout_s,
)
from lantern_jax.scenarios.warnings import canonical_text_id
from lantern_jax.types.world import Scenario

HAZARD_SLOT = 0
SCENE_SLOT = 1
FLOW_SLOTS = range(7, 10)

#: The parameter that places each occluder (by name prefix), for error messages.
OCCLUDER_FIELDS = (
    ("truck_W", "truck_length"),  # LWW: the truck waiting on the W arm
    ("truck", "truck_width"),  # PE: the parked truck hiding the pedestrian
    ("parked_", "parked_count"),
    ("corner_", "corner_setback"),
)

CAR_EXTENT = (2.3, 1.0)  # m, half length / half width of an ordinary car
BG_SPEED = (7.0, 11.0)  # m/s, desired speed range of background vehicles
BG_MARGIN = 1.0  # m, clearance of a background vehicle's box from any other box at t = 0
BG_SPACING_MARGIN = 3.0  # m, extra clearance between two background vehicles


def static_actor(xy, yaw: float, extent, kind: int, role: int) -> ActorSpec:
    """A motionless actor at ``xy`` facing ``yaw`` (2-point, 1-m path; never triggers)."""
    xy = np.asarray(xy, np.float64)
    path = np.stack([xy, xy + np.array([math.cos(yaw), math.sin(yaw)])])
    return ActorSpec(path, tuple(extent), kind, role)


def fit_path(xy: np.ndarray) -> np.ndarray:
    """A polyline reduced to at most ``PATH_POINTS`` points (uniform resampling)."""
    return xy if len(xy) <= road.PATH_POINTS else road.resample(xy, road.PATH_POINTS)


# ------------------------------------------------------------------------------------------------
# boxes
# ------------------------------------------------------------------------------------------------
def box_corners(xy, yaw: float, extent) -> np.ndarray:
    """(4, 2) corners of an oriented box."""
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = extent
    local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
    return np.asarray(xy, np.float64) + local @ np.array([[c, s], [-s, c]])


def boxes_overlap(a: tuple, b: tuple, margin: float = 0.0) -> bool:
    """Separating-axis test of two boxes ``(xy, yaw, (hl, hw))``, each inflated by ``margin``."""
    ca = box_corners(a[0], a[1], (a[2][0] + margin, a[2][1] + margin))
    cb = box_corners(b[0], b[1], (b[2][0] + margin, b[2][1] + margin))
    for yaw in (a[1], b[1]):
        for ax in (
            np.array([math.cos(yaw), math.sin(yaw)]),
            np.array([-math.sin(yaw), math.cos(yaw)]),
        ):
            pa, pb = ca @ ax, cb @ ax
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


# ------------------------------------------------------------------------------------------------
# background traffic
# ------------------------------------------------------------------------------------------------
@dataclass
class LaneSection:
    """Where background vehicles may start: arc interval ``[s_lo, s_hi]`` of a lane."""

    lane: road.LaneSpec
    s_lo: float
    s_hi: float


def place_background(
    bg_seed: int,
    sections: list[LaneSection],
    occupied: list[tuple],
    exclusion: list[tuple[np.ndarray, float]] = (),
) -> list[ActorSpec]:
    """Deterministic background traffic: 0-5 IDM vehicles on the given lane sections.

    Args:
        bg_seed: background seed; the same seed and scene give the same vehicles.
        sections: admissible start intervals (the family builders pass only lanes that cannot
            conflict with the ego route or the scenario actors).
        occupied: boxes ``(xy, yaw, extent)`` already in the scene at ``t = 0`` (ego and the
            scenario actors of *both* routes); a vehicle keeps ``BG_MARGIN`` from all of them.
        exclusion: ``(centre, radius)`` discs no background vehicle may start in.

    Returns:
        up to ``MAX_BACKGROUND`` actor specs (role background, ``MOTION_IDM``) whose path is their
        lane's centre line; the light fields are set when that lane's stop line lies ahead.
    """
    rng = np.random.default_rng(int(bg_seed))
    n_target = int(rng.integers(0, MAX_BACKGROUND + 1))
    placed: list[ActorSpec] = []
    boxes: list[tuple] = []
    if not sections:
        return placed
    paths = [fit_path(sec.lane.center) for sec in sections]  # once, not per attempt
    for _ in range(n_target):
        for _attempt in range(30):
            k = int(rng.integers(len(sections)))
            sec, path = sections[k], paths[k]
            s0 = float(rng.uniform(sec.s_lo, sec.s_hi))
            v = round(float(rng.uniform(*BG_SPEED)), 3)
            xy = road.point_at(path, s0)
            box = (xy, road.heading_at(path, s0), CAR_EXTENT)
            if any(boxes_overlap(box, o, BG_MARGIN) for o in occupied):
                continue
            if any(boxes_overlap(box, o, BG_SPACING_MARGIN) for o in boxes):
                continue
            if any(np.linalg.norm(xy - c) < r for c, r in exclusion):
                continue
            ahead = sec.lane.light >= 0 and sec.lane.stop_s > s0
            placed.append(
                ActorSpec(
                    path,
                    CAR_EXTENT,
                    KIND_VEHICLE,
                    ROLE_BACKGROUND,
                    motion=MOTION_IDM,
                    s_init=s0,
                    v_pre=v,
                    v_post=v,
                    despawn_at_end=True,
                    light_index=sec.lane.light if ahead else -1,
                    stop_s=sec.lane.stop_s if ahead else BIG,
                )
            )
            boxes.append(box)
            break
    return placed


def ego_box(route_xy: np.ndarray) -> tuple:
    """The ego box ``(xy, yaw, extent)`` at the route start."""
    return (route_xy[0], road.heading_at(route_xy, 0.0), (EGO_HALF_LENGTH, EGO_HALF_WIDTH))


def spec_box(spec: ActorSpec | None) -> tuple | None:
    """The box of an actor spec at ``t = 0`` (None for an empty slot)."""
    if spec is None:
        return None
    xy, yaw, _, _ = initial_pose(spec)
    return (xy, yaw, spec.extent)


def pair_params(
    *,
    family: int,
    markers: tuple[float, float, float],
    hazard_index: int,
    clear_s: float,
    clear_time_limit: float,
    clear_on_ego_stop: bool,
    despawn_on_clear: bool,
    force_event: bool,
    ego_light: int,
    ego_stop_s: float,
    v_ref: float,
    friction: float,
    sensing_range: float,
    route_length: float,
    seed: int,
    d_safe: float | None = None,
) -> tuple[dict, dict]:
    """:class:`~lantern_jax.types.world.ExecutionConfig` field values for Route A (warning enabled)
    and Route B.

    Route B differs only in ``is_route_a`` and ``warning_enabled`` (False): the markers are kept
    so that Route B's matched warning-to-event interval is defined.  The warning text is the
    family's exact warning (:func:`~lantern_jax.scenarios.warnings.canonical_text_id`: the
    family index for the six built-in families); ``d_safe`` (m) is the family's registry entry's
    unless a scene overrides it.
    """
    if d_safe is None:
        d_safe = FAMILY_REGISTRY.entry(family_codes.code(family)).d_safe
    s_warn, s_event, s_conflict = markers
    text_id = canonical_text_id(family)
    a = dict(
        family=family, is_route_a=True, warning_enabled=True,
        s_warn=s_warn, s_event=s_event, s_conflict=s_conflict, hazard_index=hazard_index,
        clear_s=clear_s, clear_time_limit=clear_time_limit, clear_on_ego_stop=clear_on_ego_stop,
        despawn_on_clear=despawn_on_clear, force_event=force_event, force_delay=2.0,
        ego_light=ego_light, ego_stop_s=ego_stop_s, d_safe=d_safe, v_ref=v_ref,
        friction=friction, sensing_range=sensing_range, template_id=family, text_id=text_id,
        timeout_s=route_timeout_s(route_length), late_onset=False, warn_hold_extra=0.0,
        pos_noise_m=0.0, noise_seed=np.uint32(int(seed) & 0xFFFFFFFF),
    )  # fmt: skip
    return a, replace_dict(a, is_route_a=False, warning_enabled=False)


def _pair_meta(
    p: dict,
    family: int,
    road_map: road.RoadMap,
    route: road.RouteSpec,
    slots_a: dict[int, ActorSpec],
    slots_b: dict[int, ActorSpec],
    markers: tuple[float, float, float],
    num_background: int,
    extra: dict,
) -> dict:
    """The JSON-friendly description of a built pair (see :func:`finish_pair`)."""
    r = road.rotation(float(p["rotation_deg"]))
    s_warn, s_event, s_conflict = markers
    signalized = bool(road_map.lights)
    return dict(
        family=family_codes.code(family),
        family_index=family,
        content_hash=content_hash(p),
        params=dict(p),
        route_length=route.length,
        s_warn=s_warn,
        s_event=s_event,
        s_conflict=s_conflict,
        conflict_xy=(r @ np.asarray(extra.pop("conflict_xy"))).tolist(),
        hazard_index=HAZARD_SLOT,
        scenario_slots=[
            k for k in sorted(set(slots_a) | set(slots_b)) if slots_a.get(k) is not slots_b.get(k)
        ],
        num_background=num_background,
        signalized=signalized,
        ego_stop_s=route.stop_s if signalized else BIG,
        lanes=road_map.names,
        route_lanes=list(route.lanes),
        text_id=canonical_text_id(family),
        canonical=extra,
    )


def replace_dict(d: dict, **kw) -> dict:
    """A copy of ``d`` with ``kw`` applied."""
    out = dict(d)
    out.update(kw)
    return out


def with_changes(spec: ActorSpec, **kw) -> ActorSpec:
    """A copy of an actor spec with fields replaced."""
    return replace(spec, **kw)


def draw(
    rng: np.random.Generator,
    family: str,
    key: str,
    at_least: float | None = None,
    at_most: float | None = None,
    nd: int = 3,
) -> float:
    """Sample field ``key`` of a family uniformly within its documented range
    (:func:`~lantern_jax.scenarios.spec.param_ranges`), optionally narrowed to
    ``[at_least, at_most]`` by the family's cross-field rules; rounded to ``nd`` decimals."""
    rng_def = param_ranges(family)[key]
    lo = rng_def.lo if at_least is None else max(rng_def.lo, at_least)
    hi = rng_def.hi if at_most is None else min(rng_def.hi, at_most)
    return uniform(rng, lo, hi, nd)


def check_occluders(family: str, p: dict, scene: tuple) -> None:
    """Refuse occluders that intrude on the route corridor or a driving lane.

    Args:
        family: family code (for the message).
        p: the parameter dict.
        scene: ``(road_map, route, ...)`` as built from ``p``.

    Raises:
        ValueError: naming the parameter that places the first intruding occluder, e.g.
            ``"PE.truck_width: occluder truck overlaps the route corridor (...)"``.
    """
    road_map, route = scene[0], scene[1]
    for msg in road.occluder_intrusions(road_map, route.xy):
        name = msg.split()[1]
        field = next((f for prefix, f in OCCLUDER_FIELDS if name.startswith(prefix)), "occluders")
        raise ValueError(f"{family}.{field}: {msg}")


def choose(rng: np.random.Generator, family: str, key: str, options: tuple | None = None):
    """Pick one of the documented options of field ``key`` (or of ``options``, a subset)."""
    return rng.choice(list(param_ranges(family)[key].options if options is None else options))


def common_fields(rng: np.random.Generator, family: str, weather: str) -> dict:
    """The fields every family samples first: seeds, weather and the scene rotation."""
    return dict(
        family=family,
        seed=int(rng.integers(0, SEED_MAX)),
        bg_seed=int(rng.integers(0, SEED_MAX)),
        weather=weather,
        rotation_deg=draw(rng, family, "rotation_deg"),
    )


def uniform(rng: np.random.Generator, lo: float, hi: float, nd: int = 3) -> float:
    """A uniform sample rounded to ``nd`` decimals that stays inside ``[lo, hi]``."""
    q = 10.0**nd
    lo_q, hi_q = math.ceil(lo * q - 1e-9) / q, math.floor(hi * q + 1e-9) / q
    if hi_q < lo_q:
        raise ValueError(f"uniform: empty interval [{lo}, {hi}]")
    return float(min(hi_q, max(lo_q, round(float(rng.uniform(lo_q, hi_q)), nd))))


def finish_pair(
    p: dict,
    family: int,
    road_map: road.RoadMap,
    route: road.RouteSpec,
    slots_a: dict[int, ActorSpec],
    slots_b: dict[int, ActorSpec],
    sections: list[LaneSection],
    markers: tuple[float, float, float],
    rules: dict,
    extra: dict,
    exclusion: list[tuple[np.ndarray, float]] = (),
) -> tuple[Scenario, Scenario, dict]:
    """Add background traffic, pack Route A and Route B and describe the pair.

    Args:
        p: the (validated) parameter dict.
        family: family index.
        road, route: canonical map and ego route.
        slots_a, slots_b: scenario actors per slot for Route A and Route B.
        sections, exclusion: where background vehicles may start (see
            :func:`place_background`).
        markers: ``(s_warn, s_event, s_conflict)``, m, route arcs.
        rules: clearance fields ``clear_s, clear_time_limit, clear_on_ego_stop,
            despawn_on_clear, force_event`` (and ``d_safe`` where a scene overrides its
            family's).
        extra: family-specific metadata (canonical frame; ``conflict_xy`` required).

    Returns:
        ``(scenario_a, scenario_b, meta)``.
    """
    weather = WEATHER_PROFILES[p["weather"]]
    occupied = [ego_box(route.xy)]
    occupied += [spec_box(s) for s in list(slots_a.values()) + list(slots_b.values())]
    bg = place_background(p["bg_seed"], sections, occupied, exclusion)
    common = dict(zip(BACKGROUND_SLOTS[: len(bg)], bg, strict=True))

    def slot_list(d: dict[int, ActorSpec]) -> list[ActorSpec | None]:
        out: list[ActorSpec | None] = [None] * road.MAX_ACTORS
        for k, v in {**d, **common}.items():
            out[k] = v
        return out

    signalized = bool(road_map.lights)
    fields_a, fields_b = pair_params(
        family=family,
        markers=markers,
        hazard_index=HAZARD_SLOT,
        ego_light=0 if signalized else -1,
        ego_stop_s=route.stop_s if signalized else BIG,
        v_ref=float(p["v_ref"]),
        friction=weather.friction,
        sensing_range=weather.sensing_range,
        route_length=route.length,
        seed=int(p["seed"]),
        **rules,
    )
    rot = float(p["rotation_deg"])
    scenario_a = assemble_scenario(road_map, route.xy, slot_list(slots_a), fields_a, rot)
    scenario_b = assemble_scenario(road_map, route.xy, slot_list(slots_b), fields_b, rot)
    meta = _pair_meta(p, family, road_map, route, slots_a, slots_b, markers, len(bg), extra)
    return scenario_a, scenario_b, meta
