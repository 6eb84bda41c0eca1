"""One tick of every non-ego actor of ONE scenario (vectorised over the A actor slots).

* **Scripted actors** (``MOTION_SCRIPTED``) take their closed-form pose at ``t_next``
  (:mod:`lantern_jax.dynamics.scripted`) with trigger time ``trigger_delay`` (clock),
  ``t_event + trigger_delay`` (event; not triggered while ``t_event`` is pending) or never.
  A deadline (``trigger_deadline``) triggers a scripted actor even if its source has not
  fired yet (the Obstacle Reveal van's own guard).
* **IDM actors** (``MOTION_IDM``) integrate arc ``s`` and speed along their path with the IDM
  (:mod:`lantern_jax.dynamics.idm`), desired speed ``v_pre``, ``lat = 0``.
* **Hand-over**: a scripted actor becomes an IDM actor ``handover_after`` seconds after its
  trigger (data, not code: every slot has the field, ``NEVER`` = never).  It continues from its
  scripted arc and speed, with desired speed ``v_post``; its lateral offset keeps following the
  script in time (constant ``lat_shift`` once the manoeuvre is over), so the Vehicle Cut-In car
  continues as ordinary traffic in its new lane after its merge.

  The IDM acceleration is the minimum of the IDM accelerations toward every constraint ahead:

  - every other present actor and the ego whose box centre lies ahead of this actor, within
    ``LEADER_LATERAL`` (1.6 m) of its heading line (a local-frame search, exact on straight
    lanes); gap = longitudinal offset minus both half lengths, leader speed = its velocity
    component along this actor's heading (>= 0).  The ego counts, so traffic behind the ego in
    its lane on a straight road stops for it.  The test is on box centres and the heading line:
    on a curved lane a follower still in the bend misses an ego ahead of it (its centre off the
    tangent) until it comes out, and an ego whose nose is in the lane with its centre more than
    1.6 m off the line is not a leader at all (``docs/learned.md``, "The slowest member's plan",
    traces such collisions).  That is ``ActorSettings(ego_leader="heading_line")``, the rule
    of every result written before 2026-12-08.  The default, ``"heading_line_or_box"``, also
    lets the ego lead wherever its box lies on the actor's own path (:func:`_ego_box_on_path`),
    the nearer of the two gaps counting: CARLA's agents, which drive the paper's scenario
    actors, test the vehicles on their path by their boxes, not their centres;
  - the stop line ``stop_s`` of the actor's light (``light_index >= 0``) while that light is red
    or yellow, as a stopped leader (gap = stop_s - s - half length), provided the actor can still
    stop before it: on red if ``gap >= v^2 / (2 max_brake)``, on yellow if
    ``gap >= v^2 / (2 b)`` (``b`` the comfortable deceleration); otherwise it proceeds;
  - the path end ``s_end`` when the actor does not despawn there, as a stopped leader placed so
    that the IDM equilibrium puts the actor's centre at ``s_end``.

  Speeds integrate exactly and never go negative
  (:func:`lantern_jax.dynamics.bicycle.longitudinal_step`); an IDM actor despawns at ``s_end``
  when ``despawn_at_end``, else it is clipped there.

Slots that are not present (padding or despawned) keep their state bit for bit and are not
candidates for anyone; once inactive an actor stays inactive.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import (
    BIG,
    DT,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    LIGHT_GREEN,
    LIGHT_RED,
    LIGHT_YELLOW,
    MOTION_IDM,
    MOTION_SCRIPTED,
)
from lantern_jax.core.times import NEVER, happened
from lantern_jax.dynamics.adversary import commanded, track_start
from lantern_jax.dynamics.bicycle import longitudinal_step
from lantern_jax.dynamics.idm import (
    DEFAULT_IDM,
    IDMParams,
    free_road_term,
    idm_from_terms,
    interaction_term,
)
from lantern_jax.dynamics.scripted import (
    ScriptedMotion,
    scripted_arc,
    scripted_pose,
    trigger_time,
)
from lantern_jax.maths.polyline import interpolate, left_normal, project
from lantern_jax.types.world import ActorScript, ActorState, present

Array = jax.Array

LEADER_LATERAL = (
    1.6  # m, |lateral offset| from an IDM actor's heading line within which others lead it
)
LEADER_RANGE = 80.0  # m, look-ahead of the leader search
#: m, what the ``"heading_line_or_box"`` rule adds to both half widths: the ego leads an IDM actor
#: when its box, projected on the actor's path, comes this close to the actor's own box sideways.
EGO_BOX_MARGIN = 0.3
#: How an IDM actor finds the ego as its leader (:class:`ActorSettings`): ``"heading_line"``, the
#: ego's box centre within :data:`LEADER_RANGE` ahead and :data:`LEADER_LATERAL` of the actor's
#: heading line, as for every other candidate; ``"heading_line_or_box"``, that or the ego's box
#: on the actor's own path (:func:`_ego_box_on_path`), so that a car brakes for an ego pulling out
#: in front of it at an angle and for one ahead of it in a bend.
EGO_LEADER_RULES = ("heading_line", "heading_line_or_box")
#: The default of :class:`ActorSettings` and of the functions below (since 2026-12-08).  The
#: paper's scenario actors and background traffic are driven by CARLA's agents (scenario
#: runner's ``ActorFlow`` drives the Right-Turn Yield flow with a ``BasicAgent``; Traffic Manager
#: the rest), which brake for a vehicle whose bounding box meets the path ahead of them (inside a
#: junction always; several Leaderboard 2.0 scenarios turn the box test on everywhere for their
#: scenario vehicles, so that these never drive over the ego), not only for one centred on
#: their lane.  Under the heading line alone a flow car drives into an ego that pulls out in
#: front of it at an angle: 6 of ``coop``'s 20 warned Right-Turn Yield executions on
#: ``lantern-v3`` and one of the ``expert``'s (``docs/settings.md``).
DEFAULT_EGO_LEADER = EGO_LEADER_RULES[1]
#: The rule of every result written before 2026-12-08, when it was the default: a manifest whose
#: settings record no ``actors`` ran under it (:func:`lantern_jax.sim.settings.actors_of_record`),
#: and the validators that filtered ``lantern-v3`` and every suite of its design drive under it
#: (:data:`lantern_jax.apps.suite_generation.VALIDATION_ACTORS`).
EARLIER_EGO_LEADER = EGO_LEADER_RULES[0]


@struct.dataclass
class ActorSettings:
    """How the IDM-driven actors treat the ego (``Settings.actors``,
    :class:`~lantern_jax.sim.settings.Settings`).

    ``ego_leader`` is static (a change compiles the world's program again): one of
    :data:`EGO_LEADER_RULES`, default :data:`DEFAULT_EGO_LEADER` (why there);
    :data:`EARLIER_ACTORS` are the actors of every result written before 2026-12-08.
    """

    ego_leader: str = struct.field(pytree_node=False, default=DEFAULT_EGO_LEADER)

    def validate(self) -> ActorSettings:
        """Check the values outside ``jit``; returns self.

        Raises:
            ValueError: naming ``ActorSettings.ego_leader`` when it is not a known rule.
        """
        if self.ego_leader not in EGO_LEADER_RULES:
            raise ValueError(f"ActorSettings.ego_leader: {self.ego_leader!r} is not one of "
                             f"{', '.join(EGO_LEADER_RULES)}")  # fmt: skip
        return self


#: The default actors.
DEFAULT_ACTORS = ActorSettings()
#: The actors of every result written before 2026-12-08 (:data:`EARLIER_EGO_LEADER`).
EARLIER_ACTORS = ActorSettings(ego_leader=EARLIER_EGO_LEADER)


def _zero_where_invalid(x: Array, valid: Array) -> Array:
    """Replace the padded slots of an (A, ...) float array by 0 (keeps padding out of the math)."""
    if not jnp.issubdtype(x.dtype, jnp.floating):
        return x
    mask = valid.reshape(valid.shape + (1,) * (x.ndim - 1))
    return jnp.where(mask, x, jnp.zeros_like(x))


def _idm_candidates(
    actors: ActorState,
    extent: Array,
    present: Array,
    ego_xy: Array,
    ego_yaw: Array,
    ego_speed: Array,
) -> tuple[Array, Array]:
    """Gaps and leader speeds of every (IDM actor i, candidate c) pair; candidates = actors + ego.

    Leaders are found in the follower's local frame (its box centre and heading): a candidate
    leads when it is ahead (longitudinal offset > 0, up to LEADER_RANGE) and within
    LEADER_LATERAL of the follower's heading line.  This is exact on straight lanes and costs
    O(A^2) per tick instead of projecting every candidate onto every path; on a curved path it
    approximates the path by its tangent over the look-ahead.

    Args:
        actors: (A,) actor states.
        extent: (A, 2) float32, m, half extents.
        present: (A,) bool, the actors that exist now.
        ego_xy, ego_yaw, ego_speed: the ego (m, rad, m/s).

    Returns:
        gap: (A, A + 1) float32, m, bumper-to-bumper gap (BIG if c does not lead i).
        v_lead: (A, A + 1) float32, m/s, candidate speed along i's heading (>= 0).
    """
    num = actors.xy.shape[0]
    cand_x = jnp.concatenate([actors.xy[:, 0], ego_xy[0:1]])
    cand_y = jnp.concatenate([actors.xy[:, 1], ego_xy[1:2]])
    cand_yaw = jnp.concatenate([actors.yaw, jnp.reshape(ego_yaw, (1,))])
    cand_speed = jnp.concatenate([actors.speed, jnp.reshape(ego_speed, (1,))])
    cand_half = jnp.concatenate([extent[:, 0], jnp.full((1,), EGO_HALF_LENGTH)])
    cand_ok = jnp.concatenate([present, jnp.ones((1,), bool)])

    hx, hy = jnp.cos(actors.yaw)[:, None], jnp.sin(actors.yaw)[:, None]  # (A, 1)
    rx = cand_x[None, :] - actors.xy[:, 0:1]  # (A, A + 1)
    ry = cand_y[None, :] - actors.xy[:, 1:2]
    lon = rx * hx + ry * hy
    lat = hx * ry - hy * rx
    not_self = ~jnp.eye(num, num + 1, dtype=bool)
    leads = (
        cand_ok[None, :]
        & not_self
        & (lon > 0.0)
        & (lon < LEADER_RANGE)
        & (jnp.abs(lat) < LEADER_LATERAL)
    )
    gap = lon - extent[:, 0:1] - cand_half[None, :]
    gap = jnp.where(leads, gap, BIG)
    v_lead = jnp.maximum(
        cand_speed[None, :] * jnp.cos(cand_yaw[None, :] - actors.yaw[:, None]), 0.0
    )
    v_lead = jnp.where(leads, v_lead, 0.0)
    return gap, v_lead


def _ego_box_on_path(
    actors: ActorState, script: ActorScript, ego_xy: Array, ego_yaw: Array, ego_speed: Array
) -> tuple[Array, Array]:
    """The ego as each IDM actor's leader when its box lies on the actor's own path.

    The ego's box centre is projected on every actor's path polyline
    (:func:`~lantern_jax.maths.polyline.project`: arc, signed offset, the path's heading there).
    Across the path the box reaches ``|sin d| L + |cos d| W`` from its centre, along it
    ``|cos d| L + |sin d| W`` (``d`` the ego's heading relative to the path's, ``L``, ``W`` its
    half length and width).  It leads actor ``i`` when its centre is ahead of the actor's arc
    (by less than :data:`LEADER_RANGE`) and its offset from the actor's own lateral place is
    within the actor's half width, the box's reach across and :data:`EGO_BOX_MARGIN`.

    Args:
        actors: (A,) actor states (``s``, m along the path; ``lat``, m off it).
        script: (A,) slots (``path``, ``path_s``, ``path_valid``; ``extent``, m).
        ego_xy: (2,) float32, m; ego_yaw: () float32, rad; ego_speed: () float32, m/s.

    Returns:
        gap: (A,) float32, m, bumper-to-bumper along the path (``BIG`` where the ego does not lead).
        v_lead: (A,) float32, m/s, the ego's speed along the path (>= 0; 0 where it does not lead).
    """
    arc, lat, heading, _ = jax.vmap(project, in_axes=(0, 0, 0, None))(
        script.path, script.path_s, script.path_valid, ego_xy
    )
    d = ego_yaw - heading
    cos_d, sin_d = jnp.abs(jnp.cos(d)), jnp.abs(jnp.sin(d))
    across = sin_d * EGO_HALF_LENGTH + cos_d * EGO_HALF_WIDTH
    along = cos_d * EGO_HALF_LENGTH + sin_d * EGO_HALF_WIDTH
    ahead = arc - actors.s
    reach = script.extent[:, 1] + across + EGO_BOX_MARGIN
    leads = (ahead > 0.0) & (ahead < LEADER_RANGE) & (jnp.abs(lat - actors.lat) < reach)
    gap = jnp.where(leads, ahead - script.extent[:, 0] - along, BIG)
    v_lead = jnp.where(leads, jnp.maximum(ego_speed * jnp.cos(d), 0.0), 0.0)
    return gap, v_lead


def _idm_update(
    actors: ActorState,
    script: ActorScript,
    present: Array,
    light_state: Array,
    ego_xy: Array,
    ego_yaw: Array,
    ego_speed: Array,
    dt: float,
    params: IDMParams,
    track_accel: Array | None = None,
    ego_leader: str = DEFAULT_EGO_LEADER,
) -> tuple[Array, Array, Array]:
    """New (s, speed, active) of every slot integrated as an IDM actor, each (A,).

    ``track_accel`` (A,) m/s^2 is an adversarial track's commanded acceleration, added to the
    IDM's and the sum kept within the track's limits (:mod:`lantern_jax.dynamics.adversary`;
    an exact no-op when 0).  ``ego_leader`` is one of :data:`EGO_LEADER_RULES`.
    """
    v = jnp.maximum(actors.speed, 0.0)
    half = script.extent[:, 0]
    gap, v_lead = _idm_candidates(actors, script.extent, present, ego_xy, ego_yaw, ego_speed)
    if ego_leader == "heading_line_or_box":  # the nearer of the two as the ego's gap
        box_gap, box_v = _ego_box_on_path(actors, script, ego_xy, ego_yaw, ego_speed)
        nearer = box_gap < gap[:, -1]
        v_lead = v_lead.at[:, -1].set(jnp.where(nearer, box_v, v_lead[:, -1]))
        gap = gap.at[:, -1].set(jnp.where(nearer, box_gap, gap[:, -1]))

    # traffic light stop line as a stopped leader
    num_lights = light_state.shape[0]
    if num_lights > 0:
        idx = jnp.clip(script.light_index, 0, num_lights - 1)
        state = jnp.where(script.light_index >= 0, light_state[idx], LIGHT_GREEN)
    else:
        state = jnp.full(v.shape, LIGHT_GREEN, jnp.int32)
    gap_light = script.stop_s - actors.s - half
    can_stop_red = gap_light >= v * v / (2.0 * params.max_brake)
    can_stop_yellow = gap_light >= v * v / (2.0 * params.decel)
    stops = ((state == LIGHT_RED) & can_stop_red) | ((state == LIGHT_YELLOW) & can_stop_yellow)
    gap_light = jnp.where(stops & (gap_light > 0.0), gap_light, BIG)

    # path end as a stopped leader (centre settles at s_end) unless the actor despawns there
    end_ok = (~script.despawn_at_end) & (script.s_end < 0.5 * BIG)
    gap_end = jnp.where(end_ok, script.s_end - actors.s + params.s0, BIG)

    gaps = jnp.concatenate([gap, gap_light[:, None], gap_end[:, None]], axis=1)
    leads_v = jnp.concatenate([v_lead, jnp.zeros((v.shape[0], 2), v.dtype)], axis=1)
    # The IDM acceleration is monotone in the interaction term: take its max over leaders and
    # evaluate the free-road power once per actor.
    inter = jnp.max(interaction_term(v[:, None], gaps, v[:, None] - leads_v, params), axis=1)
    acc = idm_from_terms(free_road_term(v, script.v_pre, params), inter, script.v_pre, params)
    if track_accel is not None:
        tr = script.track
        extra = jnp.where(v >= tr.v_max, jnp.minimum(track_accel, 0.0), track_accel)
        acc = jnp.clip(acc + extra, jnp.minimum(-tr.b_max, acc), jnp.maximum(tr.a_max, acc))

    distance, v_next = longitudinal_step(v, acc, dt)
    s_next = actors.s + distance
    reached = s_next >= script.s_end
    s_next = jnp.minimum(s_next, script.s_end)
    v_next = jnp.where(reached, 0.0, v_next)
    active = ~(script.despawn_at_end & reached)
    return s_next, v_next, active


def scripted_states(
    script: ActorScript, t: Array, t_event: Array
) -> tuple[Array, Array, Array, Array, Array, Array]:
    """Closed-form state of every slot at time ``t`` as if it were a scripted actor.

    Args:
        script: (A,) slots.
        t: () float32, s.
        t_event: () float32, s, physical event onset (``times.NEVER`` while pending).

    Returns:
        s (A,) m, lat (A,) m, speed (A,) m/s, xy (A, 2) m, yaw (A,) rad, active (A,) bool — see
        :func:`lantern_jax.dynamics.scripted.scripted_pose`.
    """
    tau = trigger_time(script.trigger, script.trigger_delay, t_event, script.trigger_deadline)
    args = (script.path, script.path_s, script.path_valid, ScriptedMotion.of(script), t, tau)
    if script.track is None:
        return jax.vmap(scripted_pose, in_axes=(0, 0, 0, 0, None, 0))(*args)
    return jax.vmap(scripted_pose, in_axes=(0, 0, 0, 0, None, 0, 0))(*args, track_args(script))


def track_args(script: ActorScript) -> tuple[Array, ...]:
    """The per-slot track profile that :func:`~lantern_jax.dynamics.scripted.scripted_arc`
    takes, ``(dv, ds, q, g, dlat, knot_s)`` with a leading (A,) slot axis."""
    tr = script.track
    return (tr.dv, tr.ds, tr.q, tr.g, tr.dlat, tr.knot_s)


def start_state(script: ActorScript) -> ActorState:
    """The actors at ``t = 0`` implied by their scripts (float32, jittable, differentiable).

    Scripted slots take their closed form at ``t = 0`` (the event has not happened); IDM slots
    stand at ``s_init`` on their path at their desired speed ``v_pre``.  Padding slots are
    zero and inactive.  The scenario builders compute the same state in float64 NumPy
    (:func:`lantern_jax.scenarios.assemble.pack_actors`); this is the run-time twin used when
    a scenario's scripts are changed after it was built (:mod:`lantern_jax.scenarios.knobs`).
    """
    zero = jnp.zeros((), jnp.float32)
    s, lat, speed, xy, yaw, _ = scripted_states(script, zero, jnp.asarray(NEVER, jnp.float32))
    id_xy, id_yaw = jax.vmap(interpolate)(
        script.path, script.path_s, script.path_valid, script.s_init
    )
    is_idm = script.motion == MOTION_IDM

    def pick(idm_value, scripted_value):
        return _where_slot(script.valid, _where_slot(is_idm, idm_value, scripted_value), 0.0)

    return ActorState(
        xy=pick(id_xy, xy),
        yaw=pick(id_yaw, yaw),
        speed=pick(script.v_pre, speed),
        s=pick(script.s_init, s),
        lat=pick(jnp.zeros_like(lat), lat),
        active=script.valid,
    )


def _where_slot(mask: Array, a: Array, b) -> Array:
    """``where(mask, a, b)`` with an (A,) slot mask broadcast over ``a``'s trailing axes."""
    return jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b)


def _idm_track(
    actors: ActorState, script: ActorScript, handed: Array, tau: Array, t_next: Array,
    t_event: Array, dt: float,
) -> tuple[Array, Array]:  # fmt: skip
    """An adversarial track acting on the IDM-driven slots during the tick ending at ``t_next``.

    Returns:
        ``track_accel`` (A,) m/s^2, the commanded acceleration of the tick, and ``lat`` (A,) m,
        the IDM slots' lateral offset at ``t_next``: the script's own (a handed-over actor's
        manoeuvre, closed form) plus the track's deviation, integrated with the actual speed
        (``w = gain * q``, :mod:`lantern_jax.dynamics.adversary`).
    """
    tr = script.track
    start = track_start(script.trigger, tau, t_event)
    t_prev = t_next - dt
    u = jnp.where(happened(start), t_prev - jnp.where(happened(start), start, 0.0), -1.0)
    accel, q_now = jax.vmap(commanded)(tr.accel, tr.q, tr.knot_s, u)
    base = jax.vmap(scripted_arc, in_axes=(0, None, 0))
    motion = ScriptedMotion.of(script)
    base_prev = jnp.where(handed, base(motion, t_prev, tau)[1], 0.0)
    base_next = jnp.where(handed, base(motion, t_next, tau)[1], 0.0)
    gain = jnp.where(tr.holonomic, 1.0, jnp.maximum(actors.speed, 0.0))
    return accel, base_next + (actors.lat - base_prev) + dt * gain * q_now


def step_actors(
    actors: ActorState,
    script: ActorScript,
    t_next: Array,
    t_event: Array,
    light_state: Array,
    ego_xy: Array,
    ego_yaw: Array,
    ego_speed: Array,
    dt: float = DT,
    idm_params: IDMParams = DEFAULT_IDM,
    ego_leader: str = DEFAULT_EGO_LEADER,
) -> ActorState:
    """Advance every actor of one scenario to time ``t_next``.

    Args:
        actors: current actor states, (A,) slots.
        script: what each slot is and how it moves, (A,) slots.
        t_next: () float32, s, time of the new state (scripted poses are closed form in it).
        t_event: () float32, s, physical event onset (``INF_TIME`` while pending).
        light_state: (T,) int32, LIGHT_* state of every traffic light at this tick.
        ego_xy: (2,) float32, m, world-frame ego box centre.
        ego_yaw: () float32, rad, ego heading.
        ego_speed: () float32, m/s, ego speed (>= 0).
        dt: s, tick used to integrate the IDM actors.
        idm_params: IDM parameters of the IDM actors.
        ego_leader: how an IDM actor finds the ego as its leader, one of
            :data:`EGO_LEADER_RULES` (static; :class:`ActorSettings`).

    Returns:
        The actors at ``t_next`` (``xy``, ``yaw``, ``speed``, ``s``, ``lat``, ``active``); slots
        that are not present are returned unchanged.
    """
    valid = script.valid
    is_present = present(script, actors)
    clean = jax.tree.map(lambda x: _zero_where_invalid(x, valid), actors)
    script = jax.tree.map(lambda x: _zero_where_invalid(x, valid), script)
    t_next = jnp.asarray(t_next, jnp.float32)

    sc_s, sc_lat, sc_speed, sc_xy, sc_yaw, sc_active = scripted_states(script, t_next, t_event)

    # Hand-over: scripted actors whose manoeuvre is over continue as IDM traffic.
    tau = trigger_time(script.trigger, script.trigger_delay, t_event, script.trigger_deadline)
    handed = (
        (script.motion == MOTION_SCRIPTED)
        & happened(tau)
        & (t_next >= jnp.where(happened(tau), tau, 0.0) + script.handover_after)
    )
    is_idm = (script.motion == MOTION_IDM) | handed
    idm_script = script.replace(v_pre=jnp.where(handed, script.v_post, script.v_pre))

    # IDM: integrate along the path (a handed-over actor's lateral offset keeps following its
    # script in time, i.e. stays at lat_shift once its manoeuvre is over)
    track_accel, track_lat = None, None
    if script.track is not None:
        track_accel, track_lat = _idm_track(clean, script, handed, tau, t_next, t_event, dt)
    id_s, id_speed, id_active = _idm_update(
        clean, idm_script, is_present, light_state, ego_xy, ego_yaw, ego_speed, dt, idm_params,
        track_accel, ego_leader,
    )  # fmt: skip
    id_pt, id_yaw = jax.vmap(interpolate)(script.path, script.path_s, script.path_valid, id_s)
    id_lat = jnp.where(handed, sc_lat, 0.0) if track_lat is None else track_lat
    id_xy = id_pt + left_normal(id_yaw) * id_lat[:, None]

    s = jnp.where(is_idm, id_s, sc_s)
    lat = jnp.where(is_idm, id_lat, sc_lat)
    speed = jnp.where(is_idm, id_speed, sc_speed)
    xy = jnp.where(is_idm[:, None], id_xy, sc_xy)
    yaw = jnp.where(is_idm, id_yaw, sc_yaw)
    active = actors.active & jnp.where(is_idm, id_active, sc_active)

    def keep(new, old):
        mask = is_present.reshape(is_present.shape + (1,) * (old.ndim - 1))
        return jnp.where(mask, new.astype(old.dtype), old)

    return actors.replace(
        xy=keep(xy, actors.xy),
        yaw=keep(yaw, actors.yaw),
        speed=keep(speed, actors.speed),
        s=keep(s, actors.s),
        lat=keep(lat, actors.lat),
        active=keep(active, actors.active),
    )
