"""Cooperative warning texts: the six canonical templates, a text bank, rendering and grounding.

The templates are verbatim from the paper's warning-template table.  The token
``<FRONT_CAR_POS>`` is never shown literally: at every step it is replaced by the hazard (or
conflict) position ``(x, y)`` in metres in the *current ego frame*, ``x`` forward and ``y`` to
the **right** (the paper's convention), formatted with one decimal.

The text bank is a list of :class:`WarningText` entries; the canonical template of family ``f``
has ``text_id == f`` (ids 0-5), and further entries (held-out paraphrases, non-actionable texts,
distance-conditioned variants) are appended with :func:`add_text`, so existing ids never change.
Inside the simulator a warning is just ``(active, text_id, grounded position)``; the strings are
produced outside ``jit`` by :func:`render_warning` for language policies.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import FAMILIES

TOKEN = "<FRONT_CAR_POS>"
TEXT_KINDS = ("canonical", "paraphrase", "non_actionable")

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


@dataclass(frozen=True)
class WarningText:
    """One entry of the text bank."""

    text_id: int
    family: int  # index into constants.FAMILIES
    kind: str  # one of TEXT_KINDS
    text: str  # may contain TOKEN (non-actionable texts need not)


def _family_index(family: int | str) -> int:
    if isinstance(family, str):
        if family not in FAMILIES:
            raise ValueError(f"family: {family!r} not one of {{{', '.join(FAMILIES)}}}")
        return FAMILIES.index(family)
    f = int(family)
    if not 0 <= f < len(FAMILIES):
        raise ValueError(f"family: {f} outside 0..{len(FAMILIES) - 1}")
    return f


#: The text bank; canonical entries first so that ``text_id == family`` for them.
TEXT_BANK: list[WarningText] = [WarningText(i, i, "canonical", t) for i, t in enumerate(TEMPLATES)]

#: Held-out paraphrases (ids 6-11, family order): same meaning, different wording.  Used by the
#: ``held_out_paraphrase`` ablation; a policy built for the canonical wording need not
#: understand them.
PARAPHRASES: tuple[str, ...] = (
    "Watch out: someone on foot near <FRONT_CAR_POS> is stepping into your lane.",
    "A car around <FRONT_CAR_POS> is about to merge in front of you.",
    "Something is stopped in your lane near <FRONT_CAR_POS>; the road ahead is blocked.",
    "A car driving against traffic near <FRONT_CAR_POS> will pass through your left turn. "
    "Wait before turning.",
    "A car driving against traffic near <FRONT_CAR_POS> will pass through your right turn. "
    "Wait before turning.",
    "Cross traffic near <FRONT_CAR_POS> is heading through your right turn. Let it pass first.",
)
TEXT_BANK += [
    WarningText(len(TEMPLATES) + i, i, "paraphrase", t) for i, t in enumerate(PARAPHRASES)
]


def paraphrase_text_id(family: int) -> int:
    """Text id of a family's held-out paraphrase."""
    return len(TEMPLATES) + int(family)


def add_text(family: int | str, kind: str, text: str) -> int:
    """Append a text to :data:`TEXT_BANK` and return its new ``text_id``.

    Raises:
        ValueError: for an unknown family or kind, an empty text, or a second canonical text.
    """
    f = _family_index(family)
    if kind not in TEXT_KINDS:
        raise ValueError(f"kind: {kind!r} not one of {{{', '.join(TEXT_KINDS)}}}")
    if kind == "canonical":
        raise ValueError("kind: the canonical texts are fixed (ids 0-5)")
    if not isinstance(text, str) or not text.strip():
        raise ValueError("text: must be a non-empty string")
    entry = WarningText(len(TEXT_BANK), f, kind, text)
    TEXT_BANK.append(entry)
    return entry.text_id


def get_text(text_id: int) -> WarningText:
    """The bank entry with ``text_id``."""
    i = int(text_id)
    if not 0 <= i < len(TEXT_BANK):
        raise ValueError(f"text_id: {i} outside 0..{len(TEXT_BANK) - 1}")
    return TEXT_BANK[i]


def format_position(pos_ego_xy) -> str:
    """``"(x, y)"`` with one decimal (``-0.0`` printed as ``0.0``)."""
    p = np.asarray(pos_ego_xy, np.float64).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"pos_ego_xy: expected two finite numbers, got {pos_ego_xy!r}")
    x, y = (round(float(v), 1) + 0.0 for v in p)
    return f"({x:.1f}, {y:.1f})"


def render_warning(text_id: int, pos_ego_xy) -> str:
    """The warning string with ``<FRONT_CAR_POS>`` grounded.

    Args:
        text_id: id in :data:`TEXT_BANK`.
        pos_ego_xy: (2,) m, grounded position in the ego frame (x forward, y right), e.g. the
            output of :func:`ground_position`.

    Example:
        ``render_warning(0, (14.2, 3.1))`` ->
        ``"The pedestrian at position (14.2, 3.1) is about to enter the ego lane."``
    """
    return get_text(text_id).text.replace(TOKEN, format_position(pos_ego_xy))


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
