"""The components of the Cooperative Unified Score, one small module each (paper appendix
"Complete Cooperative Unified Score").

Every component measures one execution from running accumulators (no stored trajectory) and
follows the same shape, so that :mod:`lantern_jax.scoring.telemetry` folds them side by side and
:mod:`lantern_jax.scoring.metrics` / :mod:`lantern_jax.scoring.cus` compose their outputs:

* ``init() -> State`` -- the accumulators before the first tick;
* ``update(state, sample, tick, temperature) -> State`` -- fold one tick; ``tick`` is the shared
  per-tick :class:`~lantern_jax.scoring.components.context.Tick` computed once by
  :func:`context.update <lantern_jax.scoring.components.context.update>`;
* ``hard(state, ctx[, t_fail]) -> (value, valid)`` -- the hard measurement (or gate pass flag)
  and whether it is available;
* ``soft(state, ctx[, t_fail], temperature) -> (value, valid)`` -- the smooth score in [0, 1]
  that tends to the hard score as ``temperature -> 0``, with the same (hard) validity.

``ctx`` is the final shared :class:`~lantern_jax.scoring.components.context.Context` and
``t_fail`` the first Route A gate failure (the hazard components are available only if their
window opened by then).  The four hazard components also have an elementwise ``score`` that maps
the hard measurement to ``[0, 1]``; progress is stateless (``hard(ctx)``, ``soft(ctx, T)``).

=================  ======================================================================
module             component
=================  ======================================================================
context            shared per-tick context: tick counter, rings, protocol times, v_pre
ttc                ``S_TTC``, time-to-collision over ``[t_ref, t_clear]``
clearance          ``S_clear``, minimum distance over ``[t_event, t_clear]``
anticipation       ``S_ant``, first sustained response (incl. the coincident-onset check)
recovery           ``S_rec``, recovery latency after ``max(t_warn_off, t_clear)``
progress           ``P``, route completion
collision          ``G_coll``
route_deviation    ``G_road``
lane               ``G_lane``
rule               ``G_rule``
block              ``G_block``: 20 s standstill, timeout, controller fault
false_brake        ``G_FB`` (Route B)
efficiency         route completion time and unjustified slow time: a diagnostic beside the
                   CUS, not a component of it (no soft form, no weight)
=================  ======================================================================
"""

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

# hazard components by Telemetry field (and availability key)
HAZARD_COMPONENTS = {"ttc": ttc, "clearance": clearance, "anticipation": anticipation,
                     "recovery": recovery}  # fmt: skip
# Route A gates by Telemetry field (the pass flag is ``"gate_" + name``), in failure-time order;
# each gate's module is named after its field
ROUTE_A_GATES = {name: globals()[name] for name in ROUTE_A_GATE_FIELDS}

__all__ = [
    "HAZARD_COMPONENTS",
    "ROUTE_A_GATES",
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
