"""One 20 Hz tick of one scenario execution: the policy's part and the world's part.

A tick (time ``t`` -> ``t + DT``) is two functions composed by :func:`step`:

* **observe and act** (:func:`policy_waypoints`) — the simulator builds the observation of
  ``t`` from the policy's declared sensors (:func:`lantern_jax.sim.observe.observe`) and the
  policy returns 10 waypoints and its new carry;
* **transition** (:func:`transition`) — the world advances under those waypoints, reading only
  the ground truth, never an observation:

  1. **ego** — controller and bicycle (:func:`lantern_jax.dynamics.controller.follow_plan`);
     an unusable plan (non-finite, or faster than ``MAX_PLAN_SPEED``) is a controller fault
     (full braking, recorded), never propagated;
  2. **protocol, before the actors** — warning point, anti-deadlock countdown (paused while a
     light or a queue holds the ego) and event onset, with sub-tick times
     (:mod:`lantern_jax.sim.protocol`);
  3. **actors** — scripted actors (closed form, triggered by the event), IDM traffic and lights
     (:mod:`lantern_jax.dynamics.actors`);
  4. **sensing** — front camera and route place (:mod:`lantern_jax.sim.sense`);
  5. **protocol, after sensing** — warning termination, clearance, onset bookkeeping, and the
     removal of a cleared hazard;
  6. **measurement** — a :class:`~lantern_jax.scoring.sample.TickSample` folded into the
     telemetry (:mod:`lantern_jax.scoring.measure`), and whether the execution has ended.

An execution that has ended is frozen: its state (the policy's carry included) no longer
changes.  The brax environment (:mod:`lantern_jax.apps.envs.env`) drives :func:`transition`
directly with its own actions.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import DT
from lantern_jax.dynamics.actors import step_actors
from lantern_jax.dynamics.controller import follow_plan
from lantern_jax.dynamics.lights import ego_light_state, light_states
from lantern_jax.policies.base import Policy
from lantern_jax.scoring.measure import TickEnd, execution_ended, justified_stop, measure
from lantern_jax.scoring.telemetry import update_telemetry
from lantern_jax.sim import protocol
from lantern_jax.sim.observe import actors_in_ego_frame, delivered_warning, observe, route_ahead
from lantern_jax.sim.record import TickRecord, tick_record
from lantern_jax.sim.sense import locate_on_route, sense
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.state import State, freeze
from lantern_jax.sim.switch import PolicySwitch
from lantern_jax.types.observation import corridor_gaps
from lantern_jax.types.world import ActorState, EgoState, ProtocolState, Scenario, present

Array = jax.Array
Driver = Policy | PolicySwitch


def policy_waypoints(
    policy: Driver,
    policy_params: Any,
    scenario: Scenario,
    state: State,
    settings: Settings = DEFAULT_SETTINGS,
) -> tuple[Array, Any]:
    """The policy's part of a tick: its observation of ``state`` and its answer.

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` (its ``sensors`` decide the
            observation) or a :class:`~lantern_jax.sim.switch.PolicySwitch` of several
            (``policy_params`` then :class:`~lantern_jax.sim.switch.SwitchParams`).
        policy_params: the policy's parameters.
        scenario: the execution's static scenario.
        state: the state at the start of the tick (``state.policy_carry`` is the policy's).
        settings: the simulation's settings (the warning texts the observation reads).

    Returns:
        ((10, 2) float32 waypoints, ego frame; the policy's new carry).
    """
    if isinstance(policy, PolicySwitch):
        waypoints, carry = policy.choose(
            policy_params, state.policy_carry, scenario, state, settings.bank
        )
        privileged = policy.any_privileged
    else:
        obs = observe(scenario, state, policy.sensors, settings.bank)
        waypoints, carry = policy.step(policy_params, state.policy_carry, obs)
        privileged = policy.privileged
    waypoints = jnp.asarray(waypoints, jnp.float32)
    if privileged:
        # Shields the expert's plan from the algebraic simplifier; on CPU the barrier is
        # expanded before fusion (see lantern_jax.maths.split_map).
        waypoints = jax.lax.optimization_barrier(waypoints)
    return waypoints, carry


@struct.dataclass
class TickParts:
    """Every intermediate of the world's part of one tick (one execution): what each stage of
    :data:`TRANSITION_STAGES` reads from the earlier ones and adds (None until its stage ran).
    """

    waypoints: Array  # (10, 2) float32, m, ego frame: the policy's plan
    warning: tuple | None = None  # delivered now: (active () bool, text id () int32, (2,) pos)
    # ego stage
    ego: EgoState | None = None  # the ego at the end of the tick
    fault: Array | None = None  # () bool, the plan was unusable (a controller fault)
    plan: Array | None = None  # (10, 2) float32, m, the plan the controller followed
    t: Array | None = None  # () float32, s, time at the end of the tick
    arc: Array | None = None  # () float32, m, the ego's route arc at the end of the tick
    dist: Array | None = None  # () float32, m, ego centre distance from the route
    progress: Array | None = None  # () float32, m, furthest route arc reached
    light: Array | None = None  # () int32, LIGHT_* state of the ego's light at ``t``
    # protocol before the actors
    gap: Array | None = None  # (A,) float32, m, route gap from the ego front to each actor
    lateral: Array | None = None  # (A,) float32, m, actor distance from the route - half size
    present_before: Array | None = None  # (A,) bool, actors present at the start of the tick
    light_holds: Array | None = None  # () bool, a red/yellow light holds the ego
    proto: ProtocolState | None = None  # protocol state (markers, then the hazard's)
    # actors, sensing, measurement
    actors: ActorState | None = None  # the actors at the end of the tick
    percept: Any = None  # the sensing of the new tick (:func:`lantern_jax.sim.sense.sense`)
    telemetry: Any = None  # the telemetry with the tick folded in
    done: Array | None = None  # () bool, the execution has ended


def _stage_ego(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """Controller and bicycle under the waypoints; the route place and light at the new time."""
    ego, fault, plan = follow_plan(st.ego, x.waypoints, sc.config.friction)
    t = st.t + DT
    arc, dist, progress = locate_on_route(sc.route, ego.xy, st.percept.progress)
    light = ego_light_state(sc.lights, sc.config.ego_light, t)
    return x.replace(ego=ego, fault=fault, plan=plan, t=t, arc=arc, dist=dist, progress=progress,
                     light=light)  # fmt: skip


def _stage_markers(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """Warning point, anti-deadlock countdown and event onset (the actors as at the start)."""
    cfg = sc.config
    route, _ = route_ahead(sc, st)
    truth = actors_in_ego_frame(sc, st)
    gap, lateral = corridor_gaps(
        route, truth["actor_xy"], truth["actor_dir"], truth["actor_extent"]
    )
    light_holds = settings.protocol.light_holds(x.light, cfg.ego_stop_s - x.arc)
    held = protocol.ego_held(
        x.light, cfg.ego_stop_s - x.arc, gap, lateral, truth["present"], sc.actors.role,
        st.actors.speed, settings.protocol,
    )  # fmt: skip
    proto = protocol.advance_markers(st.protocol, cfg, x.t, st.percept.progress, x.progress, held)
    return x.replace(gap=gap, lateral=lateral, present_before=truth["present"],
                     light_holds=light_holds, proto=proto)  # fmt: skip


def _stage_actors(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """Scripted actors, IDM traffic and lights."""
    ego = x.ego
    actors = step_actors(
        st.actors, sc.actors, x.t, x.proto.t_event, light_states(sc.lights, x.t),
        ego.xy, ego.yaw, ego.speed, ego_leader=settings.actors.ego_leader,
    )  # fmt: skip
    return x.replace(actors=actors)


def _stage_sense(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """Front camera and route place of the new tick."""
    return x.replace(percept=sense(sc, x.ego, x.actors, x.arc, x.dist, x.progress))


def _stage_hazard(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """Warning termination, clearance, onset bookkeeping, removal of a cleared hazard."""
    cfg, h, actors = sc.config, sc.config.hazard_index, x.actors
    visible = x.percept.visible[h] & present(sc.actors, actors)[h]
    proto = protocol.advance_hazard(
        x.proto, cfg, x.t, visible, actors.s[h], x.ego.speed, settings.protocol
    )
    warning_active = x.warning[0]
    proto = protocol.record_onset(proto, st.protocol, cfg, visible, warning_active)
    return x.replace(proto=proto, actors=protocol.despawn_cleared(actors, proto, cfg))


def _stage_measure(sc: Scenario, st: State, x: TickParts, settings: Settings) -> TickParts:
    """The tick's measurement folded into the telemetry, and whether the execution ended."""
    s = settings.scoring
    justified = justified_stop(
        x.light_holds, x.gap, x.lateral, x.present_before, sc.route.length - x.arc, s
    )
    end = TickEnd(
        ego=x.ego, actors=x.actors, present=present(sc.actors, x.actors), protocol=x.proto,
        t=x.t, progress=x.progress, dist_to_route=x.dist, arc_before=st.percept.route_arc,
        arc_now=x.arc, light=x.light, justified=justified, fault=x.fault,
    )  # fmt: skip
    sample = measure(sc, end, s)
    ended = execution_ended(sc, x.t, x.progress, x.dist, x.proto.ego_still_time, s)
    return x.replace(telemetry=update_telemetry(st.telemetry, sample, s), done=ended)


#: The world's stages of a tick, in order: ``(label, stage(scenario, state, parts, settings) ->
#: parts)``, each reading what the earlier ones put into the :class:`TickParts`
#: (``benchmarks/profile_tick.py`` times them one by one).
TRANSITION_STAGES = (
    ("controller + bicycle + route place", _stage_ego),
    ("protocol before the actors", _stage_markers),
    ("actors (IDM, scripts, lights)", _stage_actors),
    ("sensing (visibility, range image)", _stage_sense),
    ("protocol after sensing", _stage_hazard),
    ("measurement + telemetry + end test", _stage_measure),
)


def transition_outputs(
    scenario: Scenario, state: State, waypoints: Array, settings: Settings = DEFAULT_SETTINGS
) -> TickParts:
    """Every intermediate of the world's part of a tick (:data:`TRANSITION_STAGES` in order)."""
    x = TickParts(waypoints=waypoints,
                  warning=delivered_warning(scenario, state, settings.bank))  # fmt: skip
    for _, stage in TRANSITION_STAGES:
        x = stage(scenario, state, x, settings)
    return x


def transition(
    scenario: Scenario, state: State, waypoints: Array, settings: Settings = DEFAULT_SETTINGS
) -> tuple[State, TickRecord]:
    """The world's part of a tick: advance one execution under ``waypoints`` (see the module
    docstring for the stages).  The policy's carry is left as it was.

    Args:
        scenario: the execution's static scenario (closed over by the caller's scan).
        state: the state at the start of the tick.
        waypoints: (10, 2) float32, m, ego frame (x forward, y right), 0.25 s apart.
        settings: scoring, protocol and text bank (:class:`~lantern_jax.sim.settings.Settings`).

    Returns:
        (the state at the end of the tick — ``state`` itself when it had already ended,
        the tick's record for plots).
    """
    x = transition_outputs(scenario, state, waypoints, settings)
    new = state.replace(
        t=x.t,
        tick=state.tick + 1,
        ego=x.ego,
        actors=x.actors,
        protocol=x.proto,
        percept=x.percept,
        telemetry=x.telemetry,
        done=x.done,
        fault=state.fault | x.fault,
    )
    new = freeze(state, new)
    rec = tick_record(scenario, new, x.warning, x.plan, x.light, live=~state.done)
    return new, rec


def step(
    policy: Driver,
    policy_params: Any,
    scenario: Scenario,
    state: State,
    settings: Settings = DEFAULT_SETTINGS,
) -> tuple[State, TickRecord]:
    """Advance one execution by one tick: :func:`policy_waypoints`, then :func:`transition`.

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` or a
            :class:`~lantern_jax.sim.switch.PolicySwitch`.
        policy_params: the policy's parameters.
        scenario: the execution's static scenario (closed over by the caller's scan).
        state: the state at the start of the tick.
        settings: scoring, protocol and text bank (:class:`~lantern_jax.sim.settings.Settings`).

    Returns:
        (the state at the end of the tick — ``state`` itself when it had already ended,
        the tick's record for plots).
    """
    waypoints, carry = policy_waypoints(policy, policy_params, scenario, state, settings)
    new, rec = transition(scenario, state, waypoints, settings)
    kept = jax.tree.map(lambda n, o: jnp.where(state.done, o, n), carry, state.policy_carry)
    return new.replace(policy_carry=kept), rec
