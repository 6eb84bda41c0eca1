"""Cooperative warning texts: the six canonical templates, a text bank by ambiguity, rendering,
grounding and the token tables that a rollout reads.

The texts themselves and the bank type are :mod:`lantern_jax.scenarios.warning_texts`
(re-exported here); the templates are verbatim from the paper's warning-template table.  The
token ``<FRONT_CAR_POS>`` is never shown literally: at every step it is replaced by the hazard (or
conflict) position ``(x, y)`` in metres in the *current ego frame*, ``x`` forward and ``y`` to
the **right** (the paper's convention), formatted with one decimal.

The text bank (:class:`TextBank`, an immutable value; the built-in one is :data:`DEFAULT_BANK`)
holds :class:`WarningText` entries with fixed ids:

==========  ==================================================================================
ids         entries
==========  ==================================================================================
0-5         canonical template of family ``f`` (``text_id == f``)
6-11        first low-ambiguity paraphrase of each family (:func:`paraphrase_text_id`)
12-59       per family (8 each, family order): low 2-3, medium 1-3, high 1-3
60-64       the five non-actionable warnings of the paper's appendix, verbatim (no family)
65          the empty text (:data:`EMPTY_TEXT_ID`; no words)
66-         texts added later: every registered family's exact warning (kind ``"canonical"``)
            and paraphrases (:func:`family_texts`), texts added with :func:`add_text`
==========  ==================================================================================

Ambiguity tiers of the paraphrases (paper appendix "Additional Ablation Analysis"):

* **low** — local wording changes; the event and the position are kept;
* **medium** — the event is described less directly; the position is kept;
* **high** — only a generic description of the impending interaction, **no position**.

A text states a position exactly when it contains ``<FRONT_CAR_POS>``; one that does not (the
high tier, the non-actionable texts) delivers no position to the policy: its tokens hold no
number token and its value channel is all zero.

Distance-conditioned warnings (paper appendix "Diagnostics with Non-Actionable Language
Inputs") are a family's canonical text grounded at a near or a far position
(:data:`DISTANCE_POSITIONS`, the paper's (12.0, 0.5) m and (100.0, 0.5) m), delivered with a
warning override (``ExecutionConfig.override_*``); ``render_warning(0, (12.0, 0.5))`` is the
string a language model reads.

Inside the simulator a warning is ``(active, text_id, grounded position)``; a policy never sees
those three.  It reads only the delivered text as tokens: :func:`warning_language` looks the
text's token ids up in :func:`text_tables` (built once, outside ``jit``) and writes the grounded
position into the value channel at the text's two number tokens (:mod:`lantern_jax.types.language`,
"Numbers").  No warning, or a text the bank does not hold, reads as all padding.  Strings are
produced outside ``jit`` by :func:`render_warning`.  A bank with more texts
(:meth:`TextBank.with_text`) is a different value: a rollout given it in its settings
(``Settings(bank=...)``) is compiled for it, and no program of another bank can answer for it.

The bank's last built-in entry is the **empty text** (:data:`EMPTY_TEXT_ID`, kind ``"empty"``):
a warning delivered with no words at all, used by the language-sensitivity diagnostic to check
that a policy's response comes from the words.  A policy cannot tell it from no warning.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import (
    FAMILIES,
    OVERRIDE_ANCHOR_START,
    OVERRIDE_ANCHOR_WARN_POINT,
    OVERRIDE_FRAME_EGO,
    OVERRIDE_FRAME_WORLD,
)
from lantern_jax.core.times import NEVER
from lantern_jax.maths.geometry import world_to_ego
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY, Texts
from lantern_jax.scenarios.warning_texts import (
    DEFAULT_BANK,
    TEMPLATES,
    TIERS,
    TOKEN,
    TextBank,
    WarningText,
    check_entry,
    family_index,
)

# the rest of the texts and the bank, read from this module too
from lantern_jax.scenarios.warning_texts import EMPTY_TEXT_ID as EMPTY_TEXT_ID
from lantern_jax.scenarios.warning_texts import NO_FAMILY as NO_FAMILY
from lantern_jax.scenarios.warning_texts import NON_ACTIONABLE as NON_ACTIONABLE
from lantern_jax.scenarios.warning_texts import PARAPHRASES as PARAPHRASES
from lantern_jax.scenarios.warning_texts import TEXT_KINDS as TEXT_KINDS
from lantern_jax.types import language
from lantern_jax.types.world import Scenario

Array = jax.Array


#: Ego-frame positions (x forward, y right; m) of the distance-conditioned diagnostic (paper).
DISTANCE_POSITIONS: dict[str, tuple[float, float]] = {"near": (12.0, 0.5), "far": (100.0, 0.5)}


def registered_bank() -> TextBank:
    """The built-in bank followed by the texts of every registered family (in registration
    order; each family's :attr:`~lantern_jax.scenarios.family_registry.FamilyEntry.texts`): the
    bank of :func:`lantern_jax.sim.settings.default_settings`, and the one every function of
    this module reads when given no bank.  Equal to :data:`DEFAULT_BANK` when no family is
    registered."""
    return _registered_bank(
        tuple((e.index, e.texts) for e in FAMILY_REGISTRY.user_entries() if e.texts)
    )


@functools.lru_cache(maxsize=8)
def _registered_bank(family_texts: tuple) -> TextBank:
    entries = list(DEFAULT_BANK.entries)
    for f, texts in family_texts:
        start = len(entries)
        entries += [
            WarningText(start + i, f, kind, text, tier)
            for i, (kind, tier, text) in enumerate(texts)
        ]
    return TextBank(tuple(entries))


def _bank(bank: TextBank | None) -> TextBank:
    return registered_bank() if bank is None else bank


def paraphrase_text_id(family: int | str, bank: TextBank | None = None) -> int:
    """Text id of a family's first low-ambiguity paraphrase (ids 6-11 for the six built-in
    families, as before the tiers; a registered family's first paraphrase)."""
    f = family_index(family)
    if f < len(FAMILIES):
        return len(TEMPLATES) + f
    return _family_paraphrases(f, bank)[0]


def canonical_text_id(family: int | str, bank: TextBank | None = None) -> int:
    """Text id of a family's exact warning: the family index for the six built-in families, the
    entry of a registered one's texts (:func:`family_texts`).

    Raises:
        ValueError: for an unknown family or a registered family without texts in the bank.
    """
    f = family_index(family)
    if f < len(FAMILIES):
        return f
    for e in _bank(bank):
        if e.kind == "canonical" and e.family == f:
            return e.text_id
    raise ValueError(f"family: {family_codes.code(f)!r} has no warning text in the bank")


def _family_paraphrases(f: int, bank: TextBank | None = None) -> tuple[int, ...]:
    """Ids of a family's paraphrases, in bank order (raises when it has none)."""
    ids = tuple(e.text_id for e in _bank(bank) if e.kind == "paraphrase" and e.family == f)
    if not ids:
        raise ValueError(f"family: {family_codes.code(f)!r} has no paraphrase in the bank")
    return ids


def family_texts(warning: str, paraphrases: Mapping[str, Sequence[str]]) -> Texts:
    """A registered family's exact warning and paraphrases as the bank's entries, checked
    against the bank's rules; its registry entry holds them (they follow the built-in texts in
    :func:`registered_bank`).

    Args:
        warning: the exact warning (kind ``"canonical"``), in the templates' style, with
            ``<FRONT_CAR_POS>`` where the grounded position goes.
        paraphrases: ambiguity tier -> held-out paraphrases (the bank's tier rules apply: low
            and medium state the position, high does not).

    Returns:
        ``(kind, tier, text)`` entries, the exact warning first.

    Raises:
        ValueError: for a text that breaks the bank's rules.
    """
    entries = [("canonical", "", warning)]
    for tier, texts in paraphrases.items():
        entries += [("paraphrase", tier, t) for t in texts]
    for kind, tier, text in entries:
        check_entry(kind, tier, text)
    return tuple(entries)


def tier_text_ids(family: int | str, tier: str, bank: TextBank | None = None) -> tuple[int, ...]:
    """Ids of a family's paraphrases of one ambiguity tier, in bank order."""
    f = family_index(family)
    if tier not in TIERS:
        raise ValueError(f"tier: {tier!r} not one of {{{', '.join(TIERS)}}}")
    return tuple(
        e.text_id
        for e in _bank(bank)
        if e.kind == "paraphrase" and e.family == f and e.tier == tier
    )


def non_actionable_text_ids(bank: TextBank | None = None) -> tuple[int, ...]:
    """Ids of the non-actionable texts, in bank order (the paper's five first)."""
    return tuple(e.text_id for e in _bank(bank) if e.kind == "non_actionable")


def get_text(text_id: int, bank: TextBank | None = None) -> WarningText:
    """The bank entry with ``text_id`` (default bank: :func:`registered_bank`)."""
    return _bank(bank).get(text_id)


# ---------------------------------------------------------------------------------------------
# ambiguity tiers over a suite
# ---------------------------------------------------------------------------------------------
def _tier_order(families: Sequence[str | int], keys: Sequence[str]) -> np.ndarray:
    """Rank of every pair when ordered by (family, SHA-256 of its key)."""
    if len(families) != len(keys):
        raise ValueError(f"families/keys: {len(families)} families but {len(keys)} keys")
    fam = [family_index(f) for f in families]
    digest = [hashlib.sha256(str(k).encode()).hexdigest() for k in keys]
    order = sorted(range(len(fam)), key=lambda i: (fam[i], digest[i], i))
    rank = np.empty(len(fam), np.int64)
    rank[order] = np.arange(len(fam))
    return rank


def ambiguity_tiers(families: Sequence[str | int], keys: Sequence[str]) -> np.ndarray:
    """(n,) int: the ambiguity tier (index into :data:`TIERS`) of every pair of a suite.

    The pairs are ordered by family (paper order) and, within a family, by the SHA-256 of
    their key (e.g. the pair's generation seed); the ``k``-th pair of that order gets tier
    ``k mod 3``.
    The three tiers are therefore disjoint, cover the suite, differ in size by at most one
    (the 120-pair suite: 40 each, 6-7 per family) and do not depend on the order in which the
    suite lists its pairs.

    Args:
        families: (n,) family codes or indices.
        keys: (n,) a stable identity per pair (:func:`paraphrase_text_ids` uses the pair's
            generation seed).
    """
    return _tier_order(families, keys) % len(TIERS)


def held_out_text_ids(
    families: Sequence[str | int], keys: Sequence[str], bank: TextBank | None = None
) -> np.ndarray:
    """(n,) int32: the held-out paraphrase text of every pair, by its ambiguity tier.

    The tier comes from :func:`ambiguity_tiers`; within a tier the ``k``-th pair of the order
    uses paraphrase ``(k // 3) mod 3`` of its family and tier, so every paraphrase is used.
    """
    rank = _tier_order(families, keys)
    out = np.empty(len(rank), np.int32)
    for i, (f, r) in enumerate(zip(families, rank, strict=True)):
        # a registered family may lack a tier: it then reads any of its paraphrases
        ids = tier_text_ids(f, TIERS[r % len(TIERS)], bank) or _family_paraphrases(
            family_index(f), bank
        )
        out[i] = ids[(r // len(TIERS)) % len(ids)]
    return out


def _pair_keys(config) -> tuple[list, list[str]]:
    """(families, keys) of every execution of a batched config: the key is the pair's
    generation seed (``noise_seed``)."""
    families = np.asarray(config.family).reshape(-1).tolist()
    return families, [str(int(k)) for k in np.asarray(config.noise_seed).reshape(-1)]


def paraphrase_text_ids(config) -> np.ndarray:
    """(n,) int32: the held-out paraphrase of every execution of a batched config, by tier.

    The pair key is the pair's generation seed (``ExecutionConfig.noise_seed``, from the pair
    parameters' ``seed``), so the tiers are those of :func:`ambiguity_tiers` over the batch
    (40 / 40 / 40 on the 120-pair suite) whatever the batch order.  Outside ``jit``.

    Args:
        config: an :class:`~lantern_jax.types.world.ExecutionConfig` with a leading batch axis (the
            Route A executions of a suite, one per pair).
    """
    return held_out_text_ids(*_pair_keys(config))


def paraphrase_tiers(config) -> np.ndarray:
    """(n,) int: the ambiguity tier (index into :data:`TIERS`) that :func:`paraphrase_text_ids`
    uses for every execution of a batched config."""
    return ambiguity_tiers(*_pair_keys(config))


# ---------------------------------------------------------------------------------------------
# rendering, grounding and the token tables
# ---------------------------------------------------------------------------------------------
def format_position(pos_ego_xy) -> str:
    """``"(x, y)"`` as a warning writes it (:func:`lantern_jax.types.language.format_number`: one
    decimal, from the float32 value the simulator holds; ``-0.0`` printed as ``0.0``)."""
    p = np.asarray(pos_ego_xy, np.float64).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"pos_ego_xy: expected two finite numbers, got {pos_ego_xy!r}")
    return "(" + ", ".join(language.format_number(v) for v in p) + ")"


def render_warning(text_id: int, pos_ego_xy=None, bank: TextBank | None = None) -> str:
    """The warning string with ``<FRONT_CAR_POS>`` grounded (what a language model reads).

    Args:
        text_id: id in ``bank``.
        pos_ego_xy: (2,) m, grounded position in the ego frame (x forward, y right), e.g. the
            output of :func:`ground_position`; ignored (may be None) for a text that states no
            position.
        bank: the text bank.

    Example:
        ``render_warning(0, (14.2, 3.1))`` ->
        ``"The pedestrian at position (14.2, 3.1) is about to enter the ego lane."``
    """
    entry = _bank(bank).get(text_id)
    if not entry.has_position:
        return entry.text
    return entry.text.replace(TOKEN, format_position(pos_ego_xy))


def ground_position(hazard_xy: jax.Array, ego_xy: jax.Array, ego_yaw: jax.Array) -> jax.Array:
    """World position -> ego frame of the warning (pure JAX, jittable, broadcasts).

    Args:
        hazard_xy: (..., 2) float32, m, world frame.
        ego_xy: (..., 2) float32, m, world frame, ego box centre.
        ego_yaw: (...) float32, rad, CCW from +x.

    Returns:
        (..., 2) float32, m: ``(forward, right)`` relative to the ego.
    """

    return world_to_ego(jnp.asarray(hazard_xy), jnp.asarray(ego_xy), jnp.asarray(ego_yaw))


@dataclass(frozen=True)
class TextTables:
    """What a rollout looks up by text id (built once per bank size, read-only NumPy arrays).

    Attributes:
        tokens: (num_texts, MAX_TOKENS) int32, padded token ids of every text, a written
            position as two number tokens (:func:`lantern_jax.types.language.tokenize`).
        x_slot: (num_texts,) int32, index of the number token that writes the position's x
            (-1: the text states no position).
        y_slot: (num_texts,) int32, likewise for y.
    """

    tokens: np.ndarray
    x_slot: np.ndarray
    y_slot: np.ndarray

    @property
    def has_position(self) -> np.ndarray:
        """(num_texts,) bool: the text states a position."""
        return self.x_slot >= 0


def text_tables(bank: TextBank | None = None) -> TextTables:
    """The per-text tables a rollout indexes by text id (:class:`TextTables`): one row per text
    of the bank, built once per bank (read-only NumPy arrays); inside a trace, the bank's
    traced tables (padded to :func:`text_capacity` rows).

    Raises:
        lantern_jax.types.language.LanguageAssetError: when the tokenizer file is missing.
        ValueError: naming a text longer than ``MAX_TOKENS`` tokens.
    """
    b = _bank(bank)
    return b.tables if b.tables is not None else _text_tables(b)


#: The rows of a bank's tables in a compiled program are a multiple of this many texts: every
#: bank of up to 128 texts (the built-in 66, with the three unseen families' 30 or the language
#: diagnostic's two probes) runs the same program; a larger bank compiles another.
TEXT_CAPACITY_STEP = 128


def text_capacity(num_texts: int) -> int:
    """Rows of the tables of a bank of ``num_texts`` texts in a compiled program."""
    return -(-max(num_texts, 1) // TEXT_CAPACITY_STEP) * TEXT_CAPACITY_STEP


@functools.lru_cache(maxsize=8)
def _padded_tables(bank: TextBank) -> TextTables:
    """:func:`text_tables` padded to :func:`text_capacity` rows: padding rows read as no text
    (all ``PAD_ID``, no position), as an id beyond the bank does."""
    t = _text_tables(bank)
    pad = text_capacity(len(bank)) - len(bank)
    tables = TextTables(
        tokens=np.pad(t.tokens, ((0, pad), (0, 0)), constant_values=language.PAD_ID),
        x_slot=np.pad(t.x_slot, (0, pad), constant_values=-1),
        y_slot=np.pad(t.y_slot, (0, pad), constant_values=-1),
    )
    for a in (tables.tokens, tables.x_slot, tables.y_slot):
        a.setflags(write=False)
    return tables


def _flatten_bank(bank: TextBank) -> tuple[tuple, None]:
    t = bank.tables if bank.tables is not None else _padded_tables(bank)
    return (t.tokens, t.x_slot, t.y_slot), None


def _unflatten_bank(aux: None, leaves: tuple) -> TextBank:
    del aux
    return TextBank((), TextTables(*leaves))


# The bank is an argument of a compiled program (its tables), never a part of it.
jax.tree_util.register_pytree_node(TextBank, _flatten_bank, _unflatten_bank)


@functools.lru_cache(maxsize=8)
def _text_tables(bank: TextBank) -> TextTables:
    """:func:`text_tables`, cached by bank (one positional key, whatever the call spelling)."""
    rows, xs, ys = [], [], []
    for e in bank:
        ids = language.tokenize(e.text)
        if len(ids) > language.MAX_TOKENS:
            raise ValueError(
                f"text {e.text_id}: {len(ids)} tokens exceed MAX_TOKENS "
                f"{language.MAX_TOKENS}: {e.text!r}"
            )
        slots = language.number_slots(ids)
        rows.append(language.pad(ids))
        xs.append(slots[0] if slots else -1)
        ys.append(slots[1] if slots else -1)
    tables = TextTables(
        tokens=np.stack(rows), x_slot=np.asarray(xs, np.int32), y_slot=np.asarray(ys, np.int32)
    )
    for a in (tables.tokens, tables.x_slot, tables.y_slot):
        a.setflags(write=False)
    return tables


def token_table(bank: TextBank | None = None) -> np.ndarray:
    """(num_texts, MAX_TOKENS) int32, padded token ids of every text (see :func:`text_tables`)."""
    return text_tables(bank).tokens


def warning_language(
    text_id: Array, active: Array, position: Array, bank: TextBank | None = None
) -> tuple[Array, Array]:
    """The delivered text as a policy reads it: token ids and the aligned value channel
    (jittable; one table lookup).

    Args:
        text_id: () int32, delivered text id (-1 or out of the bank: unknown).
        active: () bool, a warning is delivered now.
        position: (2,) float32, m, the grounded position (ego frame, x forward, y right); it
            enters the value channel rounded as the text writes it, and only for a text that
            states a position.
        bank: the text bank, traced in a compiled program (default: :func:`registered_bank`,
            whose tables are then constants of the program; the simulator always passes its
            settings' bank).

    Returns:
        tokens: (MAX_TOKENS,) int32, all ``PAD_ID`` when inactive or unknown.
        values: (MAX_TOKENS,) float32, the position's x and y at the text's two number tokens,
            zero elsewhere (all zero when inactive, unknown or stating no position).
    """
    tables = text_tables(bank)
    n = tables.tokens.shape[0]
    known = active & (text_id >= 0) & (text_id < n)
    i = jnp.clip(text_id, 0, n - 1)
    tokens = jnp.where(known, jnp.asarray(tables.tokens)[i], language.PAD_ID).astype(jnp.int32)
    slots = jnp.arange(language.MAX_TOKENS, dtype=jnp.int32)
    written = language.round_number(position)
    x_at = known & (slots == jnp.asarray(tables.x_slot)[i])
    y_at = known & (slots == jnp.asarray(tables.y_slot)[i])
    values = jnp.where(x_at, written[0], 0.0) + jnp.where(y_at, written[1], 0.0)
    return tokens, values.astype(jnp.float32)


def warning_string(tokens, values) -> str:
    """The string a policy read, from its observation's token ids and value channel (outside
    ``jit``; ``""`` for no warning)."""
    return language.detokenize(np.asarray(tokens), np.asarray(values))


# ---------------------------------------------------------------------------------------------
# warning overrides (diagnostics)
# ---------------------------------------------------------------------------------------------
OVERRIDE_FRAMES = {"world": OVERRIDE_FRAME_WORLD, "ego": OVERRIDE_FRAME_EGO}
OVERRIDE_ANCHORS = {"start": OVERRIDE_ANCHOR_START, "warning_point": OVERRIDE_ANCHOR_WARN_POINT}


def set_override(
    scenario: Scenario,
    text_id: int,
    position: Sequence[float] = (0.0, 0.0),
    frame: str = "ego",
    on_s: float = 0.0,
    off_s: float = NEVER,
    anchor: str = "start",
) -> Scenario:
    """A copy of a scenario (or a batch of them) whose policy is delivered ``text_id`` at
    ``position`` while ``anchor + on_s <= t < anchor + off_s``, on any route and condition.

    Outside the window the protocol's own warning (if any) is delivered as usual.  The override
    changes only what the policy reads
    (:func:`~lantern_jax.sensors.warning_delivery.delivered_warning`), not the protocol's times
    or the scoring.  A text that states no position delivers none.

    Args:
        scenario: one :class:`~lantern_jax.types.world.Scenario` or a batch (leading axis).
        text_id: id in the bank (:data:`DEFAULT_BANK` unless ``bank``).
        position: (2,) m: ego frame ``(forward, right)`` for ``frame="ego"`` (fixed relative to
            the ego, as in the paper's distance diagnostic), world ``(x, y)`` for
            ``frame="world"`` (a fixed point, grounded into the ego frame every tick).
        frame: ``"ego"`` or ``"world"``.
        on_s: s, window start after the anchor.
        off_s: s, window end (exclusive) after the anchor; ``NEVER`` keeps it open.
        anchor: ``"start"`` (t = 0) or ``"warning_point"`` (the ego reaching the route's warning
            point, recorded on Route A and Route B alike).

    Raises:
        ValueError: naming the bad argument.
    """
    get_text(text_id)
    if frame not in OVERRIDE_FRAMES:
        raise ValueError(f"frame: {frame!r} not one of {{{', '.join(OVERRIDE_FRAMES)}}}")
    if anchor not in OVERRIDE_ANCHORS:
        raise ValueError(f"anchor: {anchor!r} not one of {{{', '.join(OVERRIDE_ANCHORS)}}}")
    pos = np.asarray(position, np.float64).reshape(-1)
    if pos.shape != (2,) or not np.all(np.isfinite(pos)):
        raise ValueError(f"position: expected two finite numbers, got {position!r}")
    if not (np.isfinite(on_s) and np.isfinite(off_s) and 0.0 <= on_s <= off_s):
        raise ValueError(f"on_s/off_s: need 0 <= on_s <= off_s (finite), got {on_s}, {off_s}")
    cfg = scenario.config
    full = jnp.full_like
    return scenario.replace(
        config=cfg.replace(
            override_text_id=full(cfg.override_text_id, int(text_id)),
            override_on_s=full(cfg.override_on_s, on_s),
            override_off_s=full(cfg.override_off_s, off_s),
            override_anchor=full(cfg.override_anchor, OVERRIDE_ANCHORS[anchor]),
            override_x=full(cfg.override_x, pos[0]),
            override_y=full(cfg.override_y, pos[1]),
            override_frame=full(cfg.override_frame, OVERRIDE_FRAMES[frame]),
        )
    )
