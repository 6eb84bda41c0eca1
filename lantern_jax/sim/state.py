"""The dynamic state of one execution — the scan carry — and how it starts.

A rollout is ``State -> State`` under a fixed :class:`~lantern_jax.types.world.Scenario` (closed
over, never carried).  :func:`init_state` derives the first state from the scenario's initial
conditions; :func:`freeze` keeps an execution that has ended exactly as it was.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.scoring.telemetry import Telemetry, init_telemetry
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings
from lantern_jax.sim.sense import Percept, locate_on_route, sense
from lantern_jax.types.world import ActorState, EgoState, ProtocolState, Scenario, present

Array = jax.Array


@struct.dataclass
class State:
    """Everything that changes during one execution."""

    t: Array  # () float32, s, simulation clock
    tick: Array  # () int32, ticks since start
    ego: EgoState
    actors: ActorState
    protocol: ProtocolState
    percept: Percept  # sensing and route place of the current tick
    telemetry: Telemetry  # scoring accumulators
    done: Array  # () bool, the execution has ended (state frozen)
    fault: Array  # () bool, a controller fault happened at some tick
    #: the policy's memory (``Policy.init_carry``'s pytree; ``()`` for a stateless policy),
    #: reset with the rest of the state when an execution starts
    policy_carry: Any = ()


def init_state(
    scenario: Scenario, policy_carry: Any = (), scoring: ScoringSettings = DEFAULT_SCORING
) -> State:
    """The state at ``t = 0``: the scenario's initial ego and actors, sensed (a hazard seen
    already counts as seen before the warning point); empty telemetry (its ring lengths from
    ``scoring``); the policy's initial carry ``policy_carry``."""
    zero = jnp.asarray(0.0, jnp.float32)
    arc, dist, progress = locate_on_route(scenario.route, scenario.ego0.xy, zero)
    percept = sense(scenario, scenario.ego0, scenario.actors0, arc, dist, progress)
    h = scenario.config.hazard_index
    seen = percept.visible[h] & present(scenario.actors, scenario.actors0)[h]
    return State(
        t=zero,
        tick=jnp.asarray(0, jnp.int32),
        ego=scenario.ego0,
        actors=scenario.actors0,
        protocol=ProtocolState.initial().replace(hazard_seen_before_warn=seen),
        percept=percept,
        telemetry=init_telemetry(scoring),
        done=jnp.asarray(False),
        fault=jnp.asarray(False),
        policy_carry=policy_carry,
    )


def freeze(old: State, new: State) -> State:
    """``old`` unchanged where it had already ended, else ``new`` (one execution)."""
    return jax.tree.map(lambda n, o: jnp.where(old.done, o, n), new, old)
