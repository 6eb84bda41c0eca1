"""Shared machinery of the family builders: actor specs, background traffic, World assembly.

Builders work in NumPy in a canonical frame (:mod:`lantern_jax.scenarios.road`) and describe each
actor slot with an :class:`ActorSpec`; :func:`assemble_world` rotates the scene, packs every
piece into the fixed capacities and returns a :class:`~lantern_jax.world.World` whose actor state
at ``t = 0`` is the closed form of :class:`~lantern_jax.world.ActorScript` evaluated at 0.

Actor slot layout (identical for every family, so Route A/B and all scenarios line up):

* slot 0 (``HAZARD_SLOT``): the controlled hazard on Route A; its Route B stand-in (role
  context) or an invalid slot on Route B;
* slot 1 (``SCENE_SLOT``): the family's scene actor kept on both routes (PE parked truck, OR
  lead van), otherwise invalid;
* slots 2-6: background traffic (0-5 IDM vehicles), identical on both routes;
* the rest: padding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import (
    BIG,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    FAMILIES,
    KIND_VEHICLE,
    MOTION_IDM,
    MOTION_SCRIPTED,
    ROLE_BACKGROUND,
    TRIGGER_CLOCK,
    TRIGGER_NEVER,
)
from lantern_jax.scenarios import road as rd
from lantern_jax.scenarios.spec import WEATHER_PROFILES, content_hash
from lantern_jax.world import (
    Actors,
    ActorScript,
    EgoState,
    Lanes,
    ProtocolState,
    Route,
    ScenarioParams,
    TrafficLights,
    World,
)

HAZARD_SLOT = 0
SCENE_SLOT = 1
BACKGROUND_SLOTS = range(2, 7)
MAX_BACKGROUND = len(BACKGROUND_SLOTS)

CAR_EXTENT = (2.3, 1.0)  # m, half length / half width of an ordinary car
BG_SPEED = (7.0, 11.0)  # m/s, desired speed range of background vehicles
BG_MARGIN = 1.0  # m, clearance of a background vehicle's box from any other box at t = 0
BG_SPACING_MARGIN = 3.0  # m, extra clearance between two background vehicles


@dataclass
class ActorSpec:
    """One actor slot in the canonical frame (see :class:`~lantern_jax.world.ActorScript`)."""

    path: np.ndarray  # (n, 2) float64, m, n >= 2
    extent: tuple[float, float]  # m, half length, half width
    kind: int
    role: int
    motion: int = MOTION_SCRIPTED
    s_init: float = 0.0
    v_pre: float = 0.0
    v_post: float = 0.0
    s_hold: float = BIG
    s_end: float | None = None  # None = path length
    trigger: int = TRIGGER_NEVER
    trigger_delay: float = 0.0
    lat_shift: float = 0.0
    lat_duration: float = 1.0
    despawn_at_end: bool = False
    light_index: int = -1
    stop_s: float = BIG

    def initial_state(self) -> tuple[float, float]:
        """``(s, speed)`` at ``t = 0`` from the scripted closed form (IDM: s_init, v_pre)."""
        if self.motion == MOTION_IDM:
            return self.s_init, self.v_pre
        if self.trigger == TRIGGER_CLOCK and self.trigger_delay <= 0.0:
            return self.s_init, self.v_post
        if self.s_init >= self.s_hold:
            return self.s_hold, 0.0
        return self.s_init, self.v_pre


def static_actor(xy, yaw: float, extent, kind: int, role: int) -> ActorSpec:
    """A motionless actor at ``xy`` facing ``yaw`` (2-point, 1-m path; never triggers)."""
    xy = np.asarray(xy, np.float64)
    path = np.stack([xy, xy + np.array([math.cos(yaw), math.sin(yaw)])])
    return ActorSpec(path, tuple(extent), kind, role)


def straight_path(p0, direction, length: float) -> np.ndarray:
    """A straight path from ``p0`` along ``direction`` for ``length`` m (<= PATH_POINTS)."""
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    p0 = np.asarray(p0, np.float64)
    n = min(rd.PATH_POINTS, max(2, int(math.ceil(length / 4.0)) + 1))
    return p0 + np.linspace(0.0, length, n)[:, None] * d


def fit_path(xy: np.ndarray) -> np.ndarray:
    """A polyline reduced to at most ``PATH_POINTS`` points (uniform resampling)."""
    return xy if len(xy) <= rd.PATH_POINTS else rd.resample(xy, rd.PATH_POINTS)


def initial_pose(spec: ActorSpec) -> tuple[np.ndarray, float, float, float]:
    """``(xy, yaw, s, speed)`` of an actor at ``t = 0`` (canonical frame)."""
    s, v = spec.initial_state()
    return rd.point_at(spec.path, s), rd.heading_at(spec.path, s), s, v


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

    lane: rd.LaneSpec
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
    for _ in range(n_target):
        for _attempt in range(30):
            sec = sections[int(rng.integers(len(sections)))]
            s0 = float(rng.uniform(sec.s_lo, sec.s_hi))
            v = round(float(rng.uniform(*BG_SPEED)), 3)
            path = fit_path(sec.lane.center)
            xy = rd.point_at(path, s0)
            box = (xy, rd.heading_at(path, s0), CAR_EXTENT)
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
    return (route_xy[0], rd.heading_at(route_xy, 0.0), (EGO_HALF_LENGTH, EGO_HALF_WIDTH))


def spec_box(spec: ActorSpec | None) -> tuple | None:
    """The box of an actor spec at ``t = 0`` (None for an empty slot)."""
    if spec is None:
        return None
    xy, yaw, _, _ = initial_pose(spec)
    return (xy, yaw, spec.extent)


# ------------------------------------------------------------------------------------------------
# packing
# ------------------------------------------------------------------------------------------------
_SCRIPT_FIELDS = (
    "motion", "s_init", "v_pre", "v_post", "s_hold", "trigger", "trigger_delay", "lat_shift",
    "lat_duration", "despawn_at_end", "light_index", "stop_s",
)  # fmt: skip


def pack_actors(slots: list[ActorSpec | None], rot: np.ndarray) -> tuple[dict, dict]:
    """Pack actor slots into the fields of :class:`Actors` and :class:`ActorScript` (NumPy)."""
    a_n, p_n = rd.MAX_ACTORS, rd.PATH_POINTS
    if len(slots) > a_n:
        raise ValueError(f"Actors.valid: {len(slots)} actors exceed capacity {a_n}")
    f32 = lambda *shape: np.zeros(shape, np.float32)  # noqa: E731
    act = dict(
        xy=f32(a_n, 2), yaw=f32(a_n), speed=f32(a_n), extent=f32(a_n, 2),
        kind=np.zeros(a_n, np.int32), role=np.zeros(a_n, np.int32),
        valid=np.zeros(a_n, bool), active=np.zeros(a_n, bool), s=f32(a_n), lat=f32(a_n),
    )  # fmt: skip
    scr = dict(
        motion=np.zeros(a_n, np.int32), path=f32(a_n, p_n, 2), path_s=f32(a_n, p_n),
        path_valid=np.zeros((a_n, p_n), bool), s_init=f32(a_n), v_pre=f32(a_n), v_post=f32(a_n),
        s_hold=np.full(a_n, BIG, np.float32), s_end=f32(a_n),
        trigger=np.full(a_n, TRIGGER_NEVER, np.int32), trigger_delay=f32(a_n),
        lat_shift=f32(a_n), lat_duration=np.ones(a_n, np.float32),
        despawn_at_end=np.zeros(a_n, bool), light_index=np.full(a_n, -1, np.int32),
        stop_s=np.full(a_n, BIG, np.float32),
    )  # fmt: skip
    scr["path_valid"][:, 0] = True  # padded slots: a single point (validate() needs one)
    for i, sp in enumerate(slots):
        if sp is None:
            continue
        path = np.asarray(sp.path, np.float64)
        if len(path) < 2 or len(path) > p_n:
            raise ValueError(f"ActorScript.path: slot {i} has {len(path)} points (2..{p_n})")
        xy, yaw, s0, v0 = initial_pose(sp)
        n = len(path)
        wp = path @ rot.T
        cs = rd.arc_length(path)
        scr["path"][i, :n], scr["path"][i, n:] = wp, wp[-1]
        scr["path_s"][i, :n], scr["path_s"][i, n:] = cs, cs[-1]
        scr["path_valid"][i, :n] = True
        for k in _SCRIPT_FIELDS:
            scr[k][i] = getattr(sp, k)
        scr["s_end"][i] = cs[-1] if sp.s_end is None else sp.s_end
        act["xy"][i] = rot @ xy
        act["yaw"][i] = math.remainder(yaw + math.atan2(rot[1, 0], rot[0, 0]), 2 * math.pi)
        act["speed"][i], act["s"][i], act["lat"][i] = v0, s0, 0.0
        act["extent"][i] = sp.extent
        act["kind"][i], act["role"][i] = sp.kind, sp.role
        act["valid"][i] = act["active"][i] = True
    return act, scr


_PARAM_DTYPES = {
    "family": jnp.int32, "hazard_index": jnp.int32, "ego_light": jnp.int32,
    "template_id": jnp.int32, "text_id": jnp.int32, "noise_seed": jnp.uint32,
    "is_route_a": jnp.bool_, "warning_enabled": jnp.bool_, "clear_on_ego_stop": jnp.bool_,
    "despawn_on_clear": jnp.bool_, "force_event": jnp.bool_, "late_onset": jnp.bool_,
}  # fmt: skip


def _jnp_tree(d: dict) -> dict:
    return {k: jnp.asarray(v) for k, v in d.items()}


def assemble_world(
    road: rd.RoadMap,
    route_xy: np.ndarray,
    slots: list[ActorSpec | None],
    params: dict,
    rotation_deg: float,
) -> World:
    """Rotate and pack a canonical scene into a :class:`World` at ``t = 0``.

    The ego starts at the route start, on the route, heading along it, at ``params["v_ref"]``
    (runs start in motion), with zero steer and acceleration.

    Args:
        road: the map (canonical frame).
        route_xy: (n, 2) route polyline (canonical frame).
        slots: actor specs per slot (None = empty), at most ``MAX_ACTORS``.
        params: every field of :class:`ScenarioParams` as Python values.
        rotation_deg: rigid rotation applied to the whole scene.
    """
    rot = rd.rotation(rotation_deg)
    route = rd.pack_route(route_xy, rot)
    act, scr = pack_actors(slots, rot)
    ego_yaw = math.remainder(rd.heading_at(route_xy, 0.0) + math.radians(rotation_deg), 2 * math.pi)
    ego = EgoState(
        xy=jnp.asarray(route["xy"][0]),
        yaw=jnp.float32(ego_yaw),
        speed=jnp.float32(params["v_ref"]),
        steer=jnp.float32(0.0),
        accel=jnp.float32(0.0),
    )
    missing = set(ScenarioParams.__dataclass_fields__) - set(params)
    if missing:
        raise ValueError(f"ScenarioParams: missing fields {sorted(missing)}")
    sp = ScenarioParams(
        **{
            k: jnp.asarray(params[k], _PARAM_DTYPES.get(k, jnp.float32))
            for k in ScenarioParams.__dataclass_fields__
        }
    )
    return World(
        t=jnp.float32(0.0),
        tick=jnp.int32(0),
        ego=ego,
        actors=Actors(**_jnp_tree(act)),
        script=ActorScript(**_jnp_tree(scr)),
        lanes=Lanes(**_jnp_tree(rd.pack_lanes(road, rot))),
        route=Route(**_jnp_tree(route)),
        lights=TrafficLights(**_jnp_tree(rd.pack_lights(road.lights, rot))),
        params=sp,
        protocol=ProtocolState.initial(),
    )


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
    d_safe: float,
    v_ref: float,
    friction: float,
    sensing_range: float,
    route_length: float,
    seed: int,
) -> tuple[dict, dict]:
    """ScenarioParams field values for Route A (warning enabled) and Route B.

    Route B differs only in ``is_route_a`` and ``warning_enabled`` (False): the markers are kept
    so that Route B's matched warning-to-event interval is defined.
    """
    s_warn, s_event, s_conflict = markers
    a = dict(
        family=family, is_route_a=True, warning_enabled=True,
        s_warn=s_warn, s_event=s_event, s_conflict=s_conflict, hazard_index=hazard_index,
        clear_s=clear_s, clear_time_limit=clear_time_limit, clear_on_ego_stop=clear_on_ego_stop,
        despawn_on_clear=despawn_on_clear, force_event=force_event, force_delay=2.0,
        ego_light=ego_light, ego_stop_s=ego_stop_s, d_safe=d_safe, v_ref=v_ref,
        friction=friction, sensing_range=sensing_range, template_id=family, text_id=family,
        timeout_s=20.0 + route_length / 3.0, late_onset=False, warn_hold_extra=0.0,
        pos_noise_sigma=0.0, noise_seed=np.uint32(int(seed) & 0xFFFFFFFF),
    )  # fmt: skip
    return a, replace_dict(a, is_route_a=False, warning_enabled=False)


def replace_dict(d: dict, **kw) -> dict:
    """A copy of ``d`` with ``kw`` applied."""
    out = dict(d)
    out.update(kw)
    return out


def with_changes(spec: ActorSpec, **kw) -> ActorSpec:
    """A copy of an actor spec with fields replaced."""
    return replace(spec, **kw)


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
    road: rd.RoadMap,
    route: rd.RouteSpec,
    slots_a: dict[int, ActorSpec],
    slots_b: dict[int, ActorSpec],
    sections: list[LaneSection],
    markers: tuple[float, float, float],
    rules: dict,
    extra: dict,
    exclusion: list[tuple[np.ndarray, float]] = (),
) -> tuple[World, World, dict]:
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
            despawn_on_clear, force_event, d_safe``.
        extra: family-specific metadata (canonical frame; ``conflict_xy`` required).

    Returns:
        ``(world_a, world_b, meta)``.
    """
    weather = WEATHER_PROFILES[p["weather"]]
    occupied = [ego_box(route.xy)]
    occupied += [spec_box(s) for s in list(slots_a.values()) + list(slots_b.values())]
    bg = place_background(p["bg_seed"], sections, occupied, exclusion)
    common = dict(zip(BACKGROUND_SLOTS[: len(bg)], bg, strict=True))

    def slot_list(d: dict[int, ActorSpec]) -> list[ActorSpec | None]:
        out: list[ActorSpec | None] = [None] * rd.MAX_ACTORS
        for k, v in {**d, **common}.items():
            out[k] = v
        return out

    signalized = bool(road.lights)
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
    world_a = assemble_world(road, route.xy, slot_list(slots_a), fields_a, rot)
    world_b = assemble_world(road, route.xy, slot_list(slots_b), fields_b, rot)
    r = rd.rotation(rot)
    s_warn, s_event, s_conflict = markers
    meta = dict(
        family=FAMILIES[family],
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
        num_background=len(bg),
        signalized=signalized,
        ego_stop_s=route.stop_s if signalized else BIG,
        lanes=road.names,
        route_lanes=list(route.lanes),
        text_id=family,
        canonical=extra,
    )
    return world_a, world_b, meta
