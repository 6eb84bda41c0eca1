"""One 20 Hz tick of one scenario execution, as a short composition of stages.

Order inside a tick (time ``t`` -> ``t + DT``), each stage owned by its layer:

1. **policy** — the policy reads the observation of ``t`` (:mod:`lantern_jax.sim.observe`) and
   returns 10 waypoints;
2. **ego** — controller and bicycle (:func:`lantern_jax.dynamics.controller.follow_plan`);
   non-finite waypoints are a controller fault (full braking, recorded), never propagated;
3. **protocol, before the actors** — warning point, anti-deadlock countdown (paused while a light
   or a queue holds the ego) and event onset, with sub-tick times
   (:mod:`lantern_jax.scenarios.protocol`);
4. **actors** — scripted actors (closed form, triggered by the event), IDM traffic and lights
   (:mod:`lantern_jax.dynamics.actors`);
5. **sensing** — front camera and route place (:mod:`lantern_jax.sim.sense`);
6. **protocol, after sensing** — warning termination, clearance, onset bookkeeping, and the
   removal of a cleared hazard;
7. **measurement** — a :class:`~lantern_jax.scoring.sample.TickSample` folded into the telemetry
   (:mod:`lantern_jax.scoring.measure`), and whether the execution has ended.

An execution that has ended is frozen: its state no longer changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax

from lantern_jax.constants import DT
from lantern_jax.dynamics.actors import step_actors
from lantern_jax.dynamics.controller import follow_plan
from lantern_jax.dynamics.lights import ego_light_state, light_holds_ego, light_states
from lantern_jax.observation import corridor_gaps
from lantern_jax.scenarios import protocol
from lantern_jax.scoring.measure import execution_ended, justified_stop, measure
from lantern_jax.scoring.telemetry import update_telemetry
from lantern_jax.sim.observe import observe
from lantern_jax.sim.record import TickRecord, tick_record
from lantern_jax.sim.sense import locate_on_route, sense
from lantern_jax.sim.state import State, freeze
from lantern_jax.sim.switch import PolicySwitch
from lantern_jax.world import Scenario, present

Array = jax.Array
ActFn = Callable[[Any, Any], Array]


def step(
    act: ActFn,
    policy_params: Any,
    scenario: Scenario,
    state: State,
    temperature: Array,
    privileged: bool = False,
) -> tuple[State, TickRecord]:
    """Advance one execution by one tick (see the module docstring for the stages).

    Args:
        act: the policy's ``act(policy_params, obs) -> (10, 2)`` waypoints, or a
            :class:`~lantern_jax.sim.switch.PolicySwitch` of several (``policy_params`` then
            :class:`~lantern_jax.sim.switch.SwitchParams`).
        policy_params: the policy's parameters.
        scenario: the execution's static scenario (closed over by the caller's scan).
        state: the state at the start of the tick.
        temperature: () float32, soft-score temperature of the telemetry's smooth accumulators.
        privileged: static; the policy reads ``obs.privileged`` (``Policy.privileged``); also
            on whenever ``act`` carries a true ``privileged`` attribute (the expert's does).
            Likewise ``act.surround`` asks for the six-camera rig (``Observation.surround``).

    Returns:
        (the state at the end of the tick — ``state`` itself when it had already ended,
        the tick's record for plots).
    """
    cfg, script, h = scenario.config, scenario.actors, scenario.config.hazard_index
    # A privileged act function says so itself (``act.privileged``), so no caller can forget it.
    if isinstance(act, PolicySwitch):
        # Several policies in one program: the chosen member's branch adds what it reads.
        obs = observe(scenario, state, False, False)
        waypoints = act.choose(policy_params, obs, scenario, state)
        privileged = act.any_privileged
    else:
        privileged = privileged or bool(getattr(act, "privileged", False))
        obs = observe(scenario, state, privileged, bool(getattr(act, "surround", False)))
        waypoints = act(policy_params, obs)
    if privileged:
        # Shields the expert's plan from the algebraic simplifier; on CPU the barrier is
        # expanded before fusion (see lantern_jax.split_map).
        waypoints = jax.lax.optimization_barrier(waypoints)
    ego, fault, plan = follow_plan(state.ego, waypoints, cfg.friction)
    t = state.t + DT

    arc, dist, progress = locate_on_route(scenario.route, ego.xy, state.percept.progress)
    light = ego_light_state(scenario.lights, cfg.ego_light, t)
    gap, lateral = corridor_gaps(obs)
    present_before = present(script, state.actors)
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
    proto = protocol.record_onset(proto, state.protocol, cfg, hazard_visible, obs.warning_active)
    actors = protocol.despawn_cleared(actors, proto, cfg)

    justified = justified_stop(
        light_holds_ego(light, cfg.ego_stop_s - arc), gap, lateral, present_before,
        scenario.route.length - arc,
    )  # fmt: skip
    sample = measure(
        scenario, ego, actors, present(script, actors), proto, t, progress, dist,
        state.percept.route_arc, arc, light, justified, fault,
    )  # fmt: skip
    new = State(
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
    return new, tick_record(scenario, new, obs, plan, light, live=~state.done)
