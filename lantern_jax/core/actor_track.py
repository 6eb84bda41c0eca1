"""Adversarial tracks of the actor slots (:class:`ActorTrack`), a static part of a scenario's
:class:`~lantern_jax.types.world.ActorScript` (``ActorScript.track``; None = the scripts' motion
alone).  The closed form that turns a track into motion is in
:mod:`lantern_jax.dynamics.adversary`; stress testing searches the tracks
(:mod:`lantern_jax.apps.stress`)."""

from __future__ import annotations

import jax
import numpy as np
from flax import struct

from lantern_jax.core.checks import check_finite, check_nonneg, check_shape

Array = jax.Array


@struct.dataclass
class ActorTrack:
    """Adversarial tracks of the actor slots: bounded actions per knot after each actor's start.

    A track perturbs an actor's motion after its start (its trigger; for an actor that never
    triggers, the physical event) through a kinematic model, knot by knot (knot ``k`` covers
    ``[start + k h, start + (k + 1) h)``, ``h = knot_s``); see
    :mod:`lantern_jax.dynamics.adversary` for the closed form and
    :data:`lantern_jax.dynamics.adversary.KINEMATIC_LIMITS` for the limits (copied into each
    slot's ``*_max`` fields by the world builder).  Every field is data, so a track is searched,
    hashed (as part of a pair's parameters) and batched like any other scenario field.  All-zero
    actions leave the motion exactly as scripted.
    """

    accel: Array  # (A, N) float32, m/s^2, commanded longitudinal acceleration per knot
    lateral: Array  # (A, N) float32, lateral target per knot: m/s (sideways speed) for a
    #                 holonomic actor, rad (heading offset from the path) otherwise
    knot_s: Array  # (A,) float32, s, knot length h (> 0)
    v_max: Array  # (A,) float32, m/s, speed limit of the actor's kind
    a_max: Array  # (A,) float32, m/s^2, acceleration limit (IDM actors: of the total)
    b_max: Array  # (A,) float32, m/s^2, braking limit (> 0; IDM actors: of the total)
    lat_max: Array  # (A,) float32, bound of the lateral channel: m/s (lateral speed) for a
    #                 holonomic actor, rad (heading offset from the path) otherwise
    lat_rate: Array  # (A,) float32, its rate limit: m/s^2 or rad/s
    holonomic: Array  # (A,) bool, the lateral channel is a lateral velocity (walkers) rather
    #                   than a heading offset (vehicles: lateral speed = speed x offset)
    # the knot profile at the N action knots and the E return knots after them, derived from
    # the fields above (lantern_jax.dynamics.adversary.track_profile) and stored so that a
    # tick only interpolates it; P = N + E + 1 knot times
    dv: Array  # (A, P) float32, m/s, speed minus the start speed at the knots
    ds: Array  # (A, P) float32, m, its integral: extra arc at the knots
    q: Array  # (A, P) float32, lateral channel at the knots (m/s or rad)
    g: Array  # (A, P) float32, lateral gain at the knots (1, or the speed in m/s)
    dlat: Array  # (A, P) float32, m, extra lateral offset at the knots

    @property
    def knots(self) -> int:
        """Static number of knots N."""
        return self.accel.shape[-1]

    def validate(self, n: int) -> ActorTrack:
        a = check_shape("ActorTrack.accel", self.accel, (n, None))
        check_shape("ActorTrack.lateral", self.lateral, a.shape)
        for f in ("accel", "lateral", "knot_s", "v_max", "a_max", "b_max", "lat_max", "lat_rate"):
            if f not in ("accel", "lateral"):
                check_shape(f"ActorTrack.{f}", getattr(self, f), (n,))
            check_finite(f"ActorTrack.{f}", getattr(self, f))
        check_shape("ActorTrack.holonomic", self.holonomic, (n,))
        profile = check_shape("ActorTrack.dv", self.dv, (n, None))
        if profile.shape[1] < a.shape[1] + 1:
            raise ValueError("ActorTrack.dv: the profile needs more knot times than actions")
        for f in ("dv", "ds", "q", "g", "dlat"):
            check_shape(f"ActorTrack.{f}", getattr(self, f), profile.shape)
            check_finite(f"ActorTrack.{f}", getattr(self, f))
        for f in ("v_max", "a_max", "b_max", "lat_max", "lat_rate"):
            check_nonneg(f"ActorTrack.{f}", getattr(self, f))
        if np.any(np.asarray(self.knot_s) <= 0):
            raise ValueError("ActorTrack.knot_s: must be > 0")
        return self
