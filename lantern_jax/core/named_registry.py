"""An ordered table of named entries, the shape every extension point's registry shares.

:class:`NamedRegistry` keeps entries by key in registration order: registering an entry equal to
the one a key holds returns the held one, another entry under a held key is refused, and
:meth:`~NamedRegistry.snapshot` / :meth:`~NamedRegistry.restore` forget what was registered
since a point (tests, a notebook trying a family or a sensor).  A registry says what it holds
(:attr:`~NamedRegistry.kind`, :attr:`~NamedRegistry.entry_type`), how an entry is keyed
(:meth:`~NamedRegistry.key_of`) and what else it checks or records on registration
(:meth:`~NamedRegistry.check`, :meth:`~NamedRegistry.added`).  The scenario families
(:class:`lantern_jax.scenarios.family_registry.FamilyRegistry`) and the sensors
(:class:`lantern_jax.sensors.registry.SensorRegistry`) are such tables.
"""

from __future__ import annotations

from typing import Any, ClassVar, Generic, TypeVar

E = TypeVar("E")


class NamedRegistry(Generic[E]):
    """Entries of one type by key, in registration order (see the module docstring)."""

    #: What an entry is, in messages ("family", "sensor").
    kind: ClassVar[str] = "entry"
    #: The type every entry must have.
    entry_type: ClassVar[type] = object

    def __init__(self) -> None:
        self._entries: dict[str, E] = {}

    def key_of(self, entry: E) -> str:
        """The key an entry is held under."""
        raise NotImplementedError

    def check(self, entry: E) -> None:
        """Refuse a malformed entry (raise ``ValueError`` naming the field); default: none."""

    def added(self, entry: E) -> None:
        """Called once when a new entry is registered, before it is held; default: nothing."""

    def register(self, entry: E) -> E:
        """Add an entry; return the entry held (registering an equal entry again is a no-op).

        Raises:
            TypeError: for something that is not an :attr:`entry_type`.
            ValueError: for a malformed entry (:meth:`check`) or a key held by another entry.
        """
        if not isinstance(entry, self.entry_type):
            raise TypeError(f"{self.kind} registry: expected a {self.entry_type.__name__}, "
                            f"got {type(entry).__name__}")  # fmt: skip
        self.check(entry)
        key = self.key_of(entry)
        have = self._entries.get(key)
        if have is not None:
            if have != entry:
                raise ValueError(f"{self.kind} {key!r}: already registered as another {self.kind}")
            return have
        self.added(entry)
        self._entries[key] = entry
        return entry

    def held(self, key: Any) -> E | None:
        """The entry held under ``key``, or ``None``."""
        return self._entries.get(key) if isinstance(key, str) else None

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and key in self._entries

    def keys(self) -> tuple[str, ...]:
        """Every key, in registration order."""
        return tuple(self._entries)

    def snapshot(self) -> tuple[E, ...]:
        """The entries as they are now, for :meth:`restore`."""
        return tuple(self._entries.values())

    def restore(self, state: tuple[E, ...]) -> None:
        """Forget every entry registered since ``state`` was taken (:meth:`snapshot`)."""
        self._entries = {self.key_of(e): e for e in state}
