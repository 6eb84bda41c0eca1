"""The one registry of scenario families: every family the benchmark knows, as one entry each.

A :class:`FamilyEntry` holds everything the package reads about a family: its code and name,
its parameter ranges, its stress-testing knobs, its premise rule, the clearance normaliser
``d_safe`` its scenes carry, its sampler, feasibility check and pair builder, what its warning
asks the ego to do, and (for a family written outside the package) its warning texts and the
user's record.  :data:`FAMILY_REGISTRY` is the single store; the six built-in families are
registered into it by :mod:`lantern_jax.scenarios.families` with the same
:meth:`FamilyRegistry.register` call that :func:`lantern_jax.scenarios.registry.register_family`
ends in for a user's family.  Parameter validation (:func:`lantern_jax.scenarios.spec.
range_errors`), the premise rule (:func:`lantern_jax.scenarios.premise.premise_rule`), the text
bank (:func:`lantern_jax.scenarios.warnings.registered_bank`), the pair builder and the stress
search spaces all read their entry here.

:mod:`lantern_jax.core.family_codes` (below every scenario module) mirrors the codes, names and
indices for the layers that check a family code without building families (the scene types,
the scoring tables); only this registry writes to it.

This module imports no scenario builder (only the built-in texts), so every scenario module may
read the registry; an entry is looked up when it is needed (at sampling, validation or building
time), by which time :mod:`lantern_jax.scenarios.families` has registered the six.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES
from lantern_jax.core.named_registry import NamedRegistry
from lantern_jax.scenarios.warning_texts import TEMPLATES

#: A family's warning texts as the bank holds them: ``(kind, tier, text)``, the exact warning
#: (kind ``"canonical"``) first, then the paraphrases.
Texts = tuple[tuple[str, str, str], ...]


@dataclass(frozen=True)
class FamilyEntry:
    """One family as the benchmark knows it (built-in or registered from user code).

    Attributes:
        code: ``"PE"``, ...; names the family in tables, suite files and pair ids.
        name: the long name (``"Pedestrian Emergence"``).
        ranges: field -> range type (:mod:`lantern_jax.scenarios.spec`), the whole table of a
            parameter dict (the common fields included): the one home of the family's ranges.
        knobs: the stress-testing search space, knob -> (lo, hi) in the knob's units
            (:mod:`lantern_jax.scenarios.knobs`).
        premise: the premise rule (one of :data:`lantern_jax.scenarios.premise.PREMISE_RULES`).
        d_safe: m, the clearance normaliser every scene of the family carries
            (``ExecutionConfig.d_safe``; the paper: 2 m for PE and OR, 3 m otherwise).
        sample: ``(rng, weather) -> params``, a parameter dict.
        check: ``params -> None``, cross-field feasibility (``ValueError`` naming the field).
        build: ``params -> (scenario_a, scenario_b, meta)``.
        response: what the warning asks the ego to do (``families.RESPONSES``; ``""`` for a
            registered family: the built-in policies' keyword rule knows the six only).
        texts: the warning texts a registered family adds to the bank (:data:`Texts`); empty
            for the six, whose texts are fixed in the built-in bank.
        record: the user's :class:`~lantern_jax.scenarios.registry.FamilyRecord` (None for the
            six).
    """

    code: str
    name: str
    ranges: Mapping[str, Any]
    knobs: Mapping[str, tuple[float, float]]
    premise: str
    d_safe: float
    sample: Callable[..., dict]
    check: Callable[[dict], None]
    build: Callable[[dict], tuple]
    response: str = ""
    texts: Texts = ()
    record: Any = None

    @property
    def index(self) -> int:
        """Family index: in ``constants.FAMILIES`` (the paper's order) for the six, then the
        registered families in registration order."""
        return family_codes.index(self.code)

    @property
    def template(self) -> str:
        """The exact warning: the paper's template for the six (warning-template table), a
        registered family's own warning."""
        return self.texts[0][2] if self.texts else TEMPLATES[self.index]

    @property
    def builtin(self) -> bool:
        """Whether this is one of the paper's six families."""
        return self.code in FAMILIES


@dataclass(frozen=True)
class RegistryState:
    """What :meth:`FamilyRegistry.snapshot` saw: the entries and the registered codes."""

    entries: tuple[FamilyEntry, ...]
    codes: tuple[tuple[str, str], ...]


class FamilyRegistry(NamedRegistry[FamilyEntry]):
    """The ordered store of :class:`FamilyEntry` values (the six first, in the paper's order,
    then the registered families in registration order).

    :meth:`register` adds a family's entry and returns the entry held: a built-in code takes its
    fixed index; another code is registered in :mod:`lantern_jax.core.family_codes` (next free
    index); registering an equal entry again returns the one held; it raises ``TypeError`` for
    something that is not a :class:`FamilyEntry` and ``ValueError`` for a code already holding
    another entry (or a malformed code)."""

    kind = "family"
    entry_type = FamilyEntry

    def key_of(self, entry: FamilyEntry) -> str:
        return entry.code

    def added(self, entry: FamilyEntry) -> None:
        """Give a new code its index (:mod:`lantern_jax.core.family_codes`; the six have theirs)."""
        if entry.code not in FAMILIES:
            family_codes.register(entry.code, entry.name)

    def entry(self, code: str) -> FamilyEntry:
        """The entry of a family code.

        Raises:
            ValueError: for an unknown code, naming the known ones.
        """
        found = self.held(code)
        if found is None:
            if code in FAMILIES:  # the six are registered by the families module
                raise ValueError(f"family: {code!r} is not registered yet (import "
                                 "lantern_jax.scenarios.families first)")  # fmt: skip
            raise ValueError(f"family: {code!r} not one of {{{', '.join(self.codes())}}}")
        return found

    def codes(self) -> tuple[str, ...]:
        """Every registered code, in index order."""
        return tuple(sorted(self.keys(), key=family_codes.index))

    def entries(self) -> tuple[FamilyEntry, ...]:
        """Every entry, in index order."""
        return tuple(self._entries[c] for c in self.codes())

    def user_entries(self) -> tuple[FamilyEntry, ...]:
        """The entries registered from user code, in registration order."""
        return tuple(e for e in self.entries() if not e.builtin)

    def snapshot(self) -> RegistryState:  # type: ignore[override]
        """The registry as it is now, for :meth:`restore`."""
        return RegistryState(
            super().snapshot(),
            tuple((c, family_codes.name(c)) for c in family_codes.registered()),
        )

    def restore(self, state: RegistryState) -> None:  # type: ignore[override]
        """Forget every family registered since ``state`` was taken (:meth:`snapshot`)."""
        super().restore(state.entries)
        family_codes.reset(dict(state.codes))


#: The registry of every family the process knows.
FAMILY_REGISTRY = FamilyRegistry()
