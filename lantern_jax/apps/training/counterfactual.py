"""Counterfactual warnings: frames whose text names no hazard of their route.

Beyond the paper's recipe. A model trained only on true warnings can fit "any text delivered ->
slow down" without reading the words. Counterfactual frames break that shortcut: a Route B
frame (the scene without its hazard) is given a text that calls for no reaction on its route,
and keeps its label — the expert's ordinary trajectory:

* **another family's text** — the canonical warning of a family of the other road type (a
  straight-road family's frame gets a junction family's text and the other way round: PE, VC,
  OR <-> LWW, RWW, RTY), so the hazard it names cannot be on this route; its stated position is
  drawn near the ego (:data:`NEAR_X_M`, :data:`NEAR_Y_M`), where a true warning asks to react;
* **a non-actionable message** — one of the bank's non-actionable texts (a hazard off the
  route; no position);
* **a distractor sentence** (only with ``distractors > 0``) — one of the set
  ``distractor_texts`` names in
  :data:`~lantern_jax.scenarios.warning_texts.DISTRACTOR_SETS`: a negation ("There is no
  stopped vehicle at position (x, y).") or an irrelevant statement ("The cafe at position
  (x, y) opens at nine ..."), its position drawn near the ego as above; the
  ``"position_and_lane"`` set adds ones in the templates' own phrases ("No vehicle at
  position (x, y) will cut into the ego lane.").  These teach that a stated position (or the
  phrase "the ego lane") alone is no reason to react; the language diagnostic's probes are
  other sentences, so they stay unseen.

An **empty text** needs no frame of its own: the observation carries no token, which a policy
cannot tell from no warning (:mod:`lantern_jax.scenarios.warnings`), so every ordinary frame
is already one.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from lantern_jax.apps.training.config import POSITION_SOURCES
from lantern_jax.apps.training.data import Examples
from lantern_jax.core.constants import FAMILIES
from lantern_jax.scenarios.warning_texts import DISTRACTOR_SETS
from lantern_jax.scenarios.warnings import DEFAULT_BANK, TextBank, text_tables
from lantern_jax.types.language import NUMBER_ID, round_number

NEAR_X_M = (10.0, 60.0)  # m, forward range of a counterfactual's stated position
NEAR_Y_M = (-4.0, 4.0)  # m, lateral range (right positive)
STRAIGHT = ("PE", "VC", "OR")  # families on a straight road; the rest turn at a junction
VARIANTS = ("other family's text", "non-actionable", "distractor sentence")


def other_road_families(family: str) -> tuple[int, ...]:
    """Indices (into :data:`FAMILIES`) of the families of the other road type than
    ``family``'s: their hazards cannot be on ``family``'s route."""
    straight = family in STRAIGHT
    return tuple(i for i, f in enumerate(FAMILIES) if (f in STRAIGHT) != straight)


def nonactionable_ids() -> np.ndarray:
    """(5,) int32 text ids of the bank's non-actionable messages."""

    return np.asarray([e.text_id for e in DEFAULT_BANK if e.kind == "non_actionable"], np.int32)


def distractor_bank(texts: str = "position") -> tuple[TextBank, np.ndarray]:
    """The built-in bank with the distractor set ``texts`` (a key of
    :data:`~lantern_jax.scenarios.warning_texts.DISTRACTOR_SETS`) appended as non-actionable
    texts, and their (K,) int32 text ids in it.  The built-in ids keep their rows, so a table
    of this bank gives every other counterfactual text the tokens of the built-in bank's.

    Raises:
        ValueError: for a set name not in ``DISTRACTOR_SETS``.
    """
    if texts not in DISTRACTOR_SETS:
        raise ValueError(f"distractor_texts: {texts!r} not one of {', '.join(DISTRACTOR_SETS)}")
    bank, ids = DEFAULT_BANK.with_unrelated_texts(DISTRACTOR_SETS[texts])
    return bank, np.asarray(ids, np.int32)


def stated_positions(
    ex: Examples, families: np.ndarray, routes: np.ndarray
) -> dict[str, np.ndarray]:
    """(k, 2) float32 m, per family code, the positions stated by the Route A examples whose
    text writes one (ego frame, x forward, y right): each text's first two numbers, as
    :func:`~lantern_jax.types.observation.stated_position` reads them."""
    tokens, values = ex.obs["warning_tokens"], ex.obs["warning_values"]
    is_num = tokens == NUMBER_ID
    rank = np.cumsum(is_num, axis=1) - 1
    x = np.sum(np.where(is_num & (rank == 0), values, 0.0), axis=1)
    y = np.sum(np.where(is_num & (rank == 1), values, 0.0), axis=1)
    stated = (is_num.sum(axis=1) >= 2) & (np.asarray(routes) == "A")
    xy = np.stack([x, y], axis=-1).astype(np.float32)
    families = np.asarray(families)
    return {str(f): xy[stated & (families == f)] for f in np.unique(families)}


def counterfactual_examples(
    ex: Examples, families: np.ndarray, routes: np.ndarray, share: float, seed: int,
    distractors: float = 0.0,
    distractor_texts: str = "position",
    positions: str = "near",
    stated_share: float = 1.0,
) -> tuple[Examples, np.ndarray]:
    """Counterfactual copies of a seeded ``share`` of the Route B examples.

    Args:
        ex: examples (``n`` of them) with the dataset's ordinary labels.
        families: (n,) str, each example's family code.
        routes: (n,) str, ``"A"`` or ``"B"``.
        share: counterfactual frames per Route B frame, in [0, 1].
        seed: seed of the choice of frames, variants, texts and positions.
        distractors: share of the counterfactual frames, in [0, 1], told a distractor sentence
            instead (drawn from a stream of their own: with 0 the frames are exactly those of
            a run without the setting).
        distractor_texts: which distractor set they are drawn from (a key of
            :data:`~lantern_jax.scenarios.warning_texts.DISTRACTOR_SETS`).
        positions: where the stated positions are drawn
            (:data:`~lantern_jax.apps.training.config.POSITION_SOURCES`); with
            ``"stated"`` a family whose examples state no position keeps the near box.  The
            frames, texts and the near draws are those of ``"near"`` (the stated positions
            come from a stream of their own).
        stated_share: with ``"stated"``, the share of those frames, in [0, 1], drawn among the
            stated positions; the others keep their near draw (chosen from a stream of their
            own: with 1 the frames are exactly those of a run without the setting).

    Returns:
        (the counterfactual examples — text replaced, labels kept, not ordinary driving —,
        (m,) int32 variant index into :data:`VARIANTS`).
    """

    rng = np.random.default_rng([seed, 42])
    is_b = np.flatnonzero(np.asarray(routes) == "B")
    pick = np.sort(rng.choice(is_b, int(round(share * len(is_b))), replace=False))
    sel = ex.take(pick)
    m = len(pick)
    variant = rng.integers(0, 2, m).astype(np.int32)
    fam = np.asarray(families)[pick]
    other = np.asarray([rng.choice(other_road_families(f)) for f in fam], np.int32)
    text = np.where(variant == 0, other, rng.choice(nonactionable_ids(), m)).astype(np.int32)
    tables = text_tables()
    rows = np.flatnonzero(tables.x_slot[text] >= 0)
    x, y = np.zeros(m, np.float32), np.zeros(m, np.float32)  # m, the stated position
    x[rows] = round_number(rng.uniform(*NEAR_X_M, len(rows)))
    y[rows] = round_number(rng.uniform(*NEAR_Y_M, len(rows)))
    if distractors > 0.0:
        bank, distractor_ids = distractor_bank(distractor_texts)
        tables = text_tables(bank)  # the built-in rows unchanged
        rng_d = np.random.default_rng([seed, 43])
        told = rng_d.random(m) < distractors
        variant = np.where(told, 2, variant).astype(np.int32)
        text = np.where(told, rng_d.choice(distractor_ids, m), text).astype(np.int32)
        x[told] = round_number(rng_d.uniform(*NEAR_X_M, int(told.sum())))
        y[told] = round_number(rng_d.uniform(*NEAR_Y_M, int(told.sum())))
    rows = np.flatnonzero(tables.x_slot[text] >= 0)
    if positions == "stated":
        pool = stated_positions(ex, families, routes)
        rng_p = np.random.default_rng([seed, 44])
        moved = rows  # the frames whose position is drawn among the stated ones
        if stated_share < 1.0:  # the others keep the near box
            moved = rows[np.random.default_rng([seed, 45]).random(len(rows)) < stated_share]
        for f in np.unique(fam[moved]):
            if len(pool.get(str(f), ())) == 0:
                continue  # no position stated for this family: the near box
            mine = moved[fam[moved] == f]
            drawn = pool[str(f)][rng_p.integers(0, len(pool[str(f)]), len(mine))]
            x[mine], y[mine] = round_number(drawn[:, 0]), round_number(drawn[:, 1])
    elif positions != "near":
        raise ValueError(f"positions: {positions!r} not one of {', '.join(POSITION_SOURCES)}")
    values = np.zeros(sel.obs["warning_values"].shape, np.float32)
    values[rows, tables.x_slot[text[rows]]] = x[rows]
    values[rows, tables.y_slot[text[rows]]] = y[rows]
    obs = dict(sel.obs)
    obs["warning_tokens"] = tables.tokens[text].astype(sel.obs["warning_tokens"].dtype)
    obs["warning_values"] = values.astype(sel.obs["warning_values"].dtype)
    return Examples(obs, sel.targets, sel.sequence, np.zeros(m, bool)), variant


def frame_counterfactuals(
    ex: Examples, frames: pd.DataFrame, share: float, seed: int, distractors: float = 0.0,
    distractor_texts: str = "position", positions: str = "near", stated_share: float = 1.0,
) -> Examples:
    """:func:`counterfactual_examples` of dataset examples (``ex`` built from ``frames``)."""
    return counterfactual_examples(
        ex, frames["family"].to_numpy(str), frames["route"].to_numpy(str), share, seed,
        distractors, distractor_texts, positions, stated_share,
    )[0]
