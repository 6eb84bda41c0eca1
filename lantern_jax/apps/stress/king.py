"""KING's recipe (Hanselmann et al., ECCV 2022) on this simulator's adversary tracks.

KING generates safety-critical scenarios by gradient descent through a differentiable proxy
simulator: every adversarial agent is driven by its own sequence of per-step actions (throttle
and steering at the simulator's 4 Hz, squashed by ``tanh``) through a kinematic bicycle model,
and Adam (step 0.005, betas 0.9/0.999, its state reset per route, at most 151 iterations)
minimises

    cost = w_ego_col * ego_col + w_adv_rd * adv_rd - w_adv_col * adv_col

with, per optimisation iteration (one rollout of the whole horizon):

* ``ego_col`` -- at every time step the distance between the ego's box and the **nearest**
  adversary's box, **averaged over the time steps** (pulls whichever adversary is nearest
  towards the ego over the whole episode, not only at its closest instant);
* ``adv_rd`` -- the mean over the time steps of the adversaries' overlap with the non-drivable
  area (a Gaussian kernel over a rasterised road map): stay on the road;
* ``adv_col`` -- the adversaries' least distance to each other, capped at 1.25 m (no collision
  among adversaries); its default weight is 0;

with the ego's actions **detached** (``detach_ego_path``): the gradient reaches the actions
through the adversaries' own motion only, the ego's reaction held as it was driven.  The search
for a route stops at its first collision.  Plausibility is judged afterwards (KING's
"solvability" check replays the scene with a privileged expert).

What this module keeps, and what it maps onto the project's parts:

* **the objective**: :func:`king_cost` -- ``ego_col`` from the watch's distance of the nearest
  watched actor (:class:`~lantern_jax.apps.stress.watch.Watch` ``near_sum`` / ``near_seen``:
  the time average over the ticks any of them is present; KING's adversaries are present
  throughout), plus
  ``adv_rd`` as the tracked actors' **soft share of the soft horizon spent off the road** (the
  watch's ``off_road_soft``, the same road rule the verification applies; a share in [0, 1]
  per actor rather than KING's raster overlap, whose scale depends on its pixel grid).
  ``adv_col`` is left out: its weight is 0 in KING's recipe, and the verification's rules
  already refuse adversaries that stop in the ego's path;
* **the detached ego**: the policy's plans are constants to differentiation
  (:func:`~lantern_jax.apps.stress.objective.held_plans`), so the ego drives as it reacts but
  the gradient flows through the adversaries' motion only;
* **no expert in the loop** (its part's weight 0), as in KING; every iterate is still verified
  by the same rules as every other method (the expert's margin, the road, the stops), which is
  KING's solvability check applied at each iteration;
* **the step**: Adam with KING's betas and step.  KING's parameters ``x`` give actions
  ``tanh(x)``; a track's normalised action here is ``2 sigmoid(z) - 1 = tanh(z / 2)``, so
  ``z = 2 x`` and KING's step 0.005 in ``x`` is :data:`KING_LR` = 0.01 in ``z``;
* **the actions**: the adversary tracks (:mod:`lantern_jax.dynamics.adversary`) with knots of
  :data:`KING_KNOT_S` (KING's 4 Hz) carry a commanded acceleration and a lateral target per
  step and actor.  This is **not** KING's free bicycle: a vehicle's heading is an offset from
  its scripted path (bounded by the kind's limits, moving at a bounded rate), which is the
  kinematic bicycle written relative to the path with the heading offset as the steering
  state; a free bicycle would need every world's actor state to be integrated tick by tick
  instead of evaluated in closed form.  The kinematic limits hold by construction, as KING's
  ``tanh`` bounds its actions;
* **restarts**: KING runs one descent per route from recorded non-critical actions; here each
  restart starts where the other descents do (:func:`~lantern_jax.apps.stress.search.
  initial_points`), so the methods of a comparison share their starting points.

:class:`~lantern_jax.apps.stress.search.KingSearch` runs it as the method ``"king"``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from lantern_jax.apps.stress.plausibility import CAP_M
from lantern_jax.core.constants import DT

Array = jax.Array

KING_LR = 0.01  # Adam step in z: KING's 0.005 on x, with z = 2 x (see the module docstring)
KING_BETAS = (0.9, 0.999)  # KING's Adam betas
KING_ITERATIONS = 151  # KING's optimisation steps per route (a budget in rollouts caps it here)
KING_KNOT_S = 0.25  # s, KING's action step (its simulator runs at 4 Hz)
W_EGO_COL = 1.0  # KING's weight on the ego-adversary distance
W_ADV_RD = 1.0  # KING's weight on leaving the drivable area
W_ADV_COL = 0.0  # KING's weight on adversary-adversary distance (0: the term is left out)


def king_cost(
    near_sum: Array, near_seen: Array, off_road_soft: Array, tracked: Array, horizon_s: float
) -> Array:
    """() KING's cost of one soft rollout from its watch (see the module docstring).

    Args:
        near_sum: () float32, m s, the box distance of the nearest watched actor present,
            integrated over the ticks any is present.
        near_seen: () float32, s, the time any watched actor was present.
        off_road_soft: (W,) float32, s, the soft time each watched actor spent off the road
            after its track's start.
        tracked: (W,) bool, which watched entries are tracked actors (each counted once).
        horizon_s: s, the soft rollout's horizon (the off-road time's denominator).

    Returns:
        ``W_EGO_COL * mean nearest distance + W_ADV_RD * sum_tracked off-road share``; with no
        watched actor ever present the distance counts as
        :data:`~lantern_jax.apps.stress.plausibility.CAP_M`.
    """
    ego_col = jnp.where(near_seen > 0.0, near_sum / jnp.maximum(near_seen, DT), CAP_M)
    adv_rd = jnp.sum(jnp.where(tracked, off_road_soft, 0.0)) / horizon_s
    return W_EGO_COL * ego_col + W_ADV_RD * adv_rd


def king_problem(problem):
    """The problem KING's recipe descends: the same pair, space, policy and watch, with KING's
    objective, no expert part and the policy's plans held (a
    :class:`~lantern_jax.apps.stress.objective.Problem`)."""
    return dataclasses.replace(problem, objective="king", expert_weight=0.0, hold_policy=True)
