"""One assembler of :class:`~lantern_jax.types.world.Scenario` pytrees, shared by the family
builders and the hand-built scenes (NumPy, build time).

Builders describe each actor slot with an :class:`ActorSpec` in a canonical frame;
:func:`assemble_scenario` rotates the scene, packs every piece into the fixed capacities of
:mod:`lantern_jax.scenarios.road` and returns a :class:`~lantern_jax.types.world.Scenario`
whose initial actor state is the closed form of :class:`~lantern_jax.types.world.ActorScript` at
``t = 0``.  :func:`execution_config` turns a dict of
:class:`~lantern_jax.types.world.ExecutionConfig` fields into the pytree with the right dtypes.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from dataclasses import dataclass

import jax
import numpy as np

from lantern_jax.core.constants import (
    BIG,
    INF_TIME,
    MOTION_IDM,
    MOTION_SCRIPTED,
    TRIGGER_CLOCK,
    TRIGGER_NEVER,
)
from lantern_jax.scenarios import road
from lantern_jax.types.world import (
    NO_OVERRIDE,
    ActorScript,
    ActorState,
    EgoState,
    ExecutionConfig,
    Lanes,
    Occluders,
    Route,
    Scenario,
    TrafficLights,
)


@dataclass
class ActorSpec:
    """One actor slot in the canonical frame (see :class:`~lantern_jax.types.world.ActorScript`)."""

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
    trigger_deadline: float = INF_TIME  # s, latest trigger time (INF_TIME = none)
    handover_after: float = INF_TIME  # s after the trigger: continue as IDM (INF_TIME = never)

    def initial_state(self) -> tuple[float, float]:
        """``(s, speed)`` at ``t = 0`` from the scripted closed form (IDM: s_init, v_pre)."""
        if self.motion == MOTION_IDM:
            return self.s_init, self.v_pre
        started = self.trigger == TRIGGER_CLOCK and self.trigger_delay <= 0.0
        if started or self.trigger_deadline <= 0.0:
            return self.s_init, self.v_post
        if self.s_init >= self.s_hold:
            return self.s_hold, 0.0
        return self.s_init, self.v_pre


def initial_pose(spec: ActorSpec) -> tuple[np.ndarray, float, float, float]:
    """``(xy, yaw, s, speed)`` of an actor at ``t = 0`` (canonical frame)."""
    s, v = spec.initial_state()
    return road.point_at(spec.path, s), road.heading_at(spec.path, s), s, v


_SCRIPT_FIELDS = (
    "motion", "s_init", "v_pre", "v_post", "s_hold", "trigger", "trigger_delay", "lat_shift",
    "lat_duration", "despawn_at_end", "light_index", "stop_s", "trigger_deadline",
    "handover_after",
)  # fmt: skip


def pack_actors(slots: list[ActorSpec | None], rot: np.ndarray) -> tuple[ActorScript, ActorState]:
    """Pack actor slots (None = empty) into the padded static script and the state at ``t = 0``."""
    a_n, p_n = road.MAX_ACTORS, road.PATH_POINTS
    if len(slots) > a_n:
        raise ValueError(f"ActorScript.valid: {len(slots)} actors exceed capacity {a_n}")
    f32 = lambda *shape: np.zeros(shape, np.float32)  # noqa: E731
    state = dict(
        xy=f32(a_n, 2), yaw=f32(a_n), speed=f32(a_n), s=f32(a_n), lat=f32(a_n),
        active=np.zeros(a_n, bool),
    )  # fmt: skip
    scr = dict(
        extent=f32(a_n, 2), kind=np.zeros(a_n, np.int32), role=np.zeros(a_n, np.int32),
        valid=np.zeros(a_n, bool),
        motion=np.zeros(a_n, np.int32), path=f32(a_n, p_n, 2), path_s=f32(a_n, p_n),
        path_valid=np.zeros((a_n, p_n), bool), s_init=f32(a_n), v_pre=f32(a_n), v_post=f32(a_n),
        s_hold=np.full(a_n, BIG, np.float32), s_end=f32(a_n),
        trigger=np.full(a_n, TRIGGER_NEVER, np.int32), trigger_delay=f32(a_n),
        lat_shift=f32(a_n), lat_duration=np.ones(a_n, np.float32),
        despawn_at_end=np.zeros(a_n, bool), light_index=np.full(a_n, -1, np.int32),
        stop_s=np.full(a_n, BIG, np.float32),
        trigger_deadline=np.full(a_n, INF_TIME, np.float32),
        handover_after=np.full(a_n, INF_TIME, np.float32),
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
        cs = road.arc_length(path)
        scr["path"][i, :n], scr["path"][i, n:] = wp, wp[-1]
        scr["path_s"][i, :n], scr["path_s"][i, n:] = cs, cs[-1]
        scr["path_valid"][i, :n] = True
        for k in _SCRIPT_FIELDS:
            scr[k][i] = getattr(sp, k)
        scr["s_end"][i] = cs[-1] if sp.s_end is None else sp.s_end
        scr["extent"][i] = sp.extent
        scr["kind"][i], scr["role"][i], scr["valid"][i] = sp.kind, sp.role, True
        state["xy"][i] = rot @ xy
        state["yaw"][i] = math.remainder(yaw + math.atan2(rot[1, 0], rot[0, 0]), 2 * math.pi)
        state["speed"][i], state["s"][i], state["lat"][i] = v0, s0, 0.0
        state["active"][i] = True
    return ActorScript(**_device_tree(scr)), ActorState(**_device_tree(state))


#: dtypes of the non-float32 fields of :class:`ExecutionConfig`.
CONFIG_DTYPES = {
    "family": np.int32, "hazard_index": np.int32, "ego_light": np.int32,
    "template_id": np.int32, "text_id": np.int32, "noise_seed": np.uint32,
    "override_text_id": np.int32, "override_anchor": np.int32, "override_frame": np.int32,
    "is_route_a": np.bool_, "warning_enabled": np.bool_, "clear_on_ego_stop": np.bool_,
    "despawn_on_clear": np.bool_, "force_event": np.bool_, "late_onset": np.bool_,
}  # fmt: skip


def execution_config(fields: dict) -> ExecutionConfig:
    """An :class:`ExecutionConfig` from a dict of Python values.

    Every field is required except the warning-override fields, which default to
    :data:`~lantern_jax.types.world.NO_OVERRIDE` (no override).

    Raises:
        ValueError: naming missing or unknown fields.
    """
    fields = {**NO_OVERRIDE, **fields}
    names = set(ExecutionConfig.__dataclass_fields__)
    missing, unknown = names - set(fields), set(fields) - names
    if missing or unknown:
        raise ValueError(
            f"ExecutionConfig: missing fields {sorted(missing)}, unknown fields {sorted(unknown)}"
        )
    config = ExecutionConfig(
        **{k: np.asarray(fields[k], CONFIG_DTYPES.get(k, np.float32)) for k in names}
    )
    return config if _ON_HOST.get() else jax.device_put(config)


def _host_array(value) -> np.ndarray:
    """``value`` as a NumPy array with the dtype JAX would give it (64-bit types narrowed to
    32 bits, as under JAX's default ``jax_enable_x64 = False``)."""
    a = np.asarray(value)
    if a.dtype == np.float64:
        return a.astype(np.float32)
    if a.dtype == np.int64:
        return a.astype(np.int32)
    return a


#: While True (:func:`host_arrays`), assembled scenarios keep NumPy leaves instead of device
#: arrays, so that a whole suite can be stacked on the host and transferred once.
_ON_HOST: contextvars.ContextVar[bool] = contextvars.ContextVar("on_host", default=False)


@contextlib.contextmanager
def host_arrays():
    """Within this context, :func:`assemble_scenario` and :func:`execution_config` return
    pytrees of NumPy arrays (with JAX's dtypes) instead of device arrays: building many
    scenarios to stack them costs no per-leaf transfer.  Such a scenario is fine as a ``jit``
    argument; use device arrays (the default) for eager ``.at[]`` updates."""
    token = _ON_HOST.set(True)
    try:
        yield
    finally:
        _ON_HOST.reset(token)


def _device_tree(d: dict) -> dict:
    """A dict of NumPy values as device arrays, in one transfer (NumPy under
    :func:`host_arrays`)."""
    tree = {k: _host_array(v) for k, v in d.items()}
    return tree if _ON_HOST.get() else jax.device_put(tree)


def assemble_scenario(
    road_map: road.RoadMap,
    route_xy: np.ndarray,
    slots: list[ActorSpec | None],
    config: dict,
    rotation_deg: float = 0.0,
    ego_speed: float | None = None,
) -> Scenario:
    """Rotate and pack a canonical scene into a :class:`Scenario`.

    The ego starts at the route start, on the route, heading along it, at ``ego_speed``
    (default ``config["v_ref"]``: runs start in motion), with zero steer and acceleration.

    Args:
        road_map: the map (canonical frame).
        route_xy: (n, 2) route polyline (canonical frame).
        slots: actor specs per slot (None = empty), at most ``MAX_ACTORS``.
        config: every field of :class:`ExecutionConfig` as Python values.
        rotation_deg: rigid rotation applied to the whole scene.
        ego_speed: initial ego speed, m/s.
    """
    rot = road.rotation(rotation_deg)
    route = road.pack_route(route_xy, rot)
    script, actors0 = pack_actors(slots, rot)
    ego_yaw = math.remainder(
        road.heading_at(route_xy, 0.0) + math.radians(rotation_deg), 2 * math.pi
    )
    speed = config["v_ref"] if ego_speed is None else ego_speed
    ego0 = EgoState(
        **_device_tree(dict(xy=route["xy"][0], yaw=ego_yaw, speed=speed, steer=0.0, accel=0.0))
    )
    return Scenario(
        lanes=Lanes(**_device_tree(road.pack_lanes(road_map, rot))),
        occluders=Occluders(**_device_tree(road.pack_occluders(road_map.occluders, rot))),
        route=Route(**_device_tree(route)),
        lights=TrafficLights(**_device_tree(road.pack_lights(road_map.lights, rot))),
        actors=script,
        config=execution_config(config),
        ego0=ego0,
        actors0=actors0,
    )
