"""The driving model: perception, ego state, navigation and language to ten waypoints (NNX).

::

    object tokens (A, F) --Linear--> (A, W) --self-attention (masked) x layers--> mean over seen
                         (W,), or by ``ModelConfig.object_pool`` "mean_max" [mean, max] (2W,)
    range image (N,)     --MLP-----> (W,)
    ego + route          --MLP-----> (W,)
    trunk = MLP([objects, ranges, ego])                               (W,)
    language (only when ``ModelConfig.language``), by ``ModelConfig.text_encoder``:
      "pooled":    gamma, beta = Linear([pooled text embedding, stated position,
                                         has_position, warning])
      "attention": word tokens (L, WORD_DIM) --Linear + learned position (L, W)--> self-attention
                   (masked to the text's tokens) x text_layers --> mean over the tokens (W,);
                   gamma, beta = MLP([pooled text embedding, that (W,), stated position,
                                      has_position, warning])
      "bigram":    word tokens (L, WORD_DIM) --Linear--> (L, W) --each word times the next one's
                   second Linear (L-1, W)--> mean over the text's adjacent pairs (W,);
                   gamma, beta = the same MLP as "attention"
        trunk = trunk * (1 + gamma) + beta                            (FiLM)
    head: MLP(trunk) -> (10, 2) increments, summed along the horizon  (ego frame, metres);
          with ``ModelConfig.modes`` K > 1: K such plans and K scores, the plan driven the one
          scored highest

The head predicts per-step displacements and accumulates them, so the waypoints are ordered
along the plan; their scale is set by :data:`STEP_SCALE_M` (a 10 m/s plan moves 2.5 m a step).
The token-embedding table is not part of the model: the pooled embedding and the word tokens'
embeddings are inputs (:mod:`lantern_jax.policies.learned.features`), so checkpoints hold only
trained weights.

The mean over the seen actors' tokens weighs every seen actor alike: the one car that matters
(the next car of the flow a right turn yields to, a wrong-way car) is one term of a mean over up
to sixteen slots.  The ``mean_max`` pooling (``ModelConfig.object_pool``) adds each feature's
largest value over the seen actors, as point-set and vector-map encoders pool, so one actor can
set a feature whatever the others are.  Measured on the closed-loop recipe, it does not score
better than the mean (the learned models' page, "Pooling the actors by their largest values"),
and the mean stays the default.

The pooled text is a bag of words: the mean of the tokens' embeddings cannot tell "The vehicle
at position (x, y) will cut into the ego lane." from a sentence that uses the same words to
negate it, and a linear FiLM of that mean weighs each word on its own.  The ``attention``
encoder reads the words in order (learned position embeddings, self-attention over the text's
tokens) and its FiLM is an MLP, so words can change one another's meaning.  The ``bigram``
encoder reads which word follows which: the mean over adjacent pairs of the first word's
projection times the second's (another projection, so "is nothing" and "nothing is" differ),
a factorised bilinear feature of every ordered word pair.  It sees no order beyond a pair and
costs about a third of the attention reader's training step
(``benchmarks/bench_text_encoder.py``).

Its two projections are linear in a token's embedding row, so a batch whose texts draw on a few
hundred distinct tokens need not project every one of its B x L token slots: training
(:func:`lantern_jax.apps.training.fit.make_loss`) projects the rows of the run's vocabulary once
per step (:meth:`DrivingModel.word_tables`) and each slot reads its token's projected row
(:class:`WordTables`).  The function is the same; the float32 sums of the gradient run in
another order, so the weights are not the bits of the per-slot form.

One plan per observation, trained by its L1 distance to the expert's, is the expert's plans
averaged where the model cannot tell them apart: where the expert sometimes waits and sometimes
goes (a restart after a crossing vehicle has cleared), the regression's answer can be a creep
that is neither.  ``ModelConfig.modes`` K > 1 gives the head K plans and a score for each,
trained winner-takes-all (:func:`modes_loss`: the L1 of the plan nearest the expert's, plus the
cross-entropy of the scores against that plan's index), as multi-hypothesis trajectory
predictors are; the model drives the plan it scores highest, always one of its own plans.
Measured on the closed-loop recipe with three plans, the left turn with a wrong-way car is
driven better with the warning, but the warning gain is no larger beyond the spread and the
right-turn yield's warning hurts more (the learned models' page, "Three plans and a score for
each"); one plan stays the default.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import nnx

from lantern_jax.core.constants import NUM_WAYPOINTS
from lantern_jax.policies.learned.features import WORD_DIM, Features
from lantern_jax.types.language import MAX_TOKENS

Array = jax.Array

STEP_SCALE_M = 2.5  # m, scale of one predicted waypoint increment
#: How the text channel is read (``ModelConfig.text_encoder``; see the module docstring).
TEXT_ENCODERS = ("pooled", "attention", "bigram")
#: How the seen actors' tokens are pooled (``ModelConfig.object_pool``; the module docstring).
OBJECT_POOLS = ("mean", "mean_max")
WORD_POSITION_INIT_STD = 0.02  # standard deviation of the learned word-position embeddings
#: Weight of the mode scores' cross-entropy beside the winning plan's L1 (m) in
#: :func:`modes_loss`: a tenth, so that the scores' loss (ln K nats at the start, 1.1 for three
#: modes) weighs about as the plans' (0.1-0.3 m once the open-loop stages have fitted).
MODE_SCORE_WEIGHT = 0.1


class WordTables(NamedTuple):
    """The bigram reader's two projections of a vocabulary's embedding rows, computed once for
    a batch (:meth:`DrivingModel.word_tables`) and read by every example's token slots."""

    row: Array  # (V,) int32, each token id's row in first / second (0 outside the vocabulary)
    first: Array  # (U, W) float32, embed_words of the vocabulary's rows (a pair's first word)
    second: Array  # (U, W) float32, embed_next of them (a pair's second word)


def reads_word_pairs(config: ModelConfig) -> bool:
    """The model reads its text with the bigram encoder (the one with :class:`WordTables`)."""
    return config.language and config.text_encoder == "bigram"


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """Architecture of a driving model (part of its checkpoint; a mismatch is refused)."""

    rig: str = "front"  # front | surround
    language: bool = True  # condition on the text channel (FiLM) and the stated position
    width: int = 64  # hidden width W
    heads: int = 4  # attention heads
    layers: int = 1  # self-attention layers over object tokens
    object_features: int = 13  # F (features.Features.objects' last axis)
    ranges: int = 32  # N, rays of the rig's range image
    text_dim: int = 256  # D, embedding width
    text_encoder: str = "pooled"  # one of TEXT_ENCODERS
    text_layers: int = 1  # self-attention layers over the words (text_encoder "attention")
    object_pool: str = "mean"  # one of OBJECT_POOLS
    modes: int = 1  # K, plans the head proposes (the module docstring); 1: one plan, no scores


class _MLP(nnx.Module):
    def __init__(self, sizes: tuple[int, ...], rngs: nnx.Rngs):
        self.layers = nnx.List(
            [nnx.Linear(a, b, rngs=rngs) for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
        )

    def __call__(self, x: Array) -> Array:
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = nnx.gelu(x)
        return x


class DrivingModel(nnx.Module):
    """See the module docstring; call it on one :class:`Features` (``vmap`` outside)."""

    def __init__(self, config: ModelConfig, rngs: nnx.Rngs):
        w = config.width
        self.config = config
        self.embed_objects = nnx.Linear(config.object_features, w, rngs=rngs)
        self.attention = nnx.List([
            nnx.MultiHeadAttention(num_heads=config.heads, in_features=w, qkv_features=w,
                                   out_features=w, decode=False, rngs=rngs)
            for _ in range(config.layers)
        ])  # fmt: skip
        self.norms = nnx.List([nnx.LayerNorm(w, rngs=rngs) for _ in range(config.layers)])
        self.ranges = _MLP((config.ranges, w, w), rngs)
        self.ego = _MLP((9 + 52, w, w), rngs)
        pooled_width = w * (2 if config.object_pool == "mean_max" else 1)
        self.trunk = _MLP((pooled_width + 2 * w, 2 * w, w), rngs)
        if config.language and config.text_encoder != "pooled":  # a reader of the words
            self.embed_words = nnx.Linear(WORD_DIM, w, rngs=rngs)
            if config.text_encoder == "bigram":
                self.embed_next = nnx.Linear(WORD_DIM, w, rngs=rngs)  # the pair's second word
            else:
                self.word_position = nnx.Param(
                    WORD_POSITION_INIT_STD * jax.random.normal(rngs.params(), (MAX_TOKENS, w))
                )
                self.text_attention = nnx.List([
                    nnx.MultiHeadAttention(num_heads=config.heads, in_features=w,
                                           qkv_features=w, out_features=w, decode=False,
                                           rngs=rngs)
                    for _ in range(config.text_layers)
                ])  # fmt: skip
                self.text_norms = nnx.List(
                    [nnx.LayerNorm(w, rngs=rngs) for _ in range(config.text_layers)]
                )
            self.film = _MLP((config.text_dim + w + 4, 2 * w, 2 * w), rngs)
        elif config.language:
            self.film = nnx.Linear(config.text_dim + 4, 2 * w, rngs=rngs)
        scores = config.modes if config.modes > 1 else 0
        self.head = _MLP((w, w, config.modes * 2 * NUM_WAYPOINTS + scores), rngs)

    def word_tables(self, embedding: Array, vocabulary: Array) -> WordTables | None:
        """The bigram reader's projections of ``vocabulary`` ((U,) int32 sorted token ids, every
        id the batch's texts use): ``embedding`` is the (V, D) float32 token table; None for
        the other encoders, which read every slot."""
        if not reads_word_pairs(self.config):
            return None
        rows = jnp.asarray(embedding, jnp.float32)[vocabulary, :WORD_DIM]  # (U, WORD_DIM)
        row = jnp.zeros(embedding.shape[0], jnp.int32).at[vocabulary].set(
            jnp.arange(vocabulary.shape[0], dtype=jnp.int32)
        )
        return WordTables(row, self.embed_words(rows), self.embed_next(rows))

    def __call__(self, f: Features, tables: WordTables | None = None) -> Array:
        """(10, 2) float32 waypoints, ego frame (x forward, y right), metres: the plan the model
        drives (with ``modes`` > 1 the one it scores highest, :meth:`plans`).  ``tables``
        (bigram reader only; :meth:`word_tables`) must project every token id of ``f.tokens``:
        the result is the per-slot reading's within float32 rounding."""
        plans, scores = self.plans(f, tables)
        if self.config.modes == 1:
            return plans[0]
        return plans[jnp.argmax(scores)]

    def plans(self, f: Features, tables: WordTables | None = None) -> tuple[Array, Array]:
        """Every plan the head proposes: ((K, 10, 2) float32 waypoints as :meth:`__call__`'s,
        (K,) float32 scores, logits of which plan to drive), K = ``ModelConfig.modes``; with one
        mode its score is 0."""
        objects = _attend(self.embed_objects(f.objects), f.mask, self.attention, self.norms)
        pooled = _masked_mean(objects, f.mask)  # (W,)
        if self.config.object_pool == "mean_max":
            pooled = jnp.concatenate([pooled, _masked_max(objects, f.mask)])  # (2W,)
        h = jnp.concatenate([pooled, self.ranges(f.ranges),
                             self.ego(jnp.concatenate([f.ego, f.route]))])  # fmt: skip
        h = self.trunk(h)
        if self.config.language:
            parts = [f.text]
            if self.config.text_encoder != "pooled":
                parts.append(self._read_words(f.words, f.word_mask, f.tokens, tables))
            cond = jnp.concatenate([*parts, f.position, f.has_position[None], f.warning[None]])
            gamma, beta = jnp.split(self.film(cond), 2)
            h = h * (1.0 + gamma) + beta
        out = self.head(nnx.gelu(h))
        k = self.config.modes
        steps = out[: k * 2 * NUM_WAYPOINTS].reshape(k, NUM_WAYPOINTS, 2) * STEP_SCALE_M
        scores = out[k * 2 * NUM_WAYPOINTS :] if k > 1 else jnp.zeros(1, out.dtype)
        return jnp.cumsum(steps, axis=1), scores

    def _read_words(self, words: Array, mask: Array, tokens: Array | None = None,
                    tables: WordTables | None = None) -> Array:  # fmt: skip
        """(W,) order-aware summary of the text: ``words`` (L, WORD_DIM) float32 embeddings,
        ``mask`` (L,) bool, the text's tokens (not padding), ``tokens`` (L,) int32 their ids
        (read through ``tables`` when given)."""
        if self.config.text_encoder == "bigram":
            if tables is None:
                pairs = self.embed_words(words[:-1]) * self.embed_next(words[1:])  # (L-1, W)
            else:
                row = tables.row[tokens]  # (L,) rows of the projected vocabulary
                pairs = tables.first[row[:-1]] * tables.second[row[1:]]  # (L-1, W)
            return _masked_mean(pairs, mask[:-1] & mask[1:])
        x = self.embed_words(words) + self.word_position[...]  # (L, W)
        return _masked_mean(_attend(x, mask, self.text_attention, self.text_norms), mask)


def _attend(tokens: Array, mask: Array, attention, norms) -> Array:
    """(T, W) float32 tokens after residual self-attention layers among the masked ones:
    ``tokens`` (T, W) float32, ``mask`` (T,) bool (unmasked rows are left for the pooling to
    drop)."""
    pair_mask = (mask[:, None] & mask[None, :])[None]  # (1, T, T)
    for att, norm in zip(attention, norms, strict=True):
        tokens = norm(tokens + att(tokens, mask=pair_mask))
    return tokens


def _masked_mean(tokens: Array, mask: Array) -> Array:
    """(W,) mean of ``tokens`` (T, W) over ``mask`` (T,) bool; zeros for an empty mask."""
    seen = mask.astype(jnp.float32)[:, None]
    return jnp.sum(tokens * seen, axis=0) / jnp.maximum(jnp.sum(seen), 1.0)


def _masked_max(tokens: Array, mask: Array) -> Array:
    """(W,) largest value of each column of ``tokens`` (T, W) over ``mask`` (T,) bool; zeros
    for an empty mask.  Its gradient reaches only the row that holds each column's maximum."""
    lowest = jnp.finfo(tokens.dtype).min
    largest = jnp.max(jnp.where(mask[:, None], tokens, lowest), axis=0)
    return jnp.where(jnp.any(mask), largest, 0.0)


def modes_loss(plans: Array, scores: Array, target: Array) -> tuple[Array, Array]:
    """Winner-takes-all loss of one example's proposals: ``plans`` (K, 10, 2) float32 m,
    ``scores`` (K,) float32 logits, ``target`` (10, 2) float32 m, the expert's plan.  Returns
    (the training loss: the L1 of the plan nearest the target, mean over its waypoints' two
    coordinates, in m, plus :data:`MODE_SCORE_WEIGHT` times the scores' cross-entropy against
    that plan's index; the L1 of the plan the model drives, m).  Only the nearest plan learns
    from the example, so the K plans can come to cover answers the expert gives in states the
    model cannot tell apart, rather than their average."""
    l1 = jnp.mean(jnp.abs(plans - target[None]), axis=(1, 2))  # (K,)
    nearest = jnp.argmin(l1)
    cross_entropy = jax.nn.logsumexp(scores) - scores[nearest]
    driven = l1[jnp.argmax(scores)]
    return l1[nearest] + MODE_SCORE_WEIGHT * cross_entropy, driven
