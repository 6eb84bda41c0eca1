"""Cooperative warning texts: the six canonical templates, a text bank by ambiguity, rendering,
grounding and the token tables that a rollout reads.

The templates are verbatim from the paper's warning-template table.  The token
``<FRONT_CAR_POS>`` is never shown literally: at every step it is replaced by the hazard (or
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
            and paraphrases (:func:`add_family_texts`), texts added with :func:`add_text`
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
position into the value channel at the text's two number tokens (:mod:`lantern_jax.language`,
"Numbers").  No warning, or a text the bank does not hold, reads as all padding.  Strings are
produced outside ``jit`` by :func:`render_warning`.  A bank with more texts
(:meth:`TextBank.with_text`) is a different value: a rollout given it in its settings
(``Settings(bank=...)``) is compiled for it, and no program of another bank can answer for it.

The bank's last built-in entry is the **empty text** (:data:`EMPTY_TEXT_ID`, kind ``"empty"``):
a warning delivered with no words at all, used by the language-sensitivity diagnostic to check
that a policy's response comes from the words.  A policy cannot tell it from no warning.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax import family_codes, language
from lantern_jax.constants import (
    FAMILIES,
    OVERRIDE_ANCHOR_START,
    OVERRIDE_ANCHOR_WARN_POINT,
    OVERRIDE_FRAME_EGO,
    OVERRIDE_FRAME_WORLD,
)
from lantern_jax.times import NEVER
from lantern_jax.world import Scenario

Array = jax.Array

TOKEN = language.PLACEHOLDER  # "<FRONT_CAR_POS>"
TEXT_KINDS = ("canonical", "paraphrase", "non_actionable", "empty")
TIERS = ("low", "medium", "high")
NO_FAMILY = -1  # family of a text that belongs to no scenario family (non-actionable)

#: Canonical templates, index = family index (paper, warning-template table).
TEMPLATES: tuple[str, ...] = (
    "The pedestrian at position <FRONT_CAR_POS> is about to enter the ego lane.",
    "The vehicle at position <FRONT_CAR_POS> will cut into the ego lane soon.",
    "The static object at position <FRONT_CAR_POS> is blocking the ego lane.",
    "A wrong-way vehicle at position <FRONT_CAR_POS> will cross the ego left-turn path. "
    "Yield before turning left.",
    "A wrong-way vehicle at position <FRONT_CAR_POS> will cross the ego right-turn path. "
    "Yield before turning right.",
    "The vehicle at position <FRONT_CAR_POS> will cross the ego right-turn path. "
    "Yield before turning right.",
)
assert len(TEMPLATES) == len(FAMILIES)

P = TOKEN
#: Paraphrases per family and tier (three each).  The first low-tier text of each family keeps
#: id ``6 + family``.
PARAPHRASES: dict[str, dict[str, tuple[str, ...]]] = {
    "PE": {
        "low": (
            f"Watch out: someone on foot near {P} is stepping into your lane.",
            f"A pedestrian at {P} is about to step into the ego lane.",
            f"Caution, a person walking at {P} will enter your lane in a moment.",
        ),
        "medium": (
            f"Someone near {P} may end up on the road ahead.",
            f"There is movement at the roadside near {P} that could reach your path.",
            f"Keep an eye on the area around {P} as it may not stay clear.",
        ),
        "high": (
            "Someone may cross in front of you.",
            "Watch for people near the road ahead.",
            "A road user may step out ahead.",
        ),
    },
    "VC": {
        "low": (
            f"A car around {P} is about to merge in front of you.",
            f"The vehicle at {P} is going to change into the ego lane shortly.",
            f"Heads up: the car at {P} will move into your lane soon.",
        ),
        "medium": (
            f"The car near {P} may not stay in its lane.",
            f"Traffic beside you near {P} could come across.",
            f"Watch the vehicle around {P} because its path may meet yours.",
        ),
        "high": (
            "A nearby vehicle may change lanes.",
            "Another car may move in front of you.",
            "Watch for merging traffic.",
        ),
    },
    "OR": {
        "low": (
            f"Something is stopped in your lane near {P} and the road ahead is blocked.",
            f"A stationary object at {P} is obstructing the ego lane.",
            f"The ego lane is blocked by a stopped object at {P} ahead.",
        ),
        "medium": (
            f"The lane near {P} is not clear.",
            f"There may be something on the road around {P} ahead.",
            f"Expect an obstruction near {P} on your way.",
        ),
        "high": (
            "The road ahead may be blocked.",
            "There may be an obstacle ahead.",
            "The way ahead may not be clear.",
        ),
    },
    "LWW": {
        "low": (
            f"A car driving against traffic near {P} will pass through your left turn. "
            "Wait before turning.",
            f"A vehicle going the wrong way at {P} will cut across your left turn. "
            "Yield before turning left.",
            f"Wrong-way traffic at {P} is about to cross the ego left-turn path, so give way "
            "before the turn.",
        ),
        "medium": (
            f"A car near {P} is not following the usual direction. Take care in the left turn.",
            f"Oncoming traffic near {P} may be in the wrong lane for your left turn.",
            f"The left turn may not be clear, so check the vehicle near {P} first.",
        ),
        "high": (
            "Take care when turning left.",
            "Another vehicle may be in your way in the turn.",
            "Be ready to wait before turning left.",
        ),
    },
    "RWW": {
        "low": (
            f"A car driving against traffic near {P} will pass through your right turn. "
            "Wait before turning.",
            f"A vehicle going the wrong way at {P} will cut across your right turn. "
            "Yield before turning right.",
            f"Wrong-way traffic at {P} is about to cross the ego right-turn path, so give way "
            "before the turn.",
        ),
        "medium": (
            f"A car near {P} is not following the usual direction. Take care in the right turn.",
            f"Oncoming traffic near {P} may be in the wrong lane for your right turn.",
            f"The right turn may not be clear, so check the vehicle near {P} first.",
        ),
        "high": (
            "Take care when turning right.",
            "Another vehicle may be in your way in the turn.",
            "Be ready to wait before turning right.",
        ),
    },
    "RTY": {
        "low": (
            f"Cross traffic near {P} is heading through your right turn. Let it pass first.",
            f"A vehicle at {P} is about to cross the ego right-turn path. Give way before "
            "turning right.",
            f"The car at {P} will pass through your right turn, so wait for it before turning.",
        ),
        "medium": (
            f"Traffic near {P} may be coming through the junction.",
            f"The junction near {P} may not be clear for your turn.",
            f"Check the crossing traffic around {P} before the right turn.",
        ),
        "high": (
            "Traffic may be crossing ahead.",
            "Be careful at the junction.",
            "Other vehicles may need to pass first.",
        ),
    },
}
del P

#: The five non-actionable warnings of the paper's appendix, verbatim.
NON_ACTIONABLE: tuple[str, ...] = (
    "Caution: maintenance equipment is operating behind the roadside barrier.",
    "Warning: a delivery van is parked in an off-road service area.",
    "Caution: a pedestrian is waiting behind a roadside fence and remains clear of traffic.",
    "Warning: a cyclist is traveling away on a physically separated path.",
    "Caution: traffic is restricted on a parallel road outside the ego route.",
)

#: Ego-frame positions (x forward, y right; m) of the distance-conditioned diagnostic (paper).
DISTANCE_POSITIONS: dict[str, tuple[float, float]] = {"near": (12.0, 0.5), "far": (100.0, 0.5)}


@dataclass(frozen=True)
class WarningText:
    """One entry of the text bank."""

    text_id: int
    family: int  # family index (family_codes.codes()), NO_FAMILY for non-actionable texts
    kind: str  # one of TEXT_KINDS
    text: str  # may contain TOKEN (then it states a position)
    tier: str = ""  # one of TIERS for paraphrases, "" otherwise

    @property
    def has_position(self) -> bool:
        """The text states a position (contains ``<FRONT_CAR_POS>``)."""
        return TOKEN in self.text


def _family_index(family: int | str, allow_none: bool = False) -> int:
    if isinstance(family, str):
        return family_codes.index(family)
    f = int(family)
    if allow_none and f == NO_FAMILY:
        return f
    family_codes.code(f)  # raises for an unknown index
    return f


def _check_entry(kind: str, tier: str, text: str) -> None:
    """Bank rules: spacing around the placeholder, at most one position, tiers consistent; only
    the empty text is empty."""
    if kind == "empty":
        if text != "" or tier:
            raise ValueError(f"text: the empty text has no words and no tier, got {text!r}")
        return
    language.check_template(text, TOKEN)
    n = text.count(TOKEN)
    if n > 1:
        raise ValueError(f"text: states {n} positions; a warning grounds one ({text!r})")
    if kind == "paraphrase" and tier not in TIERS:
        raise ValueError(f"tier: {tier!r} not one of {{{', '.join(TIERS)}}}")
    if kind != "paraphrase" and tier:
        raise ValueError(f"tier: only paraphrases have a tier, got {tier!r} for kind {kind!r}")
    if tier in ("low", "medium") and n != 1:
        raise ValueError(f"text: a {tier}-ambiguity paraphrase must state the position ({text!r})")
    if tier == "high" and n:
        raise ValueError(f"text: a high-ambiguity paraphrase states no position ({text!r})")


def _initial_entries() -> tuple[WarningText, ...]:
    bank = [WarningText(i, i, "canonical", t) for i, t in enumerate(TEMPLATES)]
    for f, fam in enumerate(FAMILIES):
        bank.append(WarningText(len(bank), f, "paraphrase", PARAPHRASES[fam]["low"][0], "low"))
    for f, fam in enumerate(FAMILIES):
        for tier in TIERS:
            for text in PARAPHRASES[fam][tier][1 if tier == "low" else 0 :]:
                bank.append(WarningText(len(bank), f, "paraphrase", text, tier))
    for text in NON_ACTIONABLE:
        bank.append(WarningText(len(bank), NO_FAMILY, "non_actionable", text))
    bank.append(WarningText(len(bank), NO_FAMILY, "empty", ""))
    for e in bank:
        _check_entry(e.kind, e.tier, e.text)
    return tuple(bank)


@dataclass(frozen=True)
class TextBank:
    """The warning texts a simulation knows: an immutable value (hashable, so it can be a
    static part of a compiled program's settings, :class:`lantern_jax.sim.settings.Settings`).

    Attributes:
        entries: the texts in id order (``entries[i].text_id == i``).
    """

    entries: tuple[WarningText, ...]

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self):
        return iter(self.entries)

    def __getitem__(self, text_id: int) -> WarningText:
        return self.get(text_id)

    def get(self, text_id: int) -> WarningText:
        """The entry with ``text_id``.

        Raises:
            ValueError: for an id outside the bank.
        """
        i = int(text_id)
        if not 0 <= i < len(self.entries):
            raise ValueError(f"text_id: {i} outside 0..{len(self.entries) - 1}")
        return self.entries[i]

    def with_text(self, family: int | str, kind: str, text: str, tier: str = "") -> TextBank:
        """A new bank with one more text (its id is the old bank's length).

        Args:
            family: family index or code (``NO_FAMILY`` allowed for non-actionable texts).
            kind: ``"paraphrase"`` or ``"non_actionable"``.
            text: the template (spacing rule: :func:`lantern_jax.language.check_template`).
            tier: the ambiguity tier of a paraphrase.

        Raises:
            ValueError: for an unknown family, kind or tier, a canonical or empty text, a text
                that breaks the spacing rule or its tier's position rule.
        """
        if kind not in TEXT_KINDS:
            raise ValueError(f"kind: {kind!r} not one of {{{', '.join(TEXT_KINDS)}}}")
        if kind in ("canonical", "empty"):
            raise ValueError(
                f"kind: the {kind} texts are fixed; add a paraphrase or a non-actionable text"
            )
        f = _family_index(family, allow_none=kind == "non_actionable")
        _check_entry(kind, tier, text)
        entry = WarningText(len(self.entries), f, kind, text, tier)
        return TextBank((*self.entries, entry))

    def with_replaced_text(self, text_id: int, text: str) -> TextBank:
        """A new bank in which entry ``text_id`` reads ``text`` (same id, family, kind and
        tier): a wording experiment on one warning, e.g. the exact warning of a family.

        Raises:
            ValueError: for an id outside the bank, the empty text, or a text that breaks the
                bank's rules for the entry's kind and tier.
        """
        old = self.get(text_id)
        if old.kind == "empty":
            raise ValueError(f"text_id: {old.text_id} is the empty text; it has no words")
        _check_entry(old.kind, old.tier, text)
        entries = list(self.entries)
        entries[old.text_id] = dataclasses.replace(old, text=text)
        return TextBank(tuple(entries))


#: The built-in bank; canonical entries first so that ``text_id == family`` for them.
DEFAULT_BANK = TextBank(_initial_entries())
#: Id of the empty text (no words; see the module docstring).
EMPTY_TEXT_ID = next(e.text_id for e in DEFAULT_BANK if e.kind == "empty")


#: Registered families' texts (:func:`add_family_texts`), by family index in registration order:
#: ``(kind, tier, text)`` entries, the exact warning first.
_FAMILY_TEXTS: dict[int, tuple[tuple[str, str, str], ...]] = {}


def registered_bank() -> TextBank:
    """The built-in bank followed by the texts of every registered family (in registration
    order): the bank of :func:`lantern_jax.sim.settings.default_settings`, and the one every
    function of this module reads when given no bank.  Equal to :data:`DEFAULT_BANK` when no
    family is registered."""
    return _registered_bank(tuple(_FAMILY_TEXTS.items()))


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
    f = _family_index(family)
    if f < len(FAMILIES):
        return len(TEMPLATES) + f
    return _family_paraphrases(f, bank)[0]


def canonical_text_id(family: int | str, bank: TextBank | None = None) -> int:
    """Text id of a family's exact warning: the family index for the six built-in families, the
    entry :func:`add_family_texts` added for a registered one.

    Raises:
        ValueError: for an unknown family or a registered family without texts in the bank.
    """
    f = _family_index(family)
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


def add_family_texts(family: int | str, warning: str, paraphrases: dict[str, Sequence[str]]
                     ) -> tuple[int, tuple[int, ...]]:  # fmt: skip
    """Register a registered family's exact warning and paraphrases (once): they follow the
    built-in texts in :func:`registered_bank`.

    Args:
        family: a registered family's code or index (not one of the six built-in families,
            whose texts are fixed).
        warning: the exact warning (kind ``"canonical"``), in the templates' style, with
            ``<FRONT_CAR_POS>`` where the grounded position goes.
        paraphrases: ambiguity tier -> held-out paraphrases (the bank's tier rules apply: low
            and medium state the position, high does not).

    Returns:
        ``(warning id, paraphrase ids)`` in :func:`registered_bank`.  Adding the same texts for
        the same family again adds nothing and returns the ids they already have.

    Raises:
        ValueError: for a built-in family, a family that already has other texts, or a text
            that breaks the bank's rules.
    """
    f = _family_index(family)
    if f < len(FAMILIES):
        raise ValueError(f"family: {family_codes.code(f)!r} is built in; its texts are fixed")
    entries = [("canonical", "", warning)]
    for tier, texts in paraphrases.items():
        entries += [("paraphrase", tier, t) for t in texts]
    for kind, tier, text in entries:
        _check_entry(kind, tier, text)
    have = _FAMILY_TEXTS.get(f)
    if have is not None and list(have) != entries:
        raise ValueError(f"family: {family_codes.code(f)!r} already has other texts")
    _FAMILY_TEXTS[f] = tuple(entries)
    ids = [e.text_id for e in registered_bank() if e.family == f]
    return ids[0], tuple(ids[1:])


def tier_text_ids(family: int | str, tier: str, bank: TextBank | None = None) -> tuple[int, ...]:
    """Ids of a family's paraphrases of one ambiguity tier, in bank order."""
    f = _family_index(family)
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
    fam = [_family_index(f) for f in families]
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
            _family_index(f), bank
        )
        out[i] = ids[(r // len(TIERS)) % len(ids)]
    return out


def paraphrase_text_ids(config) -> np.ndarray:
    """(n,) int32: the held-out paraphrase of every execution of a batched config, by tier.

    The pair key is the pair's generation seed (``ExecutionConfig.noise_seed``, from the pair
    parameters' ``seed``), so the tiers are those of :func:`ambiguity_tiers` over the batch
    (40 / 40 / 40 on the 120-pair suite) whatever the batch order.  Outside ``jit``.

    Args:
        config: an :class:`~lantern_jax.world.ExecutionConfig` with a leading batch axis (the
            Route A executions of a suite, one per pair).
    """
    families = np.asarray(config.family).reshape(-1)
    keys = [str(int(k)) for k in np.asarray(config.noise_seed).reshape(-1)]
    return held_out_text_ids(families.tolist(), keys)


def paraphrase_tiers(config) -> np.ndarray:
    """(n,) int: the ambiguity tier (index into :data:`TIERS`) that :func:`paraphrase_text_ids`
    uses for every execution of a batched config."""
    families = np.asarray(config.family).reshape(-1)
    keys = [str(int(k)) for k in np.asarray(config.noise_seed).reshape(-1)]
    return ambiguity_tiers(families.tolist(), keys)


# ---------------------------------------------------------------------------------------------
# rendering, grounding and the token tables
# ---------------------------------------------------------------------------------------------
def format_position(pos_ego_xy) -> str:
    """``"(x, y)"`` as a warning writes it (:func:`lantern_jax.language.format_number`: one
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
    from lantern_jax.geometry import world_to_ego

    return world_to_ego(jnp.asarray(hazard_xy), jnp.asarray(ego_xy), jnp.asarray(ego_yaw))


@dataclass(frozen=True)
class TextTables:
    """What a rollout looks up by text id (built once per bank size, read-only NumPy arrays).

    Attributes:
        tokens: (num_texts, MAX_TOKENS) int32, padded token ids of every text, a written
            position as two number tokens (:func:`lantern_jax.language.tokenize`).
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
    """The per-text tables a rollout indexes by text id (:class:`TextTables`), built once per
    bank (outside ``jit``; the arrays are read-only).

    Raises:
        lantern_jax.language.LanguageAssetError: when the tokenizer file is missing.
        ValueError: naming a text longer than ``MAX_TOKENS`` tokens.
    """
    return _text_tables(_bank(bank))


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
        bank: static; the text bank (default: :func:`registered_bank` when traced; the
            simulator always passes its settings' bank).

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
    changes only what the policy reads (:func:`~lantern_jax.scenarios.protocol.delivered_warning`),
    not the protocol's times or the scoring.  A text that states no position delivers none.

    Args:
        scenario: one :class:`~lantern_jax.world.Scenario` or a batch (leading axis).
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
