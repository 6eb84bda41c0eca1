"""Hand-built scenes: a small constructor for tests, benchmarks and notebook experiments.

:func:`straight_scene` builds a complete, valid :class:`~lantern_jax.world.World` on a straight
two-lane road from a short list of actor descriptions; everything not given gets a neutral
default (no hazard behaviour, no lights, dry weather).  The frozen suite uses the family
builders in :mod:`lantern_jax.scenarios.families` instead.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import (
    BIG,
    KIND_VEHICLE,
    MOTION_SCRIPTED,
    PE,
    ROLE_BACKGROUND,
    TRIGGER_NEVER,
)
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

CAP_A, CAP_P, CAP_L, CAP_Q, CAP_R, CAP_T = 16, 32, 16, 48, 96, 2


@dataclasses.dataclass
class ActorSpec:
    """One actor of a hand-built scene (world frame, metres, seconds)."""

    path: np.ndarray  # (n, 2) polyline the actor follows (n >= 1)
    extent: tuple[float, float] = (2.3, 1.0)  # half length, half width
    kind: int = KIND_VEHICLE
    role: int = ROLE_BACKGROUND
    motion: int = MOTION_SCRIPTED
    s_init: float = 0.0
    v_pre: float = 0.0
    v_post: float = 0.0
    s_hold: float = BIG
    s_end: float | None = None  # default: path end
    trigger: int = TRIGGER_NEVER
    trigger_delay: float = 0.0
    lat_shift: float = 0.0
    lat_duration: float = 2.0
    despawn_at_end: bool = False
    light_index: int = -1
    stop_s: float = BIG


def _arc(points: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def _pad(points: np.ndarray, cap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = len(points)
    if n > cap:
        raise ValueError(f"polyline has {n} points, capacity is {cap}")
    pts = np.zeros((cap, 2), np.float32)
    pts[:n] = points
    pts[n:] = points[-1]
    s = np.zeros((cap,), np.float32)
    s[:n] = _arc(points) if n > 1 else 0.0
    s[n:] = s[n - 1]
    valid = np.arange(cap) < n
    return pts, s, valid


def resample(points: np.ndarray, step: float) -> np.ndarray:
    """Resample a polyline at (about) ``step`` metres, keeping both ends."""
    points = np.asarray(points, np.float64)
    s = _arc(points)
    n = max(int(np.ceil(s[-1] / step)), 1)
    q = np.linspace(0.0, s[-1], n + 1)
    return np.stack([np.interp(q, s, points[:, 0]), np.interp(q, s, points[:, 1])], -1)


def pack_actors(specs: list[ActorSpec], cap_a: int = CAP_A, cap_p: int = CAP_P):
    """Pack actor specs into padded (Actors, ActorScript) at t = 0."""
    if len(specs) > cap_a:
        raise ValueError(f"{len(specs)} actors exceed the capacity of {cap_a}")
    path = np.zeros((cap_a, cap_p, 2), np.float32)
    path_s = np.zeros((cap_a, cap_p), np.float32)
    path_valid = np.zeros((cap_a, cap_p), bool)
    path_valid[:, 0] = True
    f = {k: np.zeros((cap_a,), np.float32) for k in (
        "s_init", "v_pre", "v_post", "trigger_delay", "lat_shift")}  # fmt: skip
    s_hold = np.full((cap_a,), BIG, np.float32)
    s_end = np.zeros((cap_a,), np.float32)
    stop_s = np.full((cap_a,), BIG, np.float32)
    lat_duration = np.ones((cap_a,), np.float32)
    motion = np.zeros((cap_a,), np.int32)
    trigger = np.full((cap_a,), TRIGGER_NEVER, np.int32)
    light_index = np.full((cap_a,), -1, np.int32)
    despawn = np.zeros((cap_a,), bool)
    xy = np.zeros((cap_a, 2), np.float32)
    yaw = np.zeros((cap_a,), np.float32)
    speed = np.zeros((cap_a,), np.float32)
    extent = np.zeros((cap_a, 2), np.float32)
    kind = np.zeros((cap_a,), np.int32)
    role = np.full((cap_a,), ROLE_BACKGROUND, np.int32)
    valid = np.zeros((cap_a,), bool)
    for i, sp in enumerate(specs):
        pts = np.asarray(sp.path, np.float64).reshape(-1, 2)
        path[i], path_s[i], path_valid[i] = _pad(pts, cap_p)
        n = len(pts)
        for k in f:
            f[k][i] = getattr(sp, k)
        s_hold[i] = sp.s_hold
        s_end[i] = path_s[i, n - 1] if sp.s_end is None else sp.s_end
        stop_s[i] = sp.stop_s
        lat_duration[i] = sp.lat_duration
        motion[i], trigger[i], light_index[i] = sp.motion, sp.trigger, sp.light_index
        despawn[i] = sp.despawn_at_end
        # Pose at t = 0 (s_init along the path, heading of the local segment).
        s0 = min(sp.s_init, sp.s_hold)
        ps = path_s[i, :n]
        if n == 1:
            xy[i], yaw[i] = pts[0], 0.0
        else:
            k = int(np.clip(np.searchsorted(ps, s0, side="right") - 1, 0, n - 2))
            d = pts[k + 1] - pts[k]
            u = (s0 - ps[k]) / max(ps[k + 1] - ps[k], 1e-9)
            xy[i] = pts[k] + u * d
            yaw[i] = np.arctan2(d[1], d[0])
        speed[i] = sp.v_pre if sp.s_init < sp.s_hold else 0.0
        extent[i], kind[i], role[i], valid[i] = sp.extent, sp.kind, sp.role, True
    actors = Actors(
        xy=jnp.asarray(xy),
        yaw=jnp.asarray(yaw),
        speed=jnp.asarray(speed),
        extent=jnp.asarray(extent),
        kind=jnp.asarray(kind),
        role=jnp.asarray(role),
        valid=jnp.asarray(valid),
        active=jnp.asarray(valid),
        s=jnp.asarray(np.minimum(f["s_init"], s_hold)),
        lat=jnp.zeros((cap_a,), jnp.float32),
    )
    script = ActorScript(
        motion=jnp.asarray(motion),
        path=jnp.asarray(path),
        path_s=jnp.asarray(path_s),
        path_valid=jnp.asarray(path_valid),
        s_init=jnp.asarray(f["s_init"]),
        v_pre=jnp.asarray(f["v_pre"]),
        v_post=jnp.asarray(f["v_post"]),
        s_hold=jnp.asarray(s_hold),
        s_end=jnp.asarray(s_end),
        trigger=jnp.asarray(trigger),
        trigger_delay=jnp.asarray(f["trigger_delay"]),
        lat_shift=jnp.asarray(f["lat_shift"]),
        lat_duration=jnp.asarray(lat_duration),
        despawn_at_end=jnp.asarray(despawn),
        light_index=jnp.asarray(light_index),
        stop_s=jnp.asarray(stop_s),
    )
    return actors, script


def pack_lanes(centers: list[np.ndarray], widths: list[float], kinds: list[int] | None = None,
               cap_l: int = CAP_L, cap_q: int = CAP_Q) -> Lanes:  # fmt: skip
    """Pack lane centre lines (travel direction = point order) into padded :class:`Lanes`."""
    if len(centers) > cap_l:
        raise ValueError(f"{len(centers)} lanes exceed the capacity of {cap_l}")
    kinds = kinds or [0] * len(centers)
    c = np.zeros((cap_l, cap_q, 2), np.float32)
    s = np.zeros((cap_l, cap_q), np.float32)
    pv = np.zeros((cap_l, cap_q), bool)
    pv[:, :2] = True
    c[:, 1, 0] = 1.0
    s[:, 1] = 1.0
    w = np.zeros((cap_l,), np.float32)
    k = np.zeros((cap_l,), np.int32)
    v = np.zeros((cap_l,), bool)
    for i, pts in enumerate(centers):
        c[i], s[i], pv[i] = _pad(np.asarray(pts, np.float64), cap_q)
        w[i], k[i], v[i] = widths[i], kinds[i], True
    return Lanes(
        center=jnp.asarray(c), s=jnp.asarray(s), point_valid=jnp.asarray(pv),
        width=jnp.asarray(w), valid=jnp.asarray(v), kind=jnp.asarray(k),
    )  # fmt: skip


def pack_route(points: np.ndarray, cap_r: int = CAP_R) -> Route:
    """Pack the ego route polyline (resampled at 2 m) into a padded :class:`Route`."""
    pts = np.asarray(points, np.float64)
    if len(pts) < 2:
        raise ValueError(f"Route.xy: a route needs at least two points, got {len(pts)}")
    pts = resample(pts, 2.0)
    xy, s, valid = _pad(pts, cap_r)
    return Route(xy=jnp.asarray(xy), s=jnp.asarray(s), valid=jnp.asarray(valid),
                 length=jnp.asarray(s[valid][-1], jnp.float32))  # fmt: skip


def no_lights(cap_t: int = CAP_T) -> TrafficLights:
    """A light set with every slot unused."""
    z = jnp.zeros((cap_t,), jnp.float32)
    return TrafficLights(green=z + 1.0, yellow=z, red=z, offset=z,
                         stop_xy=jnp.zeros((cap_t, 2), jnp.float32),
                         valid=jnp.zeros((cap_t,), bool))  # fmt: skip


_BOOL_FIELDS = ("is_route_a", "warning_enabled", "clear_on_ego_stop", "despawn_on_clear",
                "force_event", "late_onset")  # fmt: skip


def scenario_params(**overrides) -> ScenarioParams:
    """Neutral scenario parameters (no hazard behaviour unless overridden)."""
    d = dict(
        family=PE, is_route_a=True, warning_enabled=True, s_warn=BIG * 0.9, s_event=BIG * 0.9,
        s_conflict=BIG * 0.9, hazard_index=0, clear_s=BIG, clear_time_limit=BIG,
        clear_on_ego_stop=False, despawn_on_clear=False, force_event=True, force_delay=2.0,
        ego_light=-1, ego_stop_s=BIG, d_safe=2.0, v_ref=8.0, friction=1.0, sensing_range=100.0,
        template_id=0, text_id=0, timeout_s=60.0, late_onset=False, warn_hold_extra=0.0,
        pos_noise_sigma=0.0, noise_seed=0,
    )  # fmt: skip
    unknown = set(overrides) - set(d)
    if unknown:
        raise ValueError(f"ScenarioParams: unknown fields {sorted(unknown)}")
    d.update(overrides)
    dtypes = {"family": jnp.int32, "hazard_index": jnp.int32, "ego_light": jnp.int32,
              "template_id": jnp.int32, "text_id": jnp.int32, "noise_seed": jnp.uint32}  # fmt: skip
    out = {}
    for k, v in d.items():
        if isinstance(v, bool) or k in _BOOL_FIELDS:
            out[k] = jnp.asarray(bool(v))
        else:
            out[k] = jnp.asarray(v, dtypes.get(k, jnp.float32))
    return ScenarioParams(**out)


def straight_scene(
    actors: list[ActorSpec],
    length: float = 120.0,
    speed: float = 8.0,
    lights: TrafficLights | None = None,
    **param_overrides,
) -> World:
    """A straight road along +x: ego lane y = 0 (eastbound), a second eastbound lane at
    y = -3.5 and a westbound lane at y = +3.5; the ego starts at x = 0 at ``speed``.

    Args:
        actors: the actors (at most 16).
        length: route length, m.
        speed: initial ego speed and default reference speed, m/s.
        lights: optional traffic lights.
        **param_overrides: :class:`ScenarioParams` fields to override.
    """
    route = pack_route(np.array([[0.0, 0.0], [length, 0.0]]))
    lanes = pack_lanes(
        [
            resample(np.array([[-50.0, 0.0], [length + 50.0, 0.0]]), 10.0),
            resample(np.array([[-50.0, -3.5], [length + 50.0, -3.5]]), 10.0),
            resample(np.array([[length + 50.0, 3.5], [-50.0, 3.5]]), 10.0),
        ],
        [3.5, 3.5, 3.5],
    )
    a, script = pack_actors(actors)
    params = scenario_params(v_ref=speed, **param_overrides)
    ego = EgoState(
        xy=jnp.zeros((2,), jnp.float32),
        yaw=jnp.asarray(0.0, jnp.float32),
        speed=jnp.asarray(speed, jnp.float32),
        steer=jnp.asarray(0.0, jnp.float32),
        accel=jnp.asarray(0.0, jnp.float32),
    )
    world = World(
        t=jnp.asarray(0.0, jnp.float32), tick=jnp.asarray(0, jnp.int32), ego=ego, actors=a,
        script=script, lanes=lanes, route=route, lights=lights or no_lights(), params=params,
        protocol=ProtocolState.initial(),
    )  # fmt: skip
    return world.validate()
