"""Intelligent driver model (Treiber, Hennecke & Helbing 2000) for background traffic."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array

_MIN_GAP = 0.01  # m, gaps are floored here so that contact gives a huge (finite) braking term
_MIN_V0 = 1e-3  # m/s, desired speeds at or below this mean "stand still"


@struct.dataclass
class IDMParams:
    """IDM parameters (frozen; a pytree of float leaves, so they may be traced or vmapped).

    Defaults are those of the background vehicles.
    """

    s0: float = 2.0  # m, jam distance (bumper-to-bumper gap at standstill)
    time_headway: float = 1.2  # s, desired time headway T
    accel: float = 1.5  # m/s^2, maximum acceleration a
    decel: float = 2.0  # m/s^2, comfortable deceleration b
    delta: float = 4.0  # free-road exponent
    max_brake: float = 8.0  # m/s^2, physical braking limit the result is clipped to


DEFAULT_IDM = IDMParams()  # background-vehicle parameters


def desired_gap(v: Array, dv: Array, params: IDMParams = DEFAULT_IDM) -> Array:
    """IDM desired gap ``s* = s0 + max(0, v T + v dv / (2 sqrt(a b)))``.

    The dynamic part is floored at 0 (as in Treiber's formulation) so that a faster leader never
    makes the desired gap smaller than the jam distance.

    Args:
        v: (...) float32, m/s, own speed.
        dv: (...) float32, m/s, approach rate ``v - v_leader``.
        params: IDM parameters.

    Returns:
        (...) float32, m.
    """
    dyn = v * params.time_headway + v * dv / (2.0 * jnp.sqrt(params.accel * params.decel))
    return params.s0 + jnp.maximum(dyn, 0.0)


def free_road_term(v: Array, v0: Array, params: IDMParams = DEFAULT_IDM) -> Array:
    """``(v / v0)^delta`` (0 where ``v0 <= 0``); the default ``delta = 4`` uses two squarings."""
    moving = v0 > _MIN_V0
    ratio = jnp.abs(v / jnp.where(moving, v0, 1.0))
    if isinstance(params.delta, int | float) and float(params.delta) == 4.0:
        r2 = ratio * ratio
        return jnp.where(moving, r2 * r2, 0.0)
    return jnp.where(moving, ratio**params.delta, 0.0)


def interaction_term(v: Array, gap: Array, dv: Array, params: IDMParams = DEFAULT_IDM) -> Array:
    """``(s*(v, dv) / gap)^2`` with the gap floored at 0.01 m."""
    s_star = desired_gap(v, dv, params)
    return (s_star / jnp.maximum(gap, _MIN_GAP)) ** 2


def idm_from_terms(free: Array, inter: Array, v0: Array, params: IDMParams = DEFAULT_IDM) -> Array:
    """Combine the terms into the clipped IDM acceleration (full braking where ``v0 <= 0``)."""
    acc = params.accel * (1.0 - free - inter)
    acc = jnp.where(v0 > _MIN_V0, acc, -params.max_brake)
    return jnp.clip(acc, -params.max_brake, params.accel)


def idm_accel(v: Array, v0: Array, gap: Array, dv: Array, params: IDMParams = DEFAULT_IDM) -> Array:
    """IDM acceleration ``a (1 - (v / v0)^delta - (s* / gap)^2)``, clipped to physical limits.

    For several leaders, prefer ``idm_from_terms(free_road_term(v, v0), max over leaders of
    interaction_term(...), v0)``: the acceleration is monotone in the interaction term, so this
    equals the minimum over leaders without evaluating the free-road power per leader.

    Args:
        v: (...) float32, m/s, own speed (>= 0).
        v0: (...) float32, m/s, desired speed; ``v0 <= 0`` means stand still (full braking).
        gap: (...) float32, m, bumper-to-bumper gap to the leader (``BIG`` when there is none);
            floored at 0.01 m, so contact or overlap gives the braking limit.
        dv: (...) float32, m/s, ``v - v_leader`` (0 when there is no leader).
        params: IDM parameters.

    Returns:
        (...) float32, m/s^2, in ``[-params.max_brake, params.accel]``.
    """
    free = free_road_term(v, v0, params)
    return idm_from_terms(free, interaction_term(v, gap, dv, params), v0, params)
