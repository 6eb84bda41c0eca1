"""The components of the Cooperative Unified Score, one small module each (paper appendix
"Complete Cooperative Unified Score"), and :data:`COMPONENTS`, the one ordered table of them.

Every component measures one execution from running accumulators (no stored trajectory):
:mod:`lantern_jax.scoring.telemetry` folds the table's components side by side, in its order,
and :mod:`lantern_jax.scoring.metrics` / :mod:`lantern_jax.scoring.cus` compose their outputs.
The functions a component module provides depend on its *role* (:data:`ROLES`); within a role
they have one signature (``tests/test_scoring_components.py`` checks every module against it):

* every component: ``init(settings) -> State``, the accumulators before the first tick, and
  ``update(state, sample, tick, settings) -> State``, one tick folded; ``tick`` is the shared
  per-tick :class:`~lantern_jax.scoring.components.context.Tick` computed once by
  :func:`context.update <lantern_jax.scoring.components.context.update>`; and ``outputs(state,
  ctx, t_fail, settings) -> dict``, its fields of the per-execution
  :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (the names its module's ``OUTPUTS``
  lists; :func:`~lantern_jax.scoring.metrics.finalize` folds the table's outputs in order),
  and ``COLUMNS``, the route-table columns it measures (column -> route ``"A"``/``"B"`` and
  metrics field; empty where its only column is a score or a gate's pass flag);
* ``"hazard"`` (the four terms of ``S_A`` and ``T_A``): ``valid(state, ctx, t_fail)``, whether
  its window opened by the first Route A gate failure ``t_fail``; ``hard(state, ctx, t_fail) ->
  (value, valid)``, the hard measurement; ``soft(state, ctx, t_fail, temperature, settings,
  d_safe) -> (value, valid)``, the smooth score in [0, 1] that tends to the hard score as
  ``temperature -> 0`` (every term takes the scene's clearance normaliser ``d_safe``, which
  clearance reads); ``score_of(metrics, d_safe, settings)``, its score of Route A executions
  from their per-execution metrics (elementwise), named ``SCORE`` (``S_...``) among the pair
  components and in the route table; and the plain formula behind it, an elementwise
  ``score`` of the hard measurement with what that term needs (a threshold, ``d_safe``, the
  protocol times);
* ``"route_a_gate"``: ``failure_times(state, ctx, settings)``, the times it failed at (its part
  of ``t_fail``); ``hard(state, ctx, settings) -> (passed, valid)``; ``soft(state, ctx,
  temperature, settings) -> (pass probability, valid)``;
* ``"route_b_gate"``: ``hard`` and ``soft`` as a Route A gate (it fails no Route A execution,
  so it has no failure times);
* ``"diagnostic"``: ``init``, ``update`` and ``outputs`` only; its outputs are read by name (not a
  term of the CUS: no soft form, no weight).

``ctx`` is the final shared :class:`~lantern_jax.scoring.components.context.Context`.  Progress
``P`` needs no accumulator of its own (the context holds the route progress): ``progress.hard(ctx,
settings)`` and ``progress.soft(ctx, temperature, settings)``; :mod:`context` runs before every
component.

=================  =============  ==================================================================
module             role           component
=================  =============  ==================================================================
ttc                hazard         ``S_TTC``, time-to-collision over ``[t_ref, t_clear]``
clearance          hazard         ``S_clear``, minimum distance over ``[t_event, t_clear]``
anticipation       hazard         ``S_ant``, first sustained response (incl. coincident onset)
recovery           hazard         ``S_rec``, recovery latency after ``max(t_warn_off, t_clear)``
collision          route_a_gate   ``G_coll``
route_deviation    route_a_gate   ``G_road``
lane               route_a_gate   ``G_lane``
rule               route_a_gate   ``G_rule``
block              route_a_gate   ``G_block``: 20 s standstill, timeout, controller fault
false_brake        route_b_gate   ``G_FB``
efficiency         diagnostic     route completion time and unjustified slow time
progress           (context)      ``P``, route completion
context            (shared)       tick counter, rings, protocol times, ``v_pre``
=================  =============  ==================================================================

A new term of the benchmark itself is a module here and one entry of :data:`COMPONENTS`; its
state joins :class:`~lantern_jax.scoring.telemetry.Telemetry` under the entry's field name (the
test above checks both agree), its ``OUTPUTS`` fields of
:class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (checked when that module is imported:
every field has one owner), and its ``COLUMNS`` the route table's columns it measures
(column -> route ``"A"``/``"B"`` and field; checked against the result schema when
:mod:`lantern_jax.scoring.table` is imported).  A measurement of a user's own beside
the CUS needs none of this: :mod:`lantern_jax.scoring.user_metrics`.
"""

import dataclasses
from types import ModuleType

from lantern_jax.core.constants import ROUTE_A_GATE_FIELDS
from lantern_jax.scoring.components import (
    anticipation,
    block,
    clearance,
    collision,
    context,
    efficiency,
    false_brake,
    lane,
    progress,
    recovery,
    route_deviation,
    rule,
    ttc,
)

#: The roles of a component (what its module provides, see above).
ROLES = ("hazard", "route_a_gate", "route_b_gate", "diagnostic")


@dataclasses.dataclass(frozen=True)
class Component:
    """One entry of :data:`COMPONENTS`."""

    field: str  # its Telemetry field (and its module's name)
    module: ModuleType  # the functions of its role
    role: str  # one of ROLES
    symbol: str  # the paper's symbol ("" for a diagnostic)


#: Every component with accumulators, in the order the telemetry folds them and holds them.
#: (Their modules' reprs name this machine's paths, so the documentation leaves the value out.)
#:
#: :meta hide-value:
COMPONENTS: tuple[Component, ...] = (
    Component("ttc", ttc, "hazard", "S_TTC"),
    Component("clearance", clearance, "hazard", "S_clear"),
    Component("anticipation", anticipation, "hazard", "S_ant"),
    Component("recovery", recovery, "hazard", "S_rec"),
    Component("collision", collision, "route_a_gate", "G_coll"),
    Component("route_deviation", route_deviation, "route_a_gate", "G_road"),
    Component("lane", lane, "route_a_gate", "G_lane"),
    Component("rule", rule, "route_a_gate", "G_rule"),
    Component("block", block, "route_a_gate", "G_block"),
    Component("false_brake", false_brake, "route_b_gate", "G_FB"),
    Component("efficiency", efficiency, "diagnostic", ""),
)


def by_role(role: str) -> dict[str, ModuleType]:
    """The modules of the components of ``role``, by Telemetry field, in table order."""
    return {c.field: c.module for c in COMPONENTS if c.role == role}


#: The hazard components by Telemetry field (and availability key).
#:
#: :meta hide-value:
HAZARD_COMPONENTS = by_role("hazard")
#: The Route A gates by Telemetry field (the pass flag is ``"gate_" + field``), in failure-time
#: order: the order of their names in :data:`lantern_jax.core.constants.ROUTE_A_GATE_FIELDS`,
#: which the tables read without importing JAX.
#:
#: :meta hide-value:
ROUTE_A_GATES = by_role("route_a_gate")
if tuple(ROUTE_A_GATES) != ROUTE_A_GATE_FIELDS:
    raise AssertionError(f"Route A gates {tuple(ROUTE_A_GATES)} != {ROUTE_A_GATE_FIELDS}")

__all__ = [
    "COMPONENTS",
    "HAZARD_COMPONENTS",
    "ROLES",
    "ROUTE_A_GATES",
    "Component",
    "by_role",
    "anticipation",
    "block",
    "clearance",
    "collision",
    "context",
    "efficiency",
    "false_brake",
    "lane",
    "progress",
    "recovery",
    "route_deviation",
    "rule",
    "ttc",
]
