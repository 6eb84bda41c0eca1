"""Model inputs from the policy observation (one scenario; ``vmap`` outside).

The same function serves training (observations rebuilt from dataset frames) and the closed
loop (the simulator's observation), so a trained model sees identical inputs in both.

* ``ego`` — speed, acceleration, wheel angle, reference speed, distance to the route end and to
  the stop line (clipped), the light state one-hot;
* ``route`` — the 24 observed route points and the two navigation targets, scaled;
* ``objects`` — one token per actor slot the rig sees (position, velocity, heading, extent, kind
  one-hot), masked by that rig's visibility (front camera or the six-camera rig);
* ``ranges`` — that rig's range image, scaled to [0, 1];
* the **text channel** — the pooled WordLlama embedding of the delivered warning's tokens, or of
  a navigation instruction rendered from the route ahead ("Turn left at the junction ahead.")
  when no text is delivered; plus the position the text writes (its first two numbers, ego
  frame, scaled) and whether it writes one.  Everything here comes from the text itself:
  whether a warning is on is whether any token is delivered.  Language-free models ignore it.
  The same text also comes as its tokens' embeddings in order (``words``, ``word_mask``), for
  a model that reads the words in sequence (``ModelConfig.text_encoder``, ``"attention"`` or
  ``"bigram"``): the first :data:`WORD_DIM` columns of each token's row (WordLlama's
  embeddings are trained as Matryoshka representations, so a leading slice is itself an
  embedding; its loader truncates them the same way).  The full rows would make the per-token
  projection the largest cost of a training step.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from lantern_jax.core.constants import NUM_ACTOR_KINDS
from lantern_jax.maths.polyline import safe_atan2
from lantern_jax.types.language import (
    PAD_ID,
    pad,
    pooled_embedding,
    token_embeddings,
    tokenize,
)
from lantern_jax.types.observation import Observation, stated_position, warning_delivered

Array = jax.Array

POS_SCALE_M = 50.0  # m, positions are divided by this
SPEED_SCALE_MPS = 10.0  # m/s
DIST_CLIP_M = 100.0  # m, distances are clipped here before scaling
WORD_DIM = 64  # leading embedding columns of each word token in ``Features.words``
RANGE_SCALE_M = 120.0  # m, the longest camera range of any weather profile
TURN_THRESHOLD_RAD = 0.5  # rad, route heading change that makes the instruction a turn
NAV_TEXTS = (
    "Follow the road ahead.",
    "Turn left at the junction ahead.",
    "Turn right at the junction ahead.",
)
#: Camera rigs a model may be trained for (its ``config.rig``).
RIGS = ("front", "surround")


@struct.dataclass
class Features:
    """Inputs of the driving model for one observation."""

    ego: Array  # (9,) float32
    route: Array  # (52,) float32, 24 route points and 2 targets, scaled
    objects: Array  # (A, 10 + NUM_ACTOR_KINDS) float32, one token per actor slot
    mask: Array  # (A,) bool, the rig sees the actor
    ranges: Array  # (N,) float32 in [0, 1]
    text: Array  # (D,) float32, pooled embedding of the warning or the navigation instruction
    words: Array  # (L, WORD_DIM) float32, that text's token embeddings in order (0 at padding)
    word_mask: Array  # (L,) bool, the text's tokens (words, numbers, punctuation; not padding)
    tokens: Array  # (L,) int32, that text's token ids (the rows of ``words``; PAD_ID at padding)
    position: Array  # (2,) float32, stated position (ego frame, scaled; zeros when none)
    has_position: Array  # () float32, 1 when the delivered text writes a position
    warning: Array  # () float32, 1 while a text is delivered


@functools.cache
def nav_token_table() -> np.ndarray:
    """(3, MAX_TOKENS) int32 token ids of :data:`NAV_TEXTS` (tokenised once, outside jit)."""

    return np.stack([pad(tokenize(t)) for t in NAV_TEXTS]).astype(np.int32)


def navigation_instruction(route: Array) -> Array:
    """() int32 index into :data:`NAV_TEXTS` from the observed route's heading change (ego frame:
    y to the right, so a left turn bends towards negative y)."""
    d = route[-1] - route[-2]
    heading = safe_atan2(d[1], d[0])
    return jnp.where(heading < -TURN_THRESHOLD_RAD, 1,
                     jnp.where(heading > TURN_THRESHOLD_RAD, 2, 0)).astype(jnp.int32)  # fmt: skip


def features(obs: Observation, rig: str, embedding: Array, nav_tokens: Array) -> Features:
    """Model inputs of one observation.

    Args:
        obs: the policy observation.
        rig: ``"front"`` (110 deg camera) or ``"surround"`` (the six-camera rig).
        embedding: (V, D) float32 token-embedding table (frozen; not a model parameter).
        nav_tokens: (3, L) int32, :func:`nav_token_table`.
    """

    if rig not in RIGS:
        raise ValueError(f"rig: {rig!r} not one of {', '.join(RIGS)}")
    clip = lambda x: jnp.clip(x, -DIST_CLIP_M, DIST_CLIP_M) / DIST_CLIP_M  # noqa: E731
    light = jax.nn.one_hot(obs.light_state, 3)
    ego = jnp.concatenate([
        jnp.stack([obs.ego_speed / SPEED_SCALE_MPS, obs.ego_accel / 5.0, obs.ego_steer,
                   obs.v_ref / SPEED_SCALE_MPS, clip(obs.dist_to_route_end),
                   clip(obs.dist_to_stop)]),
        light,
    ])  # fmt: skip
    route = jnp.concatenate([obs.route.reshape(-1), obs.target_points.reshape(-1)]) / POS_SCALE_M
    if rig == "front":
        mask, ranges = obs.visible, obs.range_image
    else:
        if obs.surround is None:
            raise ValueError(
                "features: the surround rig needs Observation.surround (run the "
                "policy through act, whose surround flag makes the simulator fill it)"
            )
        mask, ranges = obs.surround.visible, obs.surround.ranges
    kind = jax.nn.one_hot(obs.actor_kind, NUM_ACTOR_KINDS)
    xy = jnp.where(mask[:, None], obs.actor_xy, 0.0)
    objects = jnp.concatenate(
        [xy / POS_SCALE_M, obs.actor_vel / SPEED_SCALE_MPS, obs.actor_dir, obs.actor_extent,
         jnp.linalg.norm(xy, axis=-1, keepdims=True) / POS_SCALE_M,
         jnp.ones_like(xy[:, :1]), kind], axis=-1,
    ) * mask[:, None]  # fmt: skip
    active = warning_delivered(obs)
    nav = nav_tokens[navigation_instruction(obs.route)]
    tokens = jnp.where(active, obs.warning_tokens, nav)
    text = pooled_embedding(embedding, tokens)
    word_mask = tokens != PAD_ID
    leading = jnp.asarray(embedding, jnp.float32)[:, :WORD_DIM]
    words = token_embeddings(leading, tokens) * word_mask[:, None]
    pos, has_pos = stated_position(obs)
    has_pos = active & has_pos
    return Features(
        ego=ego.astype(jnp.float32),
        route=route.astype(jnp.float32),
        objects=objects.astype(jnp.float32),
        mask=mask,
        ranges=jnp.clip(ranges / RANGE_SCALE_M, 0.0, 1.0).astype(jnp.float32),
        text=text,
        words=words,
        word_mask=word_mask,
        tokens=tokens.astype(jnp.int32),
        position=jnp.where(has_pos, pos / POS_SCALE_M, 0.0).astype(jnp.float32),
        has_position=has_pos.astype(jnp.float32),
        warning=active.astype(jnp.float32),
    )
