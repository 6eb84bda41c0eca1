"""The world of ONE scenario execution, as ``flax.struct`` pytrees: a static :class:`Scenario`
and the dynamic pieces that the simulator's :class:`~lantern_jax.sim.state.State` carries.

* :class:`Scenario` — everything that never changes during an execution: the map
  (:class:`Lanes` and the static :class:`Occluders`), the ego :class:`Route`, the
  :class:`TrafficLights`, what every actor slot is
  and how it moves (:class:`ActorScript`), the execution's markers, condition, rules and weather
  (:class:`ExecutionConfig`) and the initial conditions (``ego0``, ``actors0``).  It is closed
  over (one execution) or broadcast along the batch axis (``vmap``), never carried.
* :class:`EgoState`, :class:`ActorState`, :class:`ProtocolState` — what changes tick by tick;
  the simulator's ``State`` (in :mod:`lantern_jax.sim.state`) composes them with the sensing
  results and the scoring accumulators.

Every function in the package takes and returns a single scenario; batches are made with
``jax.vmap`` outside.  Capacities (``A`` actors, ``P`` path points, ``L`` lanes, ``Q`` lane
points, ``R`` route points, ``T`` traffic lights, ``K`` occluders) are static and fixed by the
arrays' shapes; padded slots carry a ``valid`` mask.

Frames: world frame x east / y north / yaw counter-clockwise (see
:mod:`lantern_jax.core.constants`).

Each struct has a ``validate()`` method that runs **outside** ``jit`` on concrete arrays and raises
:class:`ValueError` naming the offending field (``"ActorScript.extent: ..."``).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.core import family_codes
from lantern_jax.core.actor_track import ActorTrack
from lantern_jax.core.checks import check_finite, check_nonneg, check_shape
from lantern_jax.core.constants import NUM_ACTOR_KINDS, NUM_OCCLUDER_KINDS, NUM_ROLES
from lantern_jax.core.times import NEVER

Array = jax.Array


# ---------------------------------------------------------------------------------------------
# dynamic pieces
# ---------------------------------------------------------------------------------------------
@struct.dataclass
class EgoState:
    """Ego vehicle state (kinematic bicycle, reference point = box centre)."""

    xy: Array  # (2,) float32, m, world frame, box centre
    yaw: Array  # () float32, rad, CCW from +x
    speed: Array  # () float32, m/s, >= 0 (no reversing)
    steer: Array  # () float32, rad, front-wheel angle, + = left
    accel: Array  # () float32, m/s^2, longitudinal acceleration applied during the last tick

    def validate(self) -> EgoState:
        check_shape("EgoState.xy", self.xy, (2,))
        for f in ("yaw", "speed", "steer", "accel"):
            check_shape(f"EgoState.{f}", getattr(self, f), ())
        for f in ("xy", "yaw", "speed", "steer", "accel"):
            check_finite(f"EgoState.{f}", getattr(self, f))
        check_nonneg("EgoState.speed", self.speed)
        return self


@struct.dataclass
class ActorState:
    """Dynamic state of a fixed-capacity padded actor set (A slots).

    Whether a slot holds an actor at all (``ActorScript.valid``) and its box are static; an actor
    exists in the world right now when it is valid and ``active`` (see :func:`present`).
    """

    xy: Array  # (A, 2) float32, m, world frame, box centre
    yaw: Array  # (A,) float32, rad, CCW from +x
    speed: Array  # (A,) float32, m/s, signed along the heading
    s: Array  # (A,) float32, m, arc length along the actor's path
    lat: Array  # (A,) float32, m, lateral offset from the path, + = left of travel
    active: Array  # (A,) bool, actor currently in the world (False after despawn)

    @property
    def num(self) -> int:
        """Static capacity A."""
        return self.xy.shape[-2]

    def validate(self, valid: Any = None) -> ActorState:
        """Check shapes, and finiteness of the slots marked ``valid`` (all slots when None)."""
        xy = check_shape("ActorState.xy", self.xy, (None, 2))
        n = xy.shape[0]
        for f in ("yaw", "speed", "s", "lat", "active"):
            check_shape(f"ActorState.{f}", getattr(self, f), (n,))
        v = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
        for f in ("xy", "yaw", "speed", "s", "lat"):
            check_finite(f"ActorState.{f}", getattr(self, f), v)
        return self


@struct.dataclass
class ProtocolState:
    """Temporal-protocol times of one execution; ``times.NEVER`` until the transition happens."""

    t_warn_point: Array  # () float32, s, ego reached the warning point (= t_ref)
    t_warn_on: Array  # () float32, s, warning delivery starts (NEVER in the no-warning
    #                   condition and on Route B)
    t_event: Array  # () float32, s, physical event onset
    t_warn_off: Array  # () float32, s, warning termination (hazard seen after the event)
    t_clear: Array  # () float32, s, hazard clearance
    countdown: Array  # () float32, s, anti-deadlock time accumulated since the warning point
    event_forced: Array  # () bool, the event was started by the anti-deadlock rule
    clear_by_limit: Array  # () bool, clearance came from a safety/stop limit
    ego_still_time: Array  # () float32, s, continuous time the ego has been (almost) still
    hazard_visible_at_warn: Array  # () bool, the hazard was camera-visible at the warning point
    warning_ticks: Array  # () int32, ticks at which a warning was delivered
    hazard_seen_before_warn: Array  # () bool, the camera saw the hazard at some tick from t = 0
    #                                 up to (and including) the one reaching the warning point

    @staticmethod
    def initial() -> ProtocolState:
        """All transitions pending."""
        never = jnp.asarray(NEVER, jnp.float32)
        z = jnp.asarray(0.0, jnp.float32)
        f = jnp.asarray(False)
        none = jnp.asarray(0, jnp.int32)
        return ProtocolState(never, never, never, never, never, z, f, f, z, f, none, f)


# ---------------------------------------------------------------------------------------------
# static pieces
# ---------------------------------------------------------------------------------------------
@struct.dataclass
class ActorScript:
    """What every actor slot is and how it moves (static over an execution).

    Body: ``extent``, ``kind``, ``role`` and ``valid`` (padding slots are ``valid = False``).

    Motion: scripted actors (``motion == MOTION_SCRIPTED``) move in closed form in time::

        trigger time   tau = trigger_delay            (TRIGGER_CLOCK)
                       tau = t_event + trigger_delay  (TRIGGER_EVENT; inf until the event)
                       tau = min(tau, trigger_deadline)   (a deadline triggers it regardless)
        before tau     s(t) = min(s_init + v_pre * t, s_hold)
        after tau      s(t) = s(tau) + v_post * (t - tau)
                       lat(t) = lat_shift * smoothstep((t - tau) / lat_duration)
        always         s clipped to s_end; the actor despawns at s_end when ``despawn_at_end``.

    A static object is ``v_pre = v_post = 0``.  IDM actors (``motion == MOTION_IDM``) integrate
    ``s`` with the intelligent driver model, desired speed ``v_pre``, stopping at ``stop_s`` while
    the light ``light_index`` is not green.  A scripted actor with a finite ``handover_after``
    is handed over to the IDM ``handover_after`` seconds after its trigger: from then on it
    continues from its scripted arc and speed as IDM traffic with desired speed ``v_post``, its
    lateral offset still following the script (the cut-in vehicle after its merge).
    """

    extent: Array  # (A, 2) float32, m, (half length, half width), >= 0
    kind: Array  # (A,) int32, KIND_* (vehicle, pedestrian, static)
    role: Array  # (A,) int32, ROLE_* (hazard, occluder, context, background)
    valid: Array  # (A,) bool, slot holds an actor of this execution (padding = False)
    motion: Array  # (A,) int32, MOTION_*
    path: Array  # (A, P, 2) float32, m, world-frame polyline followed by the actor
    path_s: Array  # (A, P) float32, m, cumulative arc length of ``path`` (0 at the first point)
    path_valid: Array  # (A, P) bool, valid polyline points (a prefix of each row)
    s_init: Array  # (A,) float32, m, initial arc length
    v_pre: Array  # (A,) float32, m/s, speed before the trigger (IDM: desired speed)
    v_post: Array  # (A,) float32, m/s, speed after the trigger
    s_hold: Array  # (A,) float32, m, arc where the actor waits until its trigger (BIG = none)
    s_end: Array  # (A,) float32, m, arc where the actor stops (or despawns)
    trigger: Array  # (A,) int32, TRIGGER_*
    trigger_delay: Array  # (A,) float32, s, delay after the trigger source
    lat_shift: Array  # (A,) float32, m, lateral offset executed after the trigger, + = left
    lat_duration: Array  # (A,) float32, s, duration of the lateral manoeuvre, > 0
    despawn_at_end: Array  # (A,) bool, remove the actor when it reaches ``s_end``
    light_index: Array  # (A,) int32, traffic light governing an IDM actor (-1 = none)
    stop_s: Array  # (A,) float32, m, arc of that light's stop line on the actor's path
    trigger_deadline: Array  # (A,) float32, s, latest trigger time (times.NEVER = none)
    handover_after: Array  # (A,) float32, s after the trigger: scripted -> IDM (NEVER = never)
    #: adversarial tracks (:class:`ActorTrack`); None = none, the motion of the scripts alone
    track: ActorTrack | None = None

    @property
    def num(self) -> int:
        """Static capacity A."""
        return self.extent.shape[-2]

    def validate(self, num_lights: int | None = None) -> ActorScript:
        ext = check_shape("ActorScript.extent", self.extent, (None, 2))
        n = ext.shape[0]
        for f in ("kind", "role", "valid", "motion"):
            check_shape(f"ActorScript.{f}", getattr(self, f), (n,))
        v = np.asarray(self.valid, bool)
        check_nonneg("ActorScript.extent", self.extent, v)
        kind, role = np.asarray(self.kind), np.asarray(self.role)
        if np.any(v & ((kind < 0) | (kind >= NUM_ACTOR_KINDS))):
            raise ValueError("ActorScript.kind: must be 0 (vehicle), 1 (pedestrian) or 2 (static)")
        if np.any(v & ((role < 0) | (role >= NUM_ROLES))):
            raise ValueError(
                "ActorScript.role: must be 0..3 (hazard, occluder, context, background)"
            )
        path = check_shape("ActorScript.path", self.path, (n, None, 2))
        p = path.shape[1]
        path_s = check_shape("ActorScript.path_s", self.path_s, (n, p))
        pv = check_shape("ActorScript.path_valid", self.path_valid, (n, p)).astype(bool)
        check_finite("ActorScript.path", self.path, pv)
        check_finite("ActorScript.path_s", self.path_s, pv)
        for f in (
            "s_init", "v_pre", "v_post", "s_hold", "s_end", "trigger", "trigger_delay",
            "lat_shift", "lat_duration", "despawn_at_end", "light_index", "stop_s",
            "trigger_deadline", "handover_after",
        ):  # fmt: skip
            check_shape(f"ActorScript.{f}", getattr(self, f), (n,))
            check_finite(f"ActorScript.{f}", getattr(self, f))
        for f in ("v_pre", "v_post", "trigger_delay", "trigger_deadline", "handover_after"):
            check_nonneg(f"ActorScript.{f}", getattr(self, f))
        if np.any(np.asarray(self.lat_duration) <= 0):
            raise ValueError("ActorScript.lat_duration: must be > 0")
        if np.any(pv.sum(-1) < 1):
            raise ValueError("ActorScript.path_valid: every actor path needs at least one point")
        both = pv[:, 1:] & pv[:, :-1] & v[:, None]
        if np.any(both & (np.diff(path_s, axis=-1) < 0)):
            raise ValueError("ActorScript.path_s: arc length must not decrease along a path")
        li = np.asarray(self.light_index)
        if num_lights is not None and np.any(v & (li >= num_lights)):
            raise ValueError(f"ActorScript.light_index: must be -1 or < {num_lights} light slots")
        if self.track is not None:
            self.track.validate(n)
        return self


@struct.dataclass
class Lanes:
    """Driving lanes as padded centre-line polylines; travel direction = point order."""

    center: Array  # (L, Q, 2) float32, m, world frame
    s: Array  # (L, Q) float32, m, cumulative arc length
    point_valid: Array  # (L, Q) bool
    width: Array  # (L,) float32, m
    valid: Array  # (L,) bool
    kind: Array  # (L,) int32, 0 = driving, 1 = shoulder/parking, 2 = junction connector

    def validate(self) -> Lanes:
        c = check_shape("Lanes.center", self.center, (None, None, 2))
        n, q = c.shape[:2]
        check_shape("Lanes.s", self.s, (n, q))
        pv = check_shape("Lanes.point_valid", self.point_valid, (n, q)).astype(bool)
        for f in ("width", "valid", "kind"):
            check_shape(f"Lanes.{f}", getattr(self, f), (n,))
        check_finite("Lanes.center", self.center, pv)
        v = np.asarray(self.valid, bool)
        check_nonneg("Lanes.width", self.width, v)
        if np.any(v & (pv.sum(-1) < 2)):
            raise ValueError("Lanes.point_valid: every valid lane needs at least two points")
        return self


@struct.dataclass
class Occluders:
    """Static scenery boxes of the map (buildings, walls, parked trucks and vans), K slots.

    They block camera rays (front camera, 360-degree rig and range image) and count as
    collisions, but they are never "visible" targets themselves and never move; Route A and
    Route B of a pair share them exactly.  Padded slots are ``valid = False``.
    """

    center: Array  # (K, 2) float32, m, world frame, box centre
    yaw: Array  # (K,) float32, rad, CCW from +x, direction of the box's long axis
    extent: Array  # (K, 2) float32, m, (half length, half width), > 0 for valid slots
    kind: Array  # (K,) int32, OCC_* (building, wall, parked vehicle)
    valid: Array  # (K,) bool, slot holds an occluder (padding = False)

    @property
    def num(self) -> int:
        """Static capacity K."""
        return self.valid.shape[-1]

    def validate(self) -> Occluders:
        c = check_shape("Occluders.center", self.center, (None, 2))
        n = c.shape[0]
        for f in ("yaw", "kind", "valid"):
            check_shape(f"Occluders.{f}", getattr(self, f), (n,))
        check_shape("Occluders.extent", self.extent, (n, 2))
        v = np.asarray(self.valid, bool)
        for f in ("center", "yaw", "extent"):
            check_finite(f"Occluders.{f}", getattr(self, f), v)
        ext = np.asarray(self.extent, np.float64)
        if np.any(v[:, None] & (ext <= 0.0)):
            i = int(np.argwhere(v[:, None] & (ext <= 0.0))[0, 0])
            raise ValueError(f"Occluders.extent: occluder {i} needs positive half extents")
        kind = np.asarray(self.kind)
        if np.any(v & ((kind < 0) | (kind >= NUM_OCCLUDER_KINDS))):
            raise ValueError("Occluders.kind: must be 0 (building), 1 (wall) or 2 (parked vehicle)")
        return self


ROUTE_LENGTH_TOL = 1e-3  # m, Route.length must match the last valid arc length to this


@struct.dataclass
class Route:
    """The ego route: a padded polyline with cumulative arc length."""

    xy: Array  # (R, 2) float32, m, world frame
    s: Array  # (R,) float32, m, cumulative arc length (0 at the start)
    valid: Array  # (R,) bool, valid points (a prefix)
    length: Array  # () float32, m, total route length

    def validate(self) -> Route:
        xy = check_shape("Route.xy", self.xy, (None, 2))
        r = xy.shape[0]
        check_shape("Route.s", self.s, (r,))
        v = check_shape("Route.valid", self.valid, (r,)).astype(bool)
        check_shape("Route.length", self.length, ())
        if v.sum() < 2:
            raise ValueError(f"Route.xy: a route needs at least two points, got {int(v.sum())}")
        check_finite("Route.xy", self.xy, v)
        check_finite("Route.s", self.s, v)
        check_finite("Route.length", self.length)
        s = np.asarray(self.s)[v]
        if np.any(np.diff(s) <= 0):
            raise ValueError("Route.s: arc length must be strictly increasing (duplicate points?)")
        length = float(self.length)
        if length <= 0 or abs(length - float(s[-1])) > ROUTE_LENGTH_TOL:
            raise ValueError(
                f"Route.length: {length!r} must equal the last valid arc length {float(s[-1])!r}"
            )
        return self


@struct.dataclass
class TrafficLights:
    """Fixed-cycle traffic lights (T slots); phase = (t + offset) mod (green + yellow + red)."""

    green: Array  # (T,) float32, s
    yellow: Array  # (T,) float32, s
    red: Array  # (T,) float32, s
    offset: Array  # (T,) float32, s, phase offset at t = 0
    stop_xy: Array  # (T, 2) float32, m, centre of the stop line (for drawing)
    valid: Array  # (T,) bool

    @property
    def num(self) -> int:
        """Static capacity T."""
        return self.valid.shape[-1]

    def validate(self) -> TrafficLights:
        g = check_shape("TrafficLights.green", self.green, (None,))
        n = g.shape[0]
        for f in ("yellow", "red", "offset", "valid"):
            check_shape(f"TrafficLights.{f}", getattr(self, f), (n,))
        check_shape("TrafficLights.stop_xy", self.stop_xy, (n, 2))
        v = np.asarray(self.valid, bool)
        for f in ("green", "yellow", "red"):
            check_nonneg(f"TrafficLights.{f}", getattr(self, f), v)
        check_finite("TrafficLights.offset", self.offset, v)
        cycle = np.asarray(self.green) + np.asarray(self.yellow) + np.asarray(self.red)
        if np.any(v & (cycle <= 0)):
            i = int(np.argwhere(v & (cycle <= 0))[0, 0])
            raise ValueError(f"TrafficLights.green: light {i} has an empty cycle (all phases 0)")
        return self


@struct.dataclass
class ExecutionConfig:
    """Markers, condition, clearance rules, weather and ablation switches of one execution.

    Distances along the route are arc lengths of :class:`Route`.  Everything here is data, so
    the condition (warning / no-warning) and the route variant (A / B) never branch in Python.
    """

    family: Array  # () int32, family index (family_codes.codes(): the six, then registered)
    is_route_a: Array  # () bool, Route A (hazard) vs Route B (control)
    warning_enabled: Array  # () bool, warning condition (only meaningful on Route A)
    s_warn: Array  # () float32, m, route arc of the warning point
    s_event: Array  # () float32, m, route arc of the geometric event trigger
    s_conflict: Array  # () float32, m, route arc of the conflict point
    hazard_index: Array  # () int32, actor slot of the controlled hazard actor
    clear_s: Array  # () float32, m, hazard path arc beyond which the hazard has cleared
    clear_time_limit: Array  # () float32, s after the event: safety/stop limit forcing clearance
    clear_on_ego_stop: Array  # () bool, clearance once the ego has held still after the event
    despawn_on_clear: Array  # () bool, remove the hazard actor at clearance
    force_event: Array  # () bool, anti-deadlock countdown applies (False for RTY)
    force_delay: Array  # () float32, s, anti-deadlock countdown (2.0)
    ego_light: Array  # () int32, traffic light governing the ego (-1 = none)
    ego_stop_s: Array  # () float32, m, route arc of the ego's stop line (BIG = none)
    d_safe: Array  # () float32, m, clearance normaliser (2 m PE/OR, 3 m otherwise)
    v_ref: Array  # () float32, m/s, reference (target) speed of the route
    friction: Array  # () float32, tyre-road friction coefficient (weather)
    sensing_range: Array  # () float32, m, camera range (weather)
    template_id: Array  # () int32, warning template (family) id
    text_id: Array  # () int32, warning text id in the text bank
    timeout_s: Array  # () float32, s, route timeout
    late_onset: Array  # () bool, ablation: warning delivered from the event on
    warn_hold_extra: Array  # () float32, s, ablation: warning held beyond termination
    pos_noise_m: Array  # () float32, m, ablation: one displacement of the reported hazard position
    noise_seed: Array  # () uint32, seed of its direction
    # Warning override (diagnostics): while the window is open the policy is delivered this
    # text and position instead of the protocol's warning, on any route and condition; an
    # empty window or a negative text id is "no override" (see NO_OVERRIDE).  It changes only
    # what the policy observes, never the protocol's times or the scoring.
    override_text_id: Array  # () int32, text-bank id delivered in the window (-1 = none)
    override_on_s: Array  # () float32, s, window start after the anchor (NEVER = none)
    override_off_s: Array  # () float32, s, window end (exclusive) after the anchor
    override_anchor: Array  # () int32, OVERRIDE_ANCHOR_* (execution start / warning point)
    override_x: Array  # () float32, m, override position: world x, or ego-frame forward
    override_y: Array  # () float32, m, override position: world y, or ego-frame right
    override_frame: Array  # () int32, OVERRIDE_FRAME_* (world / ego frame)

    def validate(self) -> ExecutionConfig:
        for f in self.__dataclass_fields__:
            check_shape(f"ExecutionConfig.{f}", getattr(self, f), ())
            check_finite(f"ExecutionConfig.{f}", getattr(self, f))
        for f in ("d_safe", "v_ref", "friction", "sensing_range", "timeout_s", "force_delay"):
            if float(getattr(self, f)) <= 0:
                raise ValueError(f"ExecutionConfig.{f}: must be > 0, got {float(getattr(self, f))}")
        check_nonneg("ExecutionConfig.pos_noise_m", self.pos_noise_m)
        check_nonneg("ExecutionConfig.warn_hold_extra", self.warn_hold_extra)
        if int(self.override_text_id) < -1:
            raise ValueError(
                f"ExecutionConfig.override_text_id: {int(self.override_text_id)} (-1 = none)"
            )
        for f, allowed in (
            ("override_anchor", "0 (start) or 1 (warning point)"),
            ("override_frame", "0 (world) or 1 (ego frame)"),
        ):
            value = int(getattr(self, f))
            if value not in (0, 1):
                raise ValueError(f"ExecutionConfig.{f}: must be {allowed}, got {value}")
        if float(self.override_off_s) < float(self.override_on_s):
            raise ValueError(
                f"ExecutionConfig.override_off_s: {float(self.override_off_s)} before "
                f"override_on_s {float(self.override_on_s)}"
            )
        fam, known = int(self.family), len(family_codes.codes())
        if not 0 <= fam < known:
            raise ValueError(f"ExecutionConfig.family: {fam} outside 0..{known - 1}")
        if not float(self.s_warn) <= float(self.s_event) <= float(self.s_conflict):
            raise ValueError(
                "ExecutionConfig.s_warn/s_event/s_conflict: need s_warn <= s_event <= "
                f"s_conflict, got {float(self.s_warn)}, {float(self.s_event)}, "
                f"{float(self.s_conflict)}"
            )
        return self


#: :class:`ExecutionConfig` override fields of an execution without a warning override.
NO_OVERRIDE = dict(
    override_text_id=-1, override_on_s=NEVER, override_off_s=NEVER, override_anchor=0,
    override_x=0.0, override_y=0.0, override_frame=0,
)  # fmt: skip


@struct.dataclass
class Scenario:
    """Everything that stays fixed during one execution, initial conditions included.

    Closed over by the scan of one execution (or broadcast along the batch axis); the dynamic
    :class:`~lantern_jax.sim.state.State` starts from ``ego0`` and ``actors0``.
    """

    lanes: Lanes
    occluders: Occluders  # static scenery boxes of the map
    route: Route
    lights: TrafficLights
    actors: ActorScript
    config: ExecutionConfig
    ego0: EgoState  # the ego at t = 0
    actors0: ActorState  # the actors at t = 0

    def validate(self) -> Scenario:
        """Validate every component (outside jit) and their mutual consistency."""
        self.lanes.validate()
        self.occluders.validate()
        self.route.validate()
        self.lights.validate()
        self.actors.validate(num_lights=self.lights.num)
        self.config.validate()
        self.ego0.validate()
        self.actors0.validate(self.actors.valid)
        n = self.actors.num
        if self.actors0.num != n:
            raise ValueError(f"ActorState.xy: {self.actors0.num} slots, ActorScript has {n}")
        h = int(self.config.hazard_index)
        if not 0 <= h < n:
            raise ValueError(f"ExecutionConfig.hazard_index: {h} outside 0..{n - 1}")
        el = int(self.config.ego_light)
        if el >= self.lights.num:
            raise ValueError(
                f"ExecutionConfig.ego_light: {el} >= number of light slots {self.lights.num}"
            )
        if el >= 0 and not bool(np.asarray(self.lights.valid)[el]):
            raise ValueError(f"ExecutionConfig.ego_light: light slot {el} is not valid")
        return self


def present(actors: ActorScript, state: ActorState) -> Array:
    """(A,) bool: the actors that exist in the world right now (valid and active)."""
    return actors.valid & state.active


def tree_stack(items: list) -> Any:
    """Stack a list of identically-shaped pytrees along a new leading batch axis.

    Concrete leaves are stacked on the host (NumPy, one copy per leaf, then one transfer);
    traced leaves (inside ``jit``) with ``jnp.stack``.
    """
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(items)):
        return jax.tree.map(lambda *xs: jnp.stack(xs), *items)
    return jax.device_put(jax.tree.map(lambda *xs: np.stack(xs), *items))


def pad_rows(tree: Any, multiple: int) -> tuple[Any, int]:
    """A batched pytree (leading axis ``n`` on every leaf) padded to the next multiple of
    ``multiple`` rows by repeating its rows (NumPy), so that every batch size up to a multiple
    runs one compiled program; returns it with ``n``, the rows to keep of a result computed
    row by row."""
    n = len(jax.tree.leaves(tree)[0])
    rows = np.resize(np.arange(n), -(-n // multiple) * multiple)
    return jax.tree.map(lambda x: np.asarray(x)[rows], tree), n


def tree_index(tree: Any, i: int) -> Any:
    """Take element ``i`` of a batched pytree."""
    return jax.tree.map(lambda x: x[i], tree)


def _keep_leading(tree: Any, batch_ndim: int, n: int) -> Any:
    """Every leaf of ``tree`` cut to its first ``n`` entries on axis ``batch_ndim``."""
    index = (slice(None),) * batch_ndim + (slice(0, n),)
    return jax.tree.map(lambda x: x[index], tree)


def used_slots(valid: Any) -> int:
    """Slots up to the last one marked valid anywhere in a batch (at least 1).

    Args:
        valid: (..., N) bool, concrete (NumPy or a committed JAX array), a slot mask.

    Returns:
        Python int in ``[1, N]``.
    """
    v = np.asarray(valid, bool).reshape(-1, np.shape(valid)[-1]).any(axis=0)
    return int(np.nonzero(v)[0].max()) + 1 if v.any() else 1


def trim_padding(scenario: Scenario, at_least: tuple[int, int] = (1, 1)) -> Scenario:
    """The same scenario (or batch) with the actor and lane slots past the last valid one cut.

    Padding slots are inert (``valid = False``: not present, never a target, blocker, leader or
    lane), so cutting them changes no result beyond float rounding: XLA compiles the narrower
    batch into a different program, whose last bits can differ (on the suite, 18 of 26,640
    route-table cells move by at most 4e-6, inside the promise of
    :mod:`lantern_jax.scoring.table`; gates, ids and printed tables are identical).  Every
    per-tick operation over actors or lanes gets narrower: the suite uses 10 of the 16 actor
    slots and 9 of the 16 lane slots.  Call it on concrete arrays
    (outside ``jit``); a batch is cut to the widest scenario in it, so all its members keep one
    shape.  ``hazard_index`` and every other slot index stay valid (slots are only cut after the
    last valid one).

    Args:
        scenario: a :class:`Scenario` with any number of leading batch axes (concrete).
        at_least: (actor slots, lane slots) to keep at least, e.g. those of a batch whose
            compiled program should serve this one too (at most the capacity).

    Returns:
        The :class:`Scenario` with ``actors`` / ``actors0`` and ``lanes`` narrowed.
    """
    batch_ndim = np.ndim(scenario.actors.valid) - 1
    n_act = max(used_slots(scenario.actors.valid), at_least[0])
    n_lane = max(used_slots(scenario.lanes.valid), at_least[1])
    return scenario.replace(
        actors=_keep_leading(scenario.actors, batch_ndim, n_act),
        actors0=_keep_leading(scenario.actors0, batch_ndim, n_act),
        lanes=_keep_leading(scenario.lanes, batch_ndim, n_lane),
    )
