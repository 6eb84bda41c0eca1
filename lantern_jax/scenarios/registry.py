"""The public way to add a scenario family from user code, without editing the package.

A family is a :class:`FamilyRecord`: its code and name, its parameter ranges, a sampler, a
builder that lays out one pair's scene (road, route, occluders, the hazard and its script, the
scene's other actors, the markers and the clearance rule), its warning texts and its premise
rule.  :func:`register_family` makes it known everywhere the six built-in families are: the
parameter validation and suite files (:func:`lantern_jax.scenarios.suite.load_suite`), pair
building (:func:`lantern_jax.scenarios.families.build_pair`), static validation with the premise
rule (:func:`lantern_jax.scenarios.suite.static_check`), suite generation with the expert's
validation and the near-duplicate rule
(``lantern_jax.apps.suite_generation.generate_suite(families=...)``), evaluation and its tables (a
column per registered family the results hold, after the six), and the dataset recorder
(``lantern_jax.apps.dataset.generation.generate_dataset(families=...)``). On the command line,
``lantern-jax --families FILE.py ...`` imports a file (or module) that registers families before
the command runs. ``docs/families.md`` walks through a whole family;
:mod:`lantern_jax.scenarios.unseen` (the paper's three unseen hazards) is written with nothing
but this module.

Everything a builder needs is importable from here: the actor, occluder and lane-section
records, the straight-road and junction builders, the constants of actor kinds, roles, triggers
and occluder kinds, the range types, and the samplers' helpers.  Builders work in NumPy in a
canonical frame; the scene is rotated by the pair's ``rotation_deg`` afterwards.

Conventions every registered family keeps (they are those of the six):

* the hazard is actor slot 0 on Route A (role hazard); Route B is the same scene without the
  hazard behaviour (``hazard_b``: nothing, or a stand-in that never triggers);
* the markers are route arcs ``(s_warn, s_event, s_conflict)`` with
  ``s_warn < s_event < s_conflict`` and at least ``MIN_RECOVERY_M`` (29 m) of route after the
  conflict point;
* static scenery (parked vehicles, buildings) is part of the map (:class:`OccluderSpec`) and may
  not intrude on the route corridor;
* the warning is delivered from the warning point (route A, warning condition), its position is
  the hazard's, grounded in the ego frame every tick.

Registering is idempotent: registering the same record again (the same file imported twice)
returns the family already registered; a different record under a taken code is refused.
Registered families are never part of the built-in suite ``lantern-v3`` or of the default
training dataset, whose families stay the six.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import (
    BIG,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    KIND_PEDESTRIAN,
    KIND_STATIC,
    KIND_VEHICLE,
    MOTION_IDM,
    MOTION_SCRIPTED,
    OCC_BUILDING,
    OCC_PARKED_VEHICLE,
    OCC_WALL,
    ROLE_BACKGROUND,
    ROLE_CONTEXT,
    ROLE_HAZARD,
    ROLE_OCCLUDER,
    TRIGGER_CLOCK,
    TRIGGER_EVENT,
    TRIGGER_NEVER,
    WEATHERS,
)
from lantern_jax.scenarios import road_junction as junctions
from lantern_jax.scenarios import spec as _spec
from lantern_jax.scenarios.assemble import ActorSpec
from lantern_jax.scenarios.families import FAMILY_REGISTRY  # the registry, the six registered
from lantern_jax.scenarios.families_common import (
    CAR_EXTENT,
    FLOW_SLOTS,
    HAZARD_SLOT,
    SCENE_SLOT,
    LaneSection,
    choose,
    draw,
    finish_pair,
    uniform,
)
from lantern_jax.scenarios.families_straight import opposing_sections
from lantern_jax.scenarios.family_registry import FamilyEntry, RegistryState
from lantern_jax.scenarios.knobs import KNOBS
from lantern_jax.scenarios.premise import (
    PREMISE_AT_WARNING,
    PREMISE_NONE,
    PREMISE_RULES,
    PREMISE_WHOLE_APPROACH,
)
from lantern_jax.scenarios.road import (
    CORRIDOR_MARGIN,
    PATH_POINTS,
    ROAD_MARGIN,
    VAN_HALF_WIDTH,
    OccluderSpec,
    RoadMap,
    RouteSpec,
    arc_length,
    heading_at,
    occluder_intrusions,
    point_at,
    project,
    segment,
)
from lantern_jax.scenarios.road_straight import (
    Centerline,
    StraightLayout,
    ego_route,
    lane_path,
    straight_road,
)
from lantern_jax.scenarios.spec import (
    COMMON_RANGES,
    MAX_CURVATURE,
    MIN_RECOVERY_M,
    Choice,
    Flag,
    FloatRange,
    IntRange,
)
from lantern_jax.scenarios.warnings import family_texts
from lantern_jax.scoring.thresholds import D_SAFE_LARGE_M, D_SAFE_SMALL_M

__all__ = [
    # the record, the scene a builder returns, registration
    "FamilyRecord", "Scene", "Clearance", "register_family", "registered_families", "snapshot",
    "restore",
    # building blocks
    "ActorSpec", "OccluderSpec", "LaneSection", "RoadMap", "RouteSpec", "Centerline",
    "StraightLayout", "straight_road", "ego_route", "lane_path", "opposing_sections",
    "junctions",
    "arc_length", "heading_at", "point_at", "project", "segment",
    # samplers
    "draw", "choose", "uniform",
    # ranges
    "FloatRange", "IntRange", "Choice", "Flag", "COMMON_RANGES",
    # constants
    "KIND_VEHICLE", "KIND_PEDESTRIAN", "KIND_STATIC", "ROLE_HAZARD", "ROLE_OCCLUDER",
    "ROLE_CONTEXT", "ROLE_BACKGROUND", "TRIGGER_CLOCK", "TRIGGER_EVENT", "TRIGGER_NEVER",
    "MOTION_SCRIPTED", "MOTION_IDM", "OCC_BUILDING", "OCC_WALL", "OCC_PARKED_VEHICLE",
    "CAR_EXTENT", "EGO_HALF_LENGTH", "EGO_HALF_WIDTH", "CORRIDOR_MARGIN", "PATH_POINTS",
    "ROAD_MARGIN", "VAN_HALF_WIDTH", "MAX_CURVATURE", "MIN_RECOVERY_M", "D_SAFE_SMALL_M",
    "D_SAFE_LARGE_M", "BIG", "WEATHERS",
    "PREMISE_NONE", "PREMISE_AT_WARNING", "PREMISE_WHOLE_APPROACH",
]  # fmt: skip

#: Fields every family's parameter dict must have besides :data:`COMMON_RANGES`.
REQUIRED_FIELDS = ("v_ref", "route_length")
#: Scene actors (besides the hazard) a pair may hold: the slots kept for scenario actors.
SCENE_ACTOR_SLOTS = (SCENE_SLOT, *FLOW_SLOTS)


@dataclass(frozen=True)
class Clearance:
    """When the hazard's interaction is over (the protocol's clearance), and what happens then.

    Attributes:
        path_arc: m, the hazard has cleared once it is this far along its path (``BIG``: no
            geometric clearance).
        time_limit: s after the event after which the interaction counts as cleared anyway
            (a safety limit; ``BIG``: none).
        on_ego_stop: clearance once the ego has held still for 1 s after the camera saw the
            hazard (the Obstacle Reveal rule).
        despawn: remove the hazard at clearance.
    """

    path_arc: float = BIG
    time_limit: float = BIG
    on_ego_stop: bool = False
    despawn: bool = True


@dataclass
class Scene:
    """One pair's scene as a family's builder lays it out (canonical frame, NumPy).

    Attributes:
        road_map: lanes, lights and static occluders (:func:`straight_road`,
            ``junctions.junction``; set ``road_map.occluders``).
        route: the ego route (:func:`ego_route`, ``junctions.turn_route``,
            ``junctions.through_route``).
        hazard: the hazard actor on Route A (slot 0; role hazard, usually ``TRIGGER_EVENT``).
        markers: ``(s_warn, s_event, s_conflict)``, m, route arcs.
        clearance: the clearance rule (:class:`Clearance`).
        conflict_xy: (2,) m, canonical frame, where the hazard meets the ego route.
        hazard_b: the hazard slot on Route B (None: empty; else a stand-in that never triggers,
            e.g. the same parked car).
        scene_actors: actors present on both routes (up to four, e.g. a lead vehicle).
        traffic: where background traffic may start (lane sections that cannot meet the ego
            route or the scenario actors); empty = no background traffic.
        exclusion: ``(centre, radius)`` discs where no background vehicle may start.
        premise_times: s, times before the event at which the premise rule places the actors
            (one, 0.0, where nothing moves before the event).
        anti_deadlock: the event is forced 2 s after the warning point when the ego has not
            reached the event point (the protocol's anti-deadlock rule).
        d_safe: m, this scene's clearance normaliser where it differs from the record's
            (None: the record's :attr:`FamilyRecord.d_safe`, the family's one value).
        details: JSON-friendly extras for the pair's ``meta["canonical"]``.
    """

    road_map: RoadMap
    route: RouteSpec
    hazard: ActorSpec
    markers: tuple[float, float, float]
    clearance: Clearance
    conflict_xy: Sequence[float]
    hazard_b: ActorSpec | None = None
    scene_actors: Sequence[ActorSpec] = ()
    traffic: Sequence[LaneSection] = ()
    exclusion: Sequence[tuple[np.ndarray, float]] = ()
    premise_times: Sequence[float] = (0.0,)
    anti_deadlock: bool = True
    d_safe: float | None = None
    details: dict = field(default_factory=dict)


@dataclass(frozen=True)
class FamilyRecord:
    """Everything the benchmark needs to know about a family written outside the package.

    Attributes:
        code: 1-8 upper-case letters or digits (``"CYC"``); names the family in tables and suite
            files.
        name: the long name (``"Occluded Cyclist Crossing"``).
        ranges: the family's parameter ranges, field -> :class:`FloatRange`, :class:`IntRange`,
            :class:`Choice` or :class:`Flag`; must hold ``v_ref`` (m/s) and ``route_length``
            (m); the common fields (seeds, weather, rotation, :data:`COMMON_RANGES`) are added.
            This is the one home of the ranges: validation, sampling helpers and the docs read
            them from the record.
        sample: ``(rng, common) -> fields``: draws the family's own fields (``common`` holds the
            family, seeds, weather and rotation, drawn first); use :func:`draw` and
            :func:`choose` so values stay inside ``ranges``.
        build: ``params -> Scene``: lays out one pair (deterministic in ``params``).
        warning: the exact warning, with ``<FRONT_CAR_POS>`` where the grounded hazard position
            goes (the ego-frame ``(x, y)`` of the hazard, one decimal).
        paraphrases: ambiguity tier (``"low"``, ``"medium"``, ``"high"``) -> held-out
            paraphrases; low and medium state the position, high does not.
        premise: the premise rule, one of ``PREMISE_WHOLE_APPROACH`` (the hazard hidden from
            the front camera at the warning point and from every route point before it: scenes
            where nothing that could hide it moves before the event), ``PREMISE_AT_WARNING``
            (hidden at the warning point at every premise time) or ``PREMISE_NONE``.
        check: ``params -> None``: cross-field feasibility, raising ``ValueError`` that names a
            field as ``"CODE.field: ..."`` (occluders intruding on the route corridor and the
            recovery stretch are checked for every family).
        knobs: stress-testing search space, knob -> (lo, hi) (:mod:`lantern_jax.scenarios.knobs`).
        description: one paragraph for listings.
        d_safe: m, the clearance score's normaliser of the family's scenes
            (``D_SAFE_SMALL_M`` = 2 m as PE and OR, ``D_SAFE_LARGE_M`` = 3 m for vehicles).
    """

    code: str
    name: str
    ranges: Mapping[str, Any]
    sample: Callable[[np.random.Generator, dict], dict]
    build: Callable[[dict], Scene]
    warning: str
    paraphrases: Mapping[str, Sequence[str]]
    premise: str = PREMISE_WHOLE_APPROACH
    check: Callable[[dict], None] | None = None
    knobs: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    description: str = ""
    d_safe: float = D_SAFE_LARGE_M


def _identity(record: FamilyRecord) -> tuple:
    """What makes two records the same family: their data, and their functions by source file
    and qualified name (a file imported twice under two module names is the same family)."""

    def fn(f: Callable | None) -> tuple | None:
        if f is None:
            return None
        code = getattr(f, "__code__", None)
        return (getattr(code, "co_filename", None), getattr(f, "__qualname__", repr(f)))

    return (
        record.code, record.name, tuple(record.ranges.items()), fn(record.sample),
        fn(record.build), record.warning,
        tuple((t, tuple(v)) for t, v in record.paraphrases.items()), record.premise,
        fn(record.check), tuple(record.knobs.items()), record.d_safe,
    )  # fmt: skip


def registered_families() -> dict[str, FamilyRecord]:
    """The records registered from user code so far, by code (registration order)."""
    return {e.code: e.record for e in FAMILY_REGISTRY.user_entries()}


def _range_problem(rng: Any) -> str | None:
    """What makes a parameter range unusable (an empty, inverted or non-finite interval, an
    empty choice), or None."""
    if isinstance(rng, FloatRange | IntRange):
        lo, hi = rng.lo, rng.hi
        if not (isinstance(lo, int | float) and isinstance(hi, int | float)):
            return f"bounds must be numbers, got ({lo!r}, {hi!r})"
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return f"bounds must be finite, got ({lo}, {hi})"
        if lo > hi:
            return f"empty interval: lo {lo} > hi {hi}"
    if isinstance(rng, Choice) and not rng.options:
        return "a choice of no option"
    return None


def _check_record(record: FamilyRecord) -> None:
    """Refuse a record that cannot be registered (ValueError naming the field)."""
    if not isinstance(record, FamilyRecord):
        raise TypeError(f"register_family: expected a FamilyRecord, got {type(record).__name__}")
    where = f"family {record.code!r}"
    for name in ("sample", "build"):
        if not callable(getattr(record, name)):
            raise ValueError(f"{where}: {name} must be callable")
    if record.check is not None and not callable(record.check):
        raise ValueError(f"{where}: check must be callable or None")
    clash = sorted(set(record.ranges) & (set(COMMON_RANGES) | {"family", "knobs"}))
    if clash:
        raise ValueError(f"{where}: ranges: {clash} are common fields, set for every family")
    for key in REQUIRED_FIELDS:
        if not isinstance(record.ranges.get(key), FloatRange):
            raise ValueError(f"{where}: ranges: {key!r} must be a FloatRange")
    for key, rng in record.ranges.items():
        if not callable(getattr(rng, "check", None)):
            raise ValueError(f"{where}: ranges[{key!r}] is not a range type")
        problem = _range_problem(rng)
        if problem:
            raise ValueError(f"{where}: ranges[{key!r}]: {problem}")
    if record.premise not in PREMISE_RULES:
        raise ValueError(f"{where}: premise {record.premise!r} not one of {PREMISE_RULES}")
    if not record.paraphrases:
        raise ValueError(f"{where}: paraphrases: give at least one held-out paraphrase")
    d_safe = record.d_safe
    if (
        isinstance(d_safe, bool)
        or not isinstance(d_safe, int | float)
        or not (math.isfinite(d_safe) and d_safe > 0)
    ):
        raise ValueError(f"{where}: d_safe must be a positive number of metres, got {d_safe!r}")
    for knob, (lo, hi) in record.knobs.items():
        if knob not in KNOBS:
            raise ValueError(f"{where}: knobs: {knob!r} not one of {sorted(KNOBS)}")
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ValueError(f"{where}: knobs[{knob!r}]: need finite lo <= hi, got ({lo}, {hi})")


def register_family(record: FamilyRecord) -> FamilyEntry:
    """Register a family written outside the package (see the module docstring).

    Args:
        record: the family's :class:`FamilyRecord`.

    Returns:
        The family registry's entry of the family (its ``index`` follows the six).

    Raises:
        ValueError: for a record that breaks a rule (a built-in or malformed code, missing
            ranges, a warning text that breaks the text bank's rules, an unknown premise rule),
            or a code already registered with another record.
    """
    _check_record(record)
    family_codes.check_new(record.code, record.name)  # not a built-in code, a well-formed one
    if record.code in FAMILY_REGISTRY:
        have = FAMILY_REGISTRY.entry(record.code)
        if _identity(have.record) != _identity(record):
            raise ValueError(f"family {record.code!r}: already registered with another record")
        return have
    texts = family_texts(record.warning, record.paraphrases)  # checked before anything is held
    entry = FamilyEntry(
        code=record.code,
        name=record.name,
        ranges={**COMMON_RANGES, **record.ranges},
        knobs=dict(record.knobs),
        premise=record.premise,
        d_safe=float(record.d_safe),
        sample=lambda rng, weather: _sample(record, rng, weather),
        check=lambda params: _check(record, params),
        build=lambda params: _build(record, params),
        response="",  # the built-in policies' keyword rule knows the six only
        texts=texts,
        record=record,
    )
    return FAMILY_REGISTRY.register(entry)


#: What :func:`snapshot` returns (the family registry's state).
Registrations = RegistryState


def snapshot() -> RegistryState:
    """The registrations as they are now, for :func:`restore` (tests and notebooks that define
    families for a while)."""
    return FAMILY_REGISTRY.snapshot()


def restore(state: RegistryState) -> None:
    """Forget every family registered since ``state`` was taken (:func:`snapshot`), their texts
    included.  Scenarios built or programs compiled in between keep what they were built with;
    suites of the forgotten families no longer load.
    """
    FAMILY_REGISTRY.restore(state)


# ------------------------------------------------------------------------------------------------
# what the package calls for a registered family
# ------------------------------------------------------------------------------------------------
def _sample(record: FamilyRecord, rng: np.random.Generator, weather: str) -> dict:
    """The common fields (as every family draws them first), then the family's own."""
    common = dict(
        family=record.code,
        seed=int(rng.integers(0, _spec.SEED_MAX)),
        bg_seed=int(rng.integers(0, _spec.SEED_MAX)),
        weather=weather,
        rotation_deg=draw(rng, record.code, "rotation_deg"),
    )
    own = record.sample(rng, dict(common))
    clash = sorted(set(own) & set(common))
    if clash:
        raise ValueError(f"{record.code}: the sampler returned common fields {clash}")
    return {**common, **own}


def _scene(record: FamilyRecord, params: dict) -> Scene:
    scene = record.build(params)
    if not isinstance(scene, Scene):
        raise TypeError(f"{record.code}: build must return a Scene, got {type(scene).__name__}")
    if len(scene.scene_actors) > len(SCENE_ACTOR_SLOTS):
        raise ValueError(f"{record.code}: at most {len(SCENE_ACTOR_SLOTS)} scene actors, got "
                         f"{len(scene.scene_actors)}")  # fmt: skip
    return scene


def _check(record: FamilyRecord, params: dict) -> None:
    """The record's own check, then the rules every family keeps: markers in order, the
    recovery stretch after the conflict point, occluders clear of the route corridor."""
    if record.check is not None:
        record.check(params)
    scene = _scene(record, params)
    s_warn, s_event, s_conflict = (float(m) for m in scene.markers)
    if not 0.0 <= s_warn < s_event < s_conflict:
        raise ValueError(f"{record.code}.route_length: markers out of order "
                         f"({s_warn:.2f}, {s_event:.2f}, {s_conflict:.2f})")  # fmt: skip
    if scene.route.length - s_conflict < MIN_RECOVERY_M:
        raise ValueError(f"{record.code}.route_length: {scene.route.length:.2f} m leaves "
                         f"{scene.route.length - s_conflict:.2f} m after the conflict point, "
                         f"needs >= {MIN_RECOVERY_M:g}")  # fmt: skip
    for msg in occluder_intrusions(scene.road_map, scene.route.xy):
        raise ValueError(f"{record.code}.occluders: {msg}")


def _build(record: FamilyRecord, params: dict):
    """Route A, Route B and the meta of one pair, packed as the six are
    (:func:`~lantern_jax.scenarios.families_common.finish_pair`)."""
    scene = _scene(record, params)
    shared = dict(zip(SCENE_ACTOR_SLOTS, scene.scene_actors, strict=False))
    slots_a = {HAZARD_SLOT: scene.hazard, **shared}
    slots_b = dict(shared) if scene.hazard_b is None else {HAZARD_SLOT: scene.hazard_b, **shared}
    c = scene.clearance
    rules = dict(
        clear_s=float(c.path_arc), clear_time_limit=float(c.time_limit),
        clear_on_ego_stop=bool(c.on_ego_stop), despawn_on_clear=bool(c.despawn),
        force_event=bool(scene.anti_deadlock),
        d_safe=float(record.d_safe if scene.d_safe is None else scene.d_safe),
    )  # fmt: skip
    extra = dict(scene.details)
    extra.update(
        conflict_xy=[float(v) for v in scene.conflict_xy],
        premise_times=[float(t) for t in scene.premise_times],
    )
    markers = tuple(float(m) for m in scene.markers)
    return finish_pair(
        params, family_codes.index(record.code), scene.road_map, scene.route, slots_a, slots_b,
        list(scene.traffic), markers, rules, extra, exclusion=list(scene.exclusion),
    )  # fmt: skip
