"""The warning texts and the immutable bank that holds them: the six canonical templates, the
paraphrases of every family by ambiguity tier, the non-actionable warnings, the empty text, and
:class:`TextBank` with the built-in :data:`DEFAULT_BANK` (ids and tiers:
:mod:`lantern_jax.scenarios.warnings`, which adds the registered families' texts, rendering,
grounding and the token tables, and re-exports these names).

The templates are verbatim from the paper's warning-template table and the non-actionable
warnings from its appendix.  ``<FRONT_CAR_POS>`` (:data:`TOKEN`) marks where a text states the
hazard's position.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES
from lantern_jax.types import language

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

#: The held-out probes of the language diagnostic
#: (:mod:`lantern_jax.apps.language_sensitivity`): sentences that state the hazard's position
#: and ask for no reaction.  They are in no bank that a suite, the dataset or a training recipe
#: reads (the diagnostic appends them to its own), so no model of the package trains on them.
PROBE_IRRELEVANT = f"The bakery at position {TOKEN} sells fresh bread today."
PROBE_NEGATED = f"Nothing is at position {TOKEN}; the ego lane is clear."

#: Sentences that state a position and ask for no reaction, for **training only**
#: (:mod:`lantern_jax.apps.training.counterfactual`, the ``distractors`` setting): six negations
#: and six irrelevant statements.  None is a probe above, none shares a probe's wording beyond
#: "at position" (no "Nothing", "clear", "ego lane", "bakery"), and no suite or dataset bank
#: holds them, so the language diagnostic's probes stay unseen by a model trained with them.
TRAINING_DISTRACTORS: tuple[str, ...] = (
    f"No pedestrian is at position {TOKEN}; the crossing is empty.",
    f"There is no stopped vehicle at position {TOKEN}.",
    f"No obstacle was found at position {TOKEN}; drive on normally.",
    f"The road at position {TOKEN} is free of hazards.",
    f"No oncoming car is at position {TOKEN}; the junction is free.",
    f"The earlier alert about position {TOKEN} is cancelled; no hazard remains.",
    f"The cafe at position {TOKEN} opens at nine in the morning.",
    f"A billboard at position {TOKEN} advertises a summer concert.",
    f"The parking garage at position {TOKEN} has free spaces tonight.",
    f"A street festival took place at position {TOKEN} last weekend.",
    f"The weather station at position {TOKEN} reports a light breeze.",
    f"The museum at position {TOKEN} is closed on Mondays.",
)

#: More training-only distractors (the ``distractor_texts = "position_and_lane"`` setting of the
#: closed-loop recipe): negations and irrelevant statements that use the actionable templates'
#: own phrases ("the ego lane", "the ego left-turn path", "cut into", "cross").  Every
#: actionable template and most paraphrases say "the ego lane" or "your lane", so a model that
#: never sees the phrase in a sentence asking for no reaction can take the phrase alone as the
#: hazard cue.  These still are not the probes and use none of their own words ("Nothing",
#: "clear", "bakery", "bread"): the held-out negated probe shares with them only the phrases
#: every actionable template has, and its negation words stay unseen.
TRAINING_LANE_DISTRACTORS: tuple[str, ...] = (
    f"No vehicle at position {TOKEN} will cut into the ego lane.",
    f"No pedestrian at position {TOKEN} is about to enter the ego lane.",
    f"The ego lane at position {TOKEN} is open; no object is blocking it.",
    f"No wrong-way vehicle at position {TOKEN} will cross the ego left-turn path.",
    f"The ego right-turn path at position {TOKEN} has no crossing traffic.",
    f"The flower shop at position {TOKEN} is beside the ego lane.",
    f"A mural at position {TOKEN} faces the ego lane.",
    f"The ego lane passes a library at position {TOKEN}.",
)

#: Training-only negations in other forms than "no" (the ``distractor_texts =
#: "position_lane_negations"`` setting): the actionable templates with "not", "never",
#: "isn't", "won't", "none of" or "neither ... nor" in them.  Every negation of the two sets
#: above starts with or turns on "no", so a model can learn that one word as the cue and still
#: react to a negation without it (the held-out probe negates with "Nothing" and "clear").
#: These keep the templates' words and change only the negation, and still use none of the
#: probes' own words.
TRAINING_NEGATION_DISTRACTORS: tuple[str, ...] = (
    f"The vehicle at position {TOKEN} will not cut into the ego lane.",
    f"The pedestrian at position {TOKEN} is not going to enter the ego lane.",
    f"The static object at position {TOKEN} isn't blocking the ego lane.",
    f"A wrong-way vehicle at position {TOKEN} will never cross the ego left-turn path.",
    f"The vehicle at position {TOKEN} won't cross the ego right-turn path; do not yield.",
    f"None of the cars at position {TOKEN} will move into the ego lane.",
    f"Neither a person nor a car at position {TOKEN} is near the ego lane.",
)

#: The distractor sets a closed-loop recipe may draw from (``distractor_texts``); each extends
#: the one before it, id for id.
DISTRACTOR_SETS: dict[str, tuple[str, ...]] = {
    "position": TRAINING_DISTRACTORS,
    "position_and_lane": TRAINING_DISTRACTORS + TRAINING_LANE_DISTRACTORS,
    "position_lane_negations": (
        TRAINING_DISTRACTORS + TRAINING_LANE_DISTRACTORS + TRAINING_NEGATION_DISTRACTORS
    ),
}


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


def family_index(family: int | str, allow_none: bool = False) -> int:
    """A family's index from its code or index (raises for an unknown one; ``NO_FAMILY`` only
    with ``allow_none``)."""
    if isinstance(family, str):
        return family_codes.index(family)
    f = int(family)
    if allow_none and f == NO_FAMILY:
        return f
    family_codes.code(f)  # raises for an unknown index
    return f


def check_entry(kind: str, tier: str, text: str) -> None:
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
        check_entry(e.kind, e.tier, e.text)
    return tuple(bank)


@dataclass(frozen=True)
class TextBank:
    """The warning texts a simulation knows: an immutable, hashable value.

    In a compiled program the bank is an argument, not part of the program: it is a JAX pytree
    whose leaves are its token tables, padded to a multiple of
    :data:`lantern_jax.scenarios.warnings.TEXT_CAPACITY_STEP` texts
    (:mod:`lantern_jax.scenarios.warnings` registers it), so a changed or added text runs the
    program already compiled.  Inside a trace the bank is rebuilt from those leaves: ``tables``
    holds them and ``entries`` is empty.

    Attributes:
        entries: the texts in id order (``entries[i].text_id == i``).
        tables: ``None`` on the host; inside a trace, the padded
            :class:`~lantern_jax.scenarios.warnings.TextTables` of traced arrays.
    """

    entries: tuple[WarningText, ...]
    tables: Any = dataclasses.field(default=None, compare=False, repr=False)

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
            text: the template (spacing rule: :func:`lantern_jax.types.language.check_template`).
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
        f = family_index(family, allow_none=kind == "non_actionable")
        check_entry(kind, tier, text)
        entry = WarningText(len(self.entries), f, kind, text, tier)
        return TextBank((*self.entries, entry))

    def with_unrelated_texts(self, texts: tuple[str, ...]) -> tuple[TextBank, tuple[int, ...]]:
        """A new bank with ``texts`` appended as non-actionable texts of no family (sentences
        that name no hazard of the route), and their ids in it, in order.

        Raises:
            ValueError: as :meth:`with_text`, for a text that breaks the spacing rule.
        """
        bank, ids = self, []
        for text in texts:
            ids.append(len(bank))
            bank = bank.with_text(NO_FAMILY, "non_actionable", text)
        return bank, tuple(ids)

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
        check_entry(old.kind, old.tier, text)
        entries = list(self.entries)
        entries[old.text_id] = dataclasses.replace(old, text=text)
        return TextBank(tuple(entries))


#: The built-in bank; canonical entries first so that ``text_id == family`` for them.
DEFAULT_BANK = TextBank(_initial_entries())
#: Id of the empty text (no words; see the module docstring).
EMPTY_TEXT_ID = next(e.text_id for e in DEFAULT_BANK if e.kind == "empty")
