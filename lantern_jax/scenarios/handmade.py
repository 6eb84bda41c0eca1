"""Hand-built scenes: a small constructor for tests, benchmarks and notebook experiments.

:func:`straight_scene` builds a complete, valid :class:`~lantern_jax.types.world.Scenario` on a
straight road from a short list of actor descriptions; everything not given gets a neutral
default (no hazard behaviour, no lights, dry weather).  It uses the same assembler as the
scenario families (:func:`lantern_jax.scenarios.assemble.assemble_scenario`); the frozen suite
uses the family builders in :mod:`lantern_jax.scenarios.families`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import BIG, KIND_VEHICLE, PE, ROLE_BACKGROUND
from lantern_jax.scenarios import assemble, road
from lantern_jax.types.world import (
    NO_OVERRIDE,
    ActorScript,
    ActorState,
    Lanes,
    Route,
    Scenario,
    TrafficLights,
)

CAP_T = road.MAX_LIGHTS


@dataclasses.dataclass
class ActorSpec(assemble.ActorSpec):
    """One actor of a hand-built scene (world frame, metres, seconds).

    The family builders' actor description with defaults for a parked car: a one-point ``path``
    is a static actor facing +x.
    """

    extent: tuple[float, float] = (2.3, 1.0)  # half length, half width
    kind: int = KIND_VEHICLE
    role: int = ROLE_BACKGROUND
    lat_duration: float = 2.0


def _as_family_spec(sp: ActorSpec) -> assemble.ActorSpec:
    path = np.asarray(sp.path, np.float64).reshape(-1, 2)
    if len(path) == 1:
        path = np.concatenate([path, path + np.array([[1.0, 0.0]])])
    return dataclasses.replace(sp, path=path)


def pack_actors(specs: list[ActorSpec]) -> tuple[ActorScript, ActorState]:
    """Pack actor specs into the padded static script and the actor state at t = 0."""
    return assemble.pack_actors([_as_family_spec(sp) for sp in specs], np.eye(2))


def resample(points: np.ndarray, step: float) -> np.ndarray:
    """Resample a polyline at (about) ``step`` metres, keeping both ends."""
    points = np.asarray(points, np.float64)
    n = max(int(np.ceil(road.arc_length(points)[-1] / step)), 1) + 1
    return road.resample(points, n)


def make_road_map(centers: list[np.ndarray], widths: list[float],
             kinds: list[int] | None = None) -> road.RoadMap:  # fmt: skip
    """A map of the given lane centre lines (travel direction = point order), no lights."""
    kinds = kinds or [road.LANE_DRIVING] * len(centers)
    return road.RoadMap(kind="straight", lanes=[
        road.LaneSpec(f"lane_{i}", np.asarray(c, np.float64), float(w), int(k))
        for i, (c, w, k) in enumerate(zip(centers, widths, kinds, strict=True))
    ])  # fmt: skip


def pack_lanes(centers: list[np.ndarray], widths: list[float],
               kinds: list[int] | None = None) -> Lanes:  # fmt: skip
    """Pack lane centre lines (travel direction = point order) into padded :class:`Lanes`."""
    packed = road.pack_lanes(make_road_map(centers, widths, kinds), np.eye(2))
    return Lanes(**{k: jnp.asarray(v) for k, v in packed.items()})


def route_points(points: np.ndarray) -> np.ndarray:
    """A route polyline resampled at 2 m (what :func:`pack_route` packs)."""
    pts = np.asarray(points, np.float64)
    if len(pts) < 2:
        raise ValueError(f"Route.xy: a route needs at least two points, got {len(pts)}")
    return resample(pts, 2.0)


def pack_route(points: np.ndarray) -> Route:
    """Pack the ego route polyline (resampled at 2 m) into a padded :class:`Route`."""
    packed = road.pack_route(route_points(points), np.eye(2))
    return Route(**{k: jnp.asarray(v) for k, v in packed.items()})


def no_lights(cap_t: int = CAP_T) -> TrafficLights:
    """A light set with every slot unused."""
    z = jnp.zeros((cap_t,), jnp.float32)
    return TrafficLights(green=z + 1.0, yellow=z, red=z, offset=z,
                         stop_xy=jnp.zeros((cap_t, 2), jnp.float32),
                         valid=jnp.zeros((cap_t,), bool))  # fmt: skip


#: Neutral execution configuration of a hand-built scene (no hazard behaviour).
NEUTRAL_CONFIG = dict(
    family=PE, is_route_a=True, warning_enabled=True, s_warn=BIG * 0.9, s_event=BIG * 0.9,
    s_conflict=BIG * 0.9, hazard_index=0, clear_s=BIG, clear_time_limit=BIG,
    clear_on_ego_stop=False, despawn_on_clear=False, force_event=True, force_delay=2.0,
    ego_light=-1, ego_stop_s=BIG, d_safe=2.0, v_ref=8.0, friction=1.0, sensing_range=100.0,
    template_id=0, text_id=0, timeout_s=60.0, late_onset=False, warn_hold_extra=0.0,
    pos_noise_m=0.0, noise_seed=0, **NO_OVERRIDE,
)  # fmt: skip


def config_fields(**overrides) -> dict:
    """:data:`NEUTRAL_CONFIG` with ``overrides`` (unknown fields are an error)."""
    unknown = set(overrides) - set(NEUTRAL_CONFIG)
    if unknown:
        raise ValueError(f"ExecutionConfig: unknown fields {sorted(unknown)}")
    return {**NEUTRAL_CONFIG, **overrides}


def straight_scene(
    actors: list[ActorSpec],
    length: float = 120.0,
    speed: float = 8.0,
    lights: TrafficLights | None = None,
    occluders: list[road.OccluderSpec] | None = None,
    **config_overrides,
) -> Scenario:
    """A straight road along +x: ego lane y = 0 (eastbound), a second eastbound lane at
    y = -3.5 and a westbound lane at y = +3.5; the ego starts at x = 0 at ``speed``.

    Args:
        actors: the actors (at most 16).
        length: route length, m.
        speed: initial ego speed and default reference speed, m/s.
        lights: optional traffic lights.
        occluders: optional static scenery boxes (world frame, at most ``road.MAX_OCCLUDERS``).
        **config_overrides: :class:`~lantern_jax.types.world.ExecutionConfig` fields to override.
    """
    lanes = make_road_map(
        [
            resample(np.array([[-50.0, 0.0], [length + 50.0, 0.0]]), 10.0),
            resample(np.array([[-50.0, -3.5], [length + 50.0, -3.5]]), 10.0),
            resample(np.array([[length + 50.0, 3.5], [-50.0, 3.5]]), 10.0),
        ],
        [3.5, 3.5, 3.5],
    )
    lanes.occluders = list(occluders or [])
    scenario = assemble.assemble_scenario(
        lanes,
        route_points(np.array([[0.0, 0.0], [length, 0.0]])),
        [_as_family_spec(sp) for sp in actors],
        config_fields(v_ref=speed, **config_overrides),
        ego_speed=speed,
    )
    scenario = scenario.replace(lights=lights or no_lights())
    return scenario.validate()
