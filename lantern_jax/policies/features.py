"""A flat observation vector and a two-number action, for learned policies (and the brax env).

The simulator's :class:`~lantern_jax.types.observation.Observation` is a structure; an MLP policy
(e.g. one trained with PPO on :mod:`lantern_jax.apps.envs`) reads one flat float32 vector and emits
one small action.  Both mappings live here, below the policies, so that the environment that
trains a policy and the registered policy that evaluates it use exactly the same code.

Observation vector (:func:`observation_vector`, ``OBS_SIZE`` = 276 slots, float32; positions in
the ego frame, x forward, y right, as in the observation; every slot scaled to roughly [-2, 2]):

==========  =====  ==========================================================================
slots       size   content (scale)
==========  =====  ==========================================================================
0           1      ego speed / 10 m/s
1           1      ego longitudinal acceleration / 4 m/s^2
2           1      ego front-wheel angle / ``EGO_MAX_STEER`` (+ = left)
3           1      route reference speed ``v_ref`` / 10 m/s
4           1      route distance to the route's end / 100 m, clipped to [0, 2]
5-28        24     12 route points ahead (every second observed point: 0, 4, ..., 44 m
                   along the route), (x, y) / 50 m
29-32       4      navigation targets 10 m and 30 m ahead, (x, y) / 50 m
33-224      192    16 actor slots x 12: visible flag; (x, y) / 50 m; velocity (vx, vy) /
                   10 m/s; heading (cos, sin); half length, half width / 5 m; kind one-hot
                   (vehicle, pedestrian, static).  Slots the front camera does not see now
                   are all zeros (the policy is not privileged)
225-256     32     front-camera range image / 60 m, clipped to [0, 2]
257-259     3      traffic light one-hot (green, yellow, red)
260         1      route distance to the ego's stop line / 50 m, clipped to [-1, 2] (2 = none)
261         1      a warning text is delivered (any token that is not padding; 0 / 1)
262-263     2      the position the text writes (its first two numbers, x, y) / 50 m, clipped
                   to [-2, 2] (0 when no text or no position)
264-275     12     which of the bank's first 12 texts (the canonical templates and each
                   family's first paraphrase) the delivered text is, word for word (all zeros
                   for any other text, or none)
==========  =====  ==========================================================================

Action (:func:`action_to_waypoints`, ``ACTION_SIZE`` = 2, each in [-1, 1], clipped):

* ``action[0]`` — longitudinal acceleration: ``a = action[0] * EGO_MAX_ACCEL`` (3 m/s^2) for
  positive values, ``action[0] * EGO_MAX_BRAKE`` (8 m/s^2) for negative ones;
* ``action[1]`` — path curvature ``kappa = action[1] * KAPPA_MAX`` (1/m, + = left), with
  ``KAPPA_MAX = tan(EGO_MAX_STEER) / EGO_WHEELBASE`` the tightest circle the ego can drive.

The pair becomes the 10 waypoints of the policy interface: the ego's path if it kept that
acceleration (speed floored at 0) and that curvature for 2.5 s.  The waypoint controller
(:func:`lantern_jax.dynamics.controller.follow_plan`) then tracks them like any other plan: a
constant-acceleration plan gives exactly that acceleration, and the pure-pursuit target lies on
the arc, so the commanded wheel angle is the one of that curvature (within the steering limit).
Going through waypoints keeps one ego interface for every policy, learned or not.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import (
    EGO_MAX_ACCEL,
    EGO_MAX_BRAKE,
    EGO_MAX_STEER,
    EGO_WHEELBASE,
    MAX_ACTORS,
    NUM_ACTOR_KINDS,
    NUM_WAYPOINTS,
    WAYPOINT_DT,
)
from lantern_jax.scenarios.warnings import token_table
from lantern_jax.types.observation import Observation, stated_position, warning_delivered

Array = jax.Array

ACTION_SIZE = 2
KAPPA_MAX = float(np.tan(EGO_MAX_STEER) / EGO_WHEELBASE)  # 1/m, tightest drivable curvature

NUM_TEXTS = 12  # text-bank entries (canonical + held-out paraphrase per family)
ROUTE_STRIDE = 2  # every second observed route point (4 m apart)
SPEED_SCALE = 10.0  # m/s
ACCEL_SCALE = 4.0  # m/s^2
POS_SCALE = 50.0  # m
SIZE_SCALE = 5.0  # m
RANGE_SCALE = 60.0  # m
END_SCALE = 100.0  # m
ACTOR_FEATURES = 12  # per actor slot (see the table)
OBS_ACTOR_SLOTS = MAX_ACTORS  # actor slots of the vector: the built scenarios' capacity


def _actor_features(obs: Observation) -> Array:
    """(max(A, OBS_ACTOR_SLOTS) * 12,) float32: the camera-visible actors (zeros for unseen
    slots).  A batch whose unused trailing slots were cut
    (:func:`lantern_jax.types.world.trim_padding`) is padded back with zeros, exactly what those
    empty slots gave, so the vector keeps ``OBS_SIZE``."""
    seen = obs.visible.astype(jnp.float32)[:, None]
    kind = jax.nn.one_hot(obs.actor_kind, NUM_ACTOR_KINDS, dtype=jnp.float32)
    xy = jnp.where(obs.visible[:, None], obs.actor_xy, 0.0) / POS_SCALE
    per = jnp.concatenate(
        [seen, xy, obs.actor_vel / SPEED_SCALE, obs.actor_dir, obs.actor_extent / SIZE_SCALE,
         kind], axis=-1,
    )  # fmt: skip
    per = per * seen
    missing = max(OBS_ACTOR_SLOTS - per.shape[0], 0)
    return jnp.pad(per, ((0, missing), (0, 0))).reshape(-1)


def observation_vector(obs: Observation) -> Array:
    """The flat observation vector of one tick (see the module docstring for every slot).

    Args:
        obs: one scenario's observation (no batch axis; ``vmap`` outside).

    Returns:
        (OBS_SIZE,) float32.
    """
    f32 = jnp.float32
    scalars = jnp.stack(
        [
            obs.ego_speed / SPEED_SCALE,
            obs.ego_accel / ACCEL_SCALE,
            obs.ego_steer / EGO_MAX_STEER,
            obs.v_ref / SPEED_SCALE,
            jnp.clip(obs.dist_to_route_end / END_SCALE, 0.0, 2.0),
        ]
    ).astype(f32)
    route = obs.route[::ROUTE_STRIDE].reshape(-1) / POS_SCALE
    targets = obs.target_points.reshape(-1) / POS_SCALE
    ranges = jnp.clip(obs.range_image / RANGE_SCALE, 0.0, 2.0)
    light = jax.nn.one_hot(obs.light_state, 3, dtype=f32)
    stop = jnp.clip(obs.dist_to_stop / POS_SCALE, -1.0, 2.0)[None]
    active = warning_delivered(obs).astype(f32)
    pos, _ = stated_position(obs)
    warn_pos = jnp.clip(pos / POS_SCALE, -2.0, 2.0) * active
    known = jnp.asarray(token_table()[:NUM_TEXTS])  # (NUM_TEXTS, MAX_TOKENS)
    text = jnp.all(obs.warning_tokens[None, :] == known, axis=-1).astype(f32) * active
    parts = [scalars, route, targets, _actor_features(obs), ranges, light, stop, active[None],
             warn_pos, text]  # fmt: skip
    return jnp.concatenate([p.astype(f32) for p in parts])


OBS_SIZE = 5 + 24 + 4 + OBS_ACTOR_SLOTS * ACTOR_FEATURES + 32 + 3 + 1 + 1 + 2 + NUM_TEXTS


def action_to_waypoints(action: Array, speed: Array) -> Array:
    """Waypoints of a constant acceleration and curvature held for 2.5 s.

    Args:
        action: (2,) float32 in [-1, 1] (clipped): acceleration, curvature (see the module
            docstring for the scales).
        speed: () float32, m/s, the ego's current speed.

    Returns:
        (10, 2) float32, m, ego frame (x forward, y right), waypoint ``k`` at ``0.25 (k + 1)`` s.
    """
    a_in, k_in = jnp.clip(action[0], -1.0, 1.0), jnp.clip(action[1], -1.0, 1.0)
    accel = jnp.where(a_in >= 0.0, a_in * EGO_MAX_ACCEL, a_in * EGO_MAX_BRAKE)
    kappa = k_in * KAPPA_MAX
    v0 = jnp.maximum(speed, 0.0)
    t = WAYPOINT_DT * jnp.arange(1, NUM_WAYPOINTS + 1, dtype=jnp.float32)
    # Speed floored at 0: a braking plan stops at t_stop = v0 / |a| and stays there.
    t_stop = jnp.where(accel < 0.0, v0 / jnp.maximum(-accel, 1e-6), jnp.inf)
    tt = jnp.minimum(t, t_stop)
    s = v0 * tt + 0.5 * accel * tt * tt  # arc length along the path, m
    # Circle of curvature kappa from the origin, heading +x: x = sin(k s) / k,
    # y_left = (1 - cos(k s)) / k, written with sinc so that kappa -> 0 stays exact.
    half = kappa * s / (2.0 * jnp.pi)
    x = s * jnp.sinc(kappa * s / jnp.pi)
    y_left = 0.5 * kappa * s * s * jnp.sinc(half) ** 2
    return jnp.stack([x, -y_left], axis=-1).astype(jnp.float32)
