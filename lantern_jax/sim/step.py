"""One 20 Hz tick of one scenario execution: the policy's part and the world's part.

A tick (time ``t`` -> ``t + DT``) is two functions composed by :func:`step`:

* **observe and act** (:func:`policy_waypoints`) — the simulator builds the observation of
  ``t`` from the policy's declared sensors (:func:`lantern_jax.sim.observe.observe`) and the
  policy returns 10 waypoints and its new carry;
* **transition** (:func:`transition`) — the world advances under those waypoints, reading only
  the ground truth, never an observation:

  1. **ego** — controller and bicycle (:func:`lantern_jax.dynamics.controller.follow_plan`);
     non-finite waypoints are a controller fault (full braking, recorded), never propagated;
  2. **protocol, before the actors** — warning point, anti-deadlock countdown (paused while a
     light or a queue holds the ego) and event onset, with sub-tick times
     (:mod:`lantern_jax.scenarios.protocol`);
  3. **actors** — scripted actors (closed form, triggered by the event), IDM traffic and lights
     (:mod:`lantern_jax.dynamics.actors`);
  4. **sensing** — front camera and route place (:mod:`lantern_jax.sim.sense`);
  5. **protocol, after sensing** — warning termination, clearance, onset bookkeeping, and the
     removal of a cleared hazard;
  6. **measurement** — a :class:`~lantern_jax.scoring.sample.TickSample` folded into the
     telemetry (:mod:`lantern_jax.scoring.measure`), and whether the execution has ended.

An execution that has ended is frozen: its state (the policy's carry included) no longer
changes.  The brax environment (:mod:`lantern_jax.envs.env`) drives :func:`transition`
directly with its own actions.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from lantern_jax.constants import DT
from lantern_jax.dynamics.actors import step_actors
from lantern_jax.dynamics.controller import follow_plan
from lantern_jax.dynamics.lights import ego_light_state, light_holds_ego, light_states
from lantern_jax.observation import corridor_gaps
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios import protocol
from lantern_jax.scoring.measure import execution_ended, justified_stop, measure
from lantern_jax.scoring.telemetry import update_telemetry
from lantern_jax.sim.observe import actors_in_ego_frame, delivered_warning, observe, route_ahead
from lantern_jax.sim.record import TickRecord, tick_record
from lantern_jax.sim.sense import locate_on_route, sense
from lantern_jax.sim.state import State, freeze
from lantern_jax.sim.switch import PolicySwitch
from lantern_jax.world import Scenario, present

Array = jax.Array
Driver = Policy | PolicySwitch


def policy_waypoints(
    policy: Driver, policy_params: Any, scenario: Scenario, state: State
) -> tuple[Array, Any]:
    """The policy's part of a tick: its observation of ``state`` and its answer.

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` (its ``sensors`` decide the
            observation) or a :class:`~lantern_jax.sim.switch.PolicySwitch` of several
            (``policy_params`` then :class:`~lantern_jax.sim.switch.SwitchParams`).
        policy_params: the policy's parameters.
        scenario: the execution's static scenario.
        state: the state at the start of the tick (``state.policy_carry`` is the policy's).

    Returns:
        ((10, 2) float32 waypoints, ego frame; the policy's new carry).
    """
    if isinstance(policy, PolicySwitch):
        waypoints, carry = policy.choose(policy_params, state.policy_carry, scenario, state)
        privileged = policy.any_privileged
    else:
        obs = observe(scenario, state, policy.sensors)
        waypoints, carry = policy.step(policy_params, state.policy_carry, obs)
        privileged = policy.privileged
    waypoints = jnp.asarray(waypoints, jnp.float32)
    if privileged:
        # Shields the expert's plan from the algebraic simplifier; on CPU the barrier is
        # expanded before fusion (see lantern_jax.split_map).
        waypoints = jax.lax.optimization_barrier(waypoints)
    return waypoints, carry


def transition(
    scenario: Scenario, state: State, waypoints: Array, temperature: Array
) -> tuple[State, TickRecord]:
    """The world's part of a tick: advance one execution under ``waypoints`` (see the module
    docstring for the stages).  The policy's carry is left as it was.

    Args:
        scenario: the execution's static scenario (closed over by the caller's scan).
        state: the state at the start of the tick.
        waypoints: (10, 2) float32, m, ego frame (x forward, y right), 0.25 s apart.
        temperature: () float32, soft-score temperature of the telemetry's smooth accumulators.

    Returns:
        (the state at the end of the tick — ``state`` itself when it had already ended,
        the tick's record for plots).
    """
    cfg, script, h = scenario.config, scenario.actors, scenario.config.hazard_index
    warned, text_id, warned_pos = delivered_warning(scenario, state)
    route, _ = route_ahead(scenario, state)
    truth = actors_in_ego_frame(scenario, state)
    ego, fault, plan = follow_plan(state.ego, waypoints, cfg.friction)
    t = state.t + DT

    arc, dist, progress = locate_on_route(scenario.route, ego.xy, state.percept.progress)
    light = ego_light_state(scenario.lights, cfg.ego_light, t)
    gap, lateral = corridor_gaps(
        route, truth["actor_xy"], truth["actor_dir"], truth["actor_extent"]
    )
    present_before = truth["present"]
    held = protocol.ego_held(
        light, cfg.ego_stop_s - arc, gap, lateral, present_before, script.role, state.actors.speed
    )
    proto = protocol.advance_markers(state.protocol, cfg, t, state.percept.progress, progress, held)

    actors = step_actors(
        state.actors, script, t, proto.t_event, light_states(scenario.lights, t),
        ego.xy, ego.yaw, ego.speed,
    )  # fmt: skip
    percept = sense(scenario, ego, actors, arc, dist, progress)

    hazard_visible = percept.visible[h] & present(script, actors)[h]
    proto = protocol.advance_hazard(proto, cfg, t, hazard_visible, actors.s[h], ego.speed)
    proto = protocol.record_onset(proto, state.protocol, cfg, hazard_visible, warned)
    actors = protocol.despawn_cleared(actors, proto, cfg)

    justified = justified_stop(
        light_holds_ego(light, cfg.ego_stop_s - arc), gap, lateral, present_before,
        scenario.route.length - arc,
    )  # fmt: skip
    sample = measure(
        scenario, ego, actors, present(script, actors), proto, t, progress, dist,
        state.percept.route_arc, arc, light, justified, fault,
    )  # fmt: skip
    new = state.replace(
        t=t,
        tick=state.tick + 1,
        ego=ego,
        actors=actors,
        protocol=proto,
        percept=percept,
        telemetry=update_telemetry(state.telemetry, sample, temperature),
        done=execution_ended(scenario, t, progress, dist, proto.ego_still_time),
        fault=state.fault | fault,
    )
    new = freeze(state, new)
    live = ~state.done
    rec = tick_record(scenario, new, (warned, text_id, warned_pos), plan, light, live=live)
    return new, rec


def step(
    policy: Driver,
    policy_params: Any,
    scenario: Scenario,
    state: State,
    temperature: Array,
) -> tuple[State, TickRecord]:
    """Advance one execution by one tick: :func:`policy_waypoints`, then :func:`transition`.

    Args:
        policy: a :class:`~lantern_jax.policies.base.Policy` or a
            :class:`~lantern_jax.sim.switch.PolicySwitch`.
        policy_params: the policy's parameters.
        scenario: the execution's static scenario (closed over by the caller's scan).
        state: the state at the start of the tick.
        temperature: () float32, soft-score temperature of the telemetry's smooth accumulators.

    Returns:
        (the state at the end of the tick — ``state`` itself when it had already ended,
        the tick's record for plots).
    """
    waypoints, carry = policy_waypoints(policy, policy_params, scenario, state)
    new, rec = transition(scenario, state, waypoints, temperature)
    kept = jax.tree.map(lambda n, o: jnp.where(state.done, o, n), carry, state.policy_carry)
    return new.replace(policy_carry=kept), rec
