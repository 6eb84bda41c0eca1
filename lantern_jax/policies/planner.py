"""A rule-based planner in the spirit of PDM-Lite, shared by the reference policies.

One function, :func:`plan`, turns an :class:`Observation` and a perception mask into the 10
ego-frame waypoints (0.25 s apart) that every policy returns.  What the planner may see is the
only difference between the reference policies:

* ``expert`` — all present actors (privileged, hidden ones included);
* ``ego`` — only what the front camera sees now;
* ``coop`` — ``ego`` plus the cooperative warning, turned into a virtual constraint.

Longitudinal logic (reference/parameters.md, PDM-Lite):

* the target speed is the route reference speed, capped by a curvature limit
  (``v <= sqrt(a_lat / kappa)`` with comfortable braking to reach it);
* every constraint ahead — a leader in the route corridor, an actor whose constant-velocity
  forecast over 2 s overlaps the ego's corridor (treated as a stopped obstacle at the overlap),
  a red/yellow light at the stop line, a pedestrian close to the corridor (caution) — becomes an
  IDM "leader"; the commanded acceleration is the minimum over the IDM accelerations;
* the speed profile is integrated over the 2.5 s horizon (constraints re-evaluated each
  0.25 s step) and the waypoints are the route centre-line points at the resulting arc lengths.

Simplifications (documented): no lateral evasion (the planner stays on the route centre line,
as PDM-Lite does), forecasts are constant-velocity, and a forecast overlap is handled by
stopping before the overlap point rather than by yielding gaps.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.core.constants import (
    BIG,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    KIND_PEDESTRIAN,
    LIGHT_GREEN,
    LIGHT_YELLOW,
    NUM_WAYPOINTS,
    WAYPOINT_DT,
)
from lantern_jax.maths.polyline import project_uniform
from lantern_jax.types.observation import ROUTE_STEP, Observation

Array = jax.Array


@struct.dataclass
class PlannerConfig:
    """The planner's parameters: a pytree inside the reference policies' parameters, so a
    changed value is an argument of the compiled program (sweepable and differentiable);
    ``forecast_steps`` is static (a shape)."""

    idm_a: Array  # () m/s^2, IDM maximum acceleration
    idm_b: Array  # () m/s^2, IDM comfortable deceleration
    idm_s0: Array  # () m, IDM standstill gap to leaders and obstacles
    idm_T: Array  # () s, IDM time headway
    light_s0: Array  # () m, standstill gap to the stop line
    max_brake: Array  # () m/s^2, deceleration limit of the plan
    lat_accel: Array  # () m/s^2, comfortable lateral acceleration in curves
    corridor_margin: Array  # () m, lateral margin added to the ego half width
    forecast_margin: Array  # () m, margin of the forecast-overlap test
    ped_caution_dist: Array  # () m, pedestrians within this of the corridor edge ...
    ped_caution_speed: Array  # () m/s, ... cap the speed to this
    yield_setback: Array  # () m, distance before the turn entry at which a yield stop is held
    forecast_dt: Array = 0.5  # s between the constant-velocity forecast steps
    moving_speed: Array = 0.3  # m/s, an actor slower than this is not forecast
    ped_caution_range: Array = 30.0  # m ahead within which pedestrians cap the speed
    ped_s0: Array = 2.0  # m, standstill gap behind a forecast overlap
    stop_s0: Array = 1.0  # m, standstill gap to a virtual stop (route end, warning stop)
    turn_threshold: Array = 0.3  # rad, heading change that marks a turn entry ahead
    cut_in_setback: Array = 4.9  # m, a warned cut-in is held this far behind its position
    cut_in_s0: Array = 2.0  # m, standstill gap to a warned cut-in
    match_radius: Array = 3.0  # m, a seen actor this close to a warned position gives its speed
    forecast_steps: int = struct.field(pytree_node=False, default=5)  # 0 .. 2.0 s at 0.5 s


def default_planner_config() -> PlannerConfig:
    """Defaults from PDM-Lite where it is specific (reference/parameters.md)."""
    f = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    return PlannerConfig(
        idm_a=f(2.0),
        idm_b=f(3.5),
        idm_s0=f(4.0),
        idm_T=f(0.5),
        light_s0=f(1.5),
        max_brake=f(8.0),
        lat_accel=f(2.5),
        corridor_margin=f(0.6),
        forecast_margin=f(0.6),
        ped_caution_dist=f(2.5),
        ped_caution_speed=f(5.0),
        yield_setback=f(3.0),
        forecast_dt=f(0.5),
        moving_speed=f(0.3),
        ped_caution_range=f(30.0),
        ped_s0=f(2.0),
        stop_s0=f(1.0),
        turn_threshold=f(0.3),
        cut_in_setback=f(2.0 * 2.45),  # two vehicle half lengths
        cut_in_s0=f(2.0),
        match_radius=f(3.0),
    )


# ---------------------------------------------------------------------------------------------
# route helpers (route = (N, 2) ego-frame points, ROUTE_STEP apart, arc 0 at the first point)
# ---------------------------------------------------------------------------------------------
def project_on_route(route: Array, q: Array) -> tuple[Array, Array]:
    """Project one point onto the observed route
    (:func:`lantern_jax.maths.polyline.project_uniform`)."""
    arc, dist = project_uniform(route, ROUTE_STEP, q[None, :])
    return arc[0], dist[0]


def route_tangent(route: Array, arc: Array) -> Array:
    """(2,) unit tangent of the route at ``arc``."""
    k = jnp.clip(jnp.floor(arc / ROUTE_STEP).astype(jnp.int32), 0, route.shape[0] - 2)
    d = route[k + 1] - route[k]
    return d / jnp.maximum(jnp.linalg.norm(d), 1e-6)


def route_point(route: Array, arc: Array) -> Array:
    """(2,) route point at ``arc`` (linear interpolation; linear extrapolation past the end)."""
    n = route.shape[0]
    k = jnp.clip(jnp.floor(arc / ROUTE_STEP).astype(jnp.int32), 0, n - 2)
    u = arc / ROUTE_STEP - k
    return route[k] + u * (route[k + 1] - route[k])


def turn_angles(d: Array, ref: Array) -> Array:
    """Unsigned angles (rad, in [0, pi]) between vectors ``d`` (..., 2) and ``ref`` (..., 2).

    ``atan2(|cross|, dot)``: the wrapped heading difference of the two directions, from one
    arctangent and no heading of its own (XLA on CPU calls a scalar math library for every
    trigonometric element).
    """
    cross = ref[..., 0] * d[..., 1] - ref[..., 1] * d[..., 0]
    dot = ref[..., 0] * d[..., 0] + ref[..., 1] * d[..., 1]
    return jnp.arctan2(jnp.abs(cross), dot)


def curvature_speed_limit(route: Array, lat_accel: Array, decel: Array) -> Array:
    """() m/s, the highest current speed from which every curve ahead can be taken comfortably."""
    d = route[1:] - route[:-1]
    dh = turn_angles(d[1:], d[:-1])  # heading change between consecutive segments
    kappa = dh / ROUTE_STEP  # (N-2,) 1/m
    v_curve = jnp.sqrt(lat_accel / jnp.maximum(kappa, 1e-4))
    arc = (jnp.arange(kappa.shape[0], dtype=jnp.float32) + 1.0) * ROUTE_STEP
    return jnp.min(jnp.sqrt(v_curve**2 + 2.0 * decel * arc))


def turn_entry_arc(route: Array, threshold: Array) -> Array:
    """() m, arc at which the route heading first deviates by > ``threshold`` rad (BIG: none)."""
    d = route[1:] - route[:-1]
    # angle(d, d[0]) > threshold, compared through its cosine (no arctangent per segment)
    dot = d[:, 0] * d[0, 0] + d[:, 1] * d[0, 1]
    norms = jnp.sqrt(jnp.sum(d * d, -1) * jnp.sum(d[0] * d[0]))
    turned = dot < jnp.cos(threshold) * norms
    arcs = jnp.arange(d.shape[0], dtype=jnp.float32) * ROUTE_STEP
    return jnp.min(jnp.where(turned, arcs, BIG))


# ---------------------------------------------------------------------------------------------
# constraints
# ---------------------------------------------------------------------------------------------
@struct.dataclass
class Constraints:
    """Obstacles along the route as IDM leaders: bumper gap and speed along the route."""

    gap: Array  # (K,) m, distance from the ego front to the obstacle's rear (BIG: none)
    speed: Array  # (K,) m/s, obstacle speed along the route
    s0: Array  # (K,) m, standstill gap to keep


def actor_constraints(
    p: PlannerConfig, obs: Observation, seen: Array, ego_speed: Array
) -> tuple[Constraints, Array]:
    """Leaders, forecast overlaps and pedestrian caution from the perceived actors.

    Args:
        p: planner parameters.
        obs: observation.
        seen: (A,) bool, which actors the planner may use.
        ego_speed: () m/s, ego speed used for the forecast.

    Returns:
        (constraints with K = 2A entries, caution speed cap () m/s).
    """
    route = obs.route
    hl, hw = obs.actor_extent[:, 0], obs.actor_extent[:, 1]
    # Footprint of the actor across / along the route (orientation aware).
    n_act = obs.actor_xy.shape[0]
    steps = p.forecast_steps
    taus = jnp.arange(steps, dtype=jnp.float32) * p.forecast_dt
    fut = obs.actor_xy[:, None, :] + obs.actor_vel[:, None, :] * taus[None, :, None]  # (A,F,2)
    arcs_all, dists_all = project_uniform(
        route, ROUTE_STEP, jnp.concatenate([obs.actor_xy, fut.reshape(-1, 2)], axis=0)
    )
    arc, dist = arcs_all[:n_act], dists_all[:n_act]
    f_arc = arcs_all[n_act:].reshape(n_act, steps)
    f_dist = dists_all[n_act:].reshape(n_act, steps)
    tang = jax.vmap(lambda s: route_tangent(route, s))(arc)
    cos = jnp.abs(jnp.sum(obs.actor_dir * tang, -1))
    # |cross| rather than sqrt(1 - cos^2): finite gradient for aligned actors.
    sin = jnp.abs(obs.actor_dir[:, 0] * tang[:, 1] - obs.actor_dir[:, 1] * tang[:, 0])
    half_across = hl * sin + hw * cos
    half_along = hl * cos + hw * sin

    # 1) current leaders in the corridor.
    in_corr = dist < EGO_HALF_WIDTH + half_across + p.corridor_margin
    ahead = arc > 0.0
    v_along = jnp.sum(obs.actor_vel * tang, -1)
    # An oncoming leader (moving against the route) is met where it will be at the end of the
    # forecast, treated as stopped there.
    horizon = (steps - 1) * p.forecast_dt
    oncoming = jnp.minimum(v_along, 0.0) * horizon
    lead_gap = jnp.where(seen & in_corr & ahead, arc - EGO_HALF_LENGTH - half_along + oncoming, BIG)

    # 2) constant-velocity forecast overlapping the ego's constant-speed corridor.
    ego_arc = ego_speed * taus  # (F,)
    lat_hit = f_dist < EGO_HALF_WIDTH + half_across[:, None] + p.forecast_margin
    lon_hit = jnp.abs(f_arc - ego_arc[None, :]) < (
        1.3 * EGO_HALF_LENGTH + half_along[:, None] + p.forecast_margin
    )
    moving = jnp.linalg.norm(obs.actor_vel, axis=-1) > p.moving_speed
    # Same-direction leaders in the corridor are handled by IDM; everything else moving
    # (crossing, oncoming, merging) is checked for a forecast overlap.
    follower = in_corr & (v_along >= 0.0)
    hit = lat_hit & lon_hit & (f_arc > 0.0) & moving[:, None] & ~follower[:, None]
    first_arc = jnp.min(jnp.where(hit, f_arc, BIG), axis=1)
    conflict_gap = jnp.where(
        seen & (first_arc < BIG * 0.5),
        first_arc - EGO_HALF_LENGTH - half_along - half_across,
        BIG,
    )

    # 3) pedestrian caution near the corridor.
    near = (
        seen
        & (obs.actor_kind == KIND_PEDESTRIAN)
        & ahead
        & (arc < p.ped_caution_range)
        & (dist < EGO_HALF_WIDTH + hw + p.ped_caution_dist + p.corridor_margin)
    )
    caution = jnp.where(jnp.any(near), p.ped_caution_speed, BIG)

    gap = jnp.concatenate([lead_gap, conflict_gap])
    speed = jnp.concatenate([jnp.maximum(v_along, 0.0), jnp.zeros_like(v_along)])
    s0 = jnp.concatenate([jnp.full_like(lead_gap, p.idm_s0), jnp.full_like(lead_gap, p.ped_s0)])
    return Constraints(gap=gap, speed=speed, s0=s0), caution


def light_constraint(p: PlannerConfig, obs: Observation) -> Constraints:
    """The ego's stop line as a stopped leader while its light is red (or yellow and stoppable)."""
    to_line = obs.dist_to_stop - EGO_HALF_LENGTH
    stoppable = to_line > obs.ego_speed**2 / (2.0 * p.idm_b * 1.5)
    stop = (obs.light_state != LIGHT_GREEN) & (to_line > -0.5)
    stop = stop & ((obs.light_state != LIGHT_YELLOW) | stoppable)
    gap = jnp.where(stop, jnp.maximum(to_line, 0.0), BIG)
    z = jnp.zeros((1,), jnp.float32)
    return Constraints(gap=gap[None], speed=z, s0=jnp.full((1,), p.light_s0))


def stop_constraint(p: PlannerConfig, arc: Array, active: Array) -> Constraints:
    """A virtual stopped obstacle whose rear is at ``arc`` m along the route (when ``active``)."""
    gap = jnp.where(active, jnp.maximum(arc - EGO_HALF_LENGTH, 0.0), BIG)
    return Constraints(gap=gap[None], speed=jnp.zeros((1,)), s0=jnp.full((1,), p.stop_s0))


def merge(*cs: Constraints) -> Constraints:
    """Concatenate constraint sets."""
    return jax.tree.map(lambda *xs: jnp.concatenate(xs), *cs)


def idm_accel(p: PlannerConfig, v: Array, v0: Array, c: Constraints) -> Array:
    """() m/s^2, the minimum IDM acceleration over free road and all constraints."""
    v0 = jnp.maximum(v0, 0.1)
    free = p.idm_a * (1.0 - (v / v0) ** 4)
    dv = v - c.speed
    s_star = c.s0 + v * p.idm_T + v * dv / (2.0 * jnp.sqrt(p.idm_a * p.idm_b))
    s_star = jnp.maximum(s_star, c.s0)
    gap = jnp.maximum(c.gap, 0.05)
    inter = jnp.where(c.gap < BIG * 0.5, p.idm_a * (1.0 - (v / v0) ** 4 - (s_star / gap) ** 2), BIG)
    return jnp.clip(jnp.minimum(free, jnp.min(inter)), -p.max_brake, p.idm_a)


def plan(
    p: PlannerConfig, obs: Observation, seen: Array, extra: Constraints | None = None
) -> tuple[Array, Array]:
    """Plan 10 ego-frame waypoints.

    Args:
        p: planner parameters.
        obs: observation of one scenario.
        seen: (A,) bool, the actors this planner may use.
        extra: additional constraints (e.g. from a warning).

    Returns:
        (waypoints (10, 2) float32 m, ego frame x forward / y right, 0.25 s apart;
         first-step acceleration () m/s^2 of the plan).
    """
    v = obs.ego_speed
    cons, caution = actor_constraints(p, obs, seen, v)
    cons = merge(cons, light_constraint(p, obs))
    # Route end: stop there.
    cons = merge(cons, stop_constraint(p, obs.dist_to_route_end + 2.0 * EGO_HALF_LENGTH, True))
    if extra is not None:
        cons = merge(cons, extra)
    v_target = jnp.minimum(obs.v_ref, curvature_speed_limit(obs.route, p.lat_accel, p.idm_b))
    v_target = jnp.minimum(v_target, caution)

    def step(carry, _):
        s, vel, c = carry
        a = idm_accel(p, vel, v_target, c)
        v_new = jnp.maximum(vel + a * WAYPOINT_DT, 0.0)
        ds = 0.5 * (vel + v_new) * WAYPOINT_DT
        moved = c.replace(
            gap=jnp.where(c.gap < BIG * 0.5, c.gap - ds + c.speed * WAYPOINT_DT, c.gap)
        )
        return (s + ds, v_new, moved), (s + ds, a)

    (_, _, _), (arcs, accs) = jax.lax.scan(step, (jnp.float32(0.0), v, cons), None, NUM_WAYPOINTS)
    wps = jax.vmap(lambda a: route_point(obs.route, a))(arcs)
    return wps.astype(jnp.float32), accs[0]
