"""Search spaces: one interface for a family's scenario knobs and for adversarial actor tracks.

A space is a box ``[lo, hi]^K`` of parameter values with names, and what a candidate does to a
pair (:meth:`Space.apply`) and to a pair's parameter dict (:meth:`Space.params`, so a found
candidate is an ordinary suite pair).  A candidate is a vector ``z`` in R^K; its values are
``lo + (hi - lo) * sigmoid(z)``, so every ``z`` maps strictly inside the box and the map is
smooth (optimisers work on ``z`` without projections).  Every method of
:mod:`lantern_jax.apps.stress.search` sees only this interface.

* :class:`SearchSpace` — the family's knobs (its registry entry's ``knobs``; the six's:
  :data:`lantern_jax.scenarios.families.KNOB_RANGES`),
  whose ranges a user may narrow; a range that excludes the frozen suite's own value is refused
  (a search space must contain the benchmark's nominal scenes).
* :class:`AdversarySpace` — adversarial tracks (:mod:`lantern_jax.dynamics.adversary`) of one
  or several actors: ``2 N`` normalised actions in ``[-1, 1]`` per actor (``N`` knots of
  ``knot_s`` seconds, the user's choice); zero actions are the benchmark's scene.
* :class:`ProductSpace` — several spaces searched together (knobs and tracks).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.scenarios.adversary import (
    ADVERSARY_FIELD,
    KNOT_S_RANGE,
    MAX_KNOTS,
    adversary_slots,
    with_tracks,
    without_effect,
)
from lantern_jax.scenarios.families import KNOBS_FIELD, build_pair, family
from lantern_jax.scenarios.knobs import apply_knobs, get_knobs, knob
from lantern_jax.scenarios.suite import Suite
from lantern_jax.types.world import Scenario

Array = jax.Array

INTERIOR = 1e-4  # share of a range kept between a boundary value and its unconstrained image


@dataclasses.dataclass(frozen=True)
class Space:
    """A box of parameter values (see the module docstring); subclasses say what they mean."""

    family: str
    names: tuple[str, ...]
    lo: np.ndarray  # (K,) float32, lower bounds
    hi: np.ndarray  # (K,) float32, upper bounds

    @property
    def dim(self) -> int:
        """Number of parameters K."""
        return len(self.names)

    @property
    def shared(self) -> bool:
        """Whether a candidate changes what both routes share (Route B must be re-run)."""
        return False

    @property
    def tracked(self) -> tuple[int, ...]:
        """Actor slots the space drives with adversarial tracks (none for knobs)."""
        return ()

    def key(self) -> tuple:
        """What a compiled program of this space depends on besides its arrays."""
        return (type(self).__name__, self.names)

    def values(self, z: Array) -> Array:
        """(..., K) values strictly inside the box for unconstrained ``z`` (..., K)."""
        lo, hi = jnp.asarray(self.lo), jnp.asarray(self.hi)
        return lo + (hi - lo) * jax.nn.sigmoid(z)

    def unconstrained(self, values: Array) -> Array:
        """The ``z`` mapping to ``values`` (boundary values are moved ``INTERIOR`` inside)."""
        lo, hi = jnp.asarray(self.lo), jnp.asarray(self.hi)
        u = jnp.clip((jnp.asarray(values) - lo) / (hi - lo), INTERIOR, 1.0 - INTERIOR)
        return jnp.log(u) - jnp.log1p(-u)

    def uniform(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, K) float32 values drawn uniformly in the box."""
        u = rng.uniform(0.0, 1.0, (n, self.dim))
        return (self.lo + (self.hi - self.lo) * u).astype(np.float32)

    def as_dict(self, values: Array) -> dict[str, float]:
        """Values of one candidate as plain floats, by name (for tables)."""
        v = np.asarray(values, np.float32)
        return {n: float(v[i]) for i, n in enumerate(self.names)}

    def apply(self, scenario_a: Scenario, scenario_b: Scenario, values: Array) -> tuple:
        """The pair with one candidate's values applied (differentiable in ``values`` (K,))."""
        raise NotImplementedError

    def program_parts(self) -> tuple:
        """What :meth:`apply` calls besides this package's code, for the program store's key
        (:meth:`lantern_jax.apps.stress.objective.Problem.store_identity`): nothing here."""
        return ()

    def params(self, values: Array) -> dict:
        """The fields one candidate adds to a pair's parameter dict (``knobs``, ``adversary``)."""
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class SearchSpace(Space):
    """The knobs searched in one family and their ranges (units of the knobs)."""

    @property
    def shared(self) -> bool:
        """Whether some knob is part of the scene both routes share (Route B must be re-run)."""
        return any(knob(n).shared for n in self.names)

    def apply(self, scenario_a: Scenario, scenario_b: Scenario, values: Array) -> tuple:
        """The pair with the knobs set (differentiable in ``values``, one candidate)."""
        return apply_knobs(scenario_a, scenario_b, {n: values[i] for i, n in enumerate(self.names)})

    def program_parts(self) -> tuple:
        """The knobs set, with their read and write functions (a registered knob may be a
        user's own, which the program store's key cannot describe)."""
        return tuple(knob(n) for n in self.names)

    def params(self, values: Array) -> dict:
        """``{"knobs": {name: value}}``."""
        return {KNOBS_FIELD: self.as_dict(values)}


@dataclasses.dataclass(frozen=True)
class AdversarySpace(Space):
    """Adversarial tracks of ``slots``: per slot ``knots`` accelerations then ``knots`` lateral
    rates, normalised to ``[-1, 1]`` (:mod:`lantern_jax.scenarios.adversary`)."""

    slots: tuple[int, ...] = ()
    kinds: tuple[int, ...] = ()  # KIND_* of each slot (its kinematic limits)
    knots: int = 16
    knot_s: float = 0.5  # s

    @property
    def tracked(self) -> tuple[int, ...]:
        """The slots with tracks."""
        return self.slots

    def key(self) -> tuple:
        """Names, slots, kinds, knots and knot length fix a compiled program."""
        return (type(self).__name__, self.names, self.slots, self.kinds, self.knots, self.knot_s)

    def actions(self, values: Array) -> tuple[Array, Array]:
        """``(accel, lateral)`` normalised actions, each (T, N), of one candidate (K,)."""
        v = jnp.reshape(jnp.asarray(values), (len(self.slots), 2, self.knots))
        return v[:, 0], v[:, 1]

    def apply(self, scenario_a: Scenario, scenario_b: Scenario, values: Array) -> tuple:
        """Route A with the tracks, Route B with an all-zero track of the same shape."""
        acc, lat = self.actions(values)
        a = with_tracks(scenario_a, self.slots, self.kinds, acc, lat, self.knot_s)
        return a, without_effect(scenario_b, self.knots, self.knot_s)

    def params(self, values: Array) -> dict:
        """``{"adversary": {"knot_s": h, "tracks": [...]}}`` (float32 values, exactly)."""
        v = np.asarray(values, np.float32).reshape(len(self.slots), 2, self.knots)
        tracks = [
            dict(slot=int(s), accel=[float(x) for x in v[i, 0]],
                 lateral=[float(x) for x in v[i, 1]])
            for i, s in enumerate(self.slots)
        ]  # fmt: skip
        return {ADVERSARY_FIELD: dict(knot_s=float(self.knot_s), tracks=tracks)}


@dataclasses.dataclass(frozen=True)
class ProductSpace(Space):
    """Several spaces of one family searched together, in the order given (knobs first: a track
    starts from the speed the knobs set)."""

    parts: tuple[Space, ...] = ()

    @property
    def shared(self) -> bool:
        """Whether any part changes what both routes share."""
        return any(p.shared for p in self.parts)

    @property
    def tracked(self) -> tuple[int, ...]:
        """The slots any part drives."""
        return tuple(s for p in self.parts for s in p.tracked)

    def key(self) -> tuple:
        """The parts' keys."""
        return (type(self).__name__, *(p.key() for p in self.parts))

    def _slices(self) -> list[slice]:
        edges = np.cumsum([0] + [p.dim for p in self.parts])
        return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]

    def program_parts(self) -> tuple:
        """The parts' own."""
        return tuple(x for p in self.parts for x in p.program_parts())

    def apply(self, scenario_a: Scenario, scenario_b: Scenario, values: Array) -> tuple:
        """Every part applied in turn."""
        for p, sl in zip(self.parts, self._slices(), strict=True):
            scenario_a, scenario_b = p.apply(scenario_a, scenario_b, values[sl])
        return scenario_a, scenario_b

    def params(self, values: Array) -> dict:
        """Every part's fields."""
        out: dict = {}
        for p, sl in zip(self.parts, self._slices(), strict=True):
            out.update(p.params(np.asarray(values)[sl]))
        return out


def product_space(*parts: Space) -> ProductSpace:
    """The spaces ``parts`` (of one family) searched together.

    Raises:
        ValueError: for parts of different families or a slot driven twice.
    """
    fams = {p.family for p in parts}
    if len(fams) != 1:
        raise ValueError(f"spaces of different families: {sorted(fams)}")
    tracked = [s for p in parts for s in p.tracked]
    if len(set(tracked)) != len(tracked):
        raise ValueError(f"a slot is driven by two spaces: {tracked}")
    return ProductSpace(
        parts[0].family, tuple(n for p in parts for n in p.names),
        np.concatenate([p.lo for p in parts]).astype(np.float32),
        np.concatenate([p.hi for p in parts]).astype(np.float32), parts=tuple(parts),
    )  # fmt: skip


def adversary_space(
    scenario_a: Scenario, family_code: str, actors: Sequence[str] = ("hazard",), knots: int = 16,
    knot_s: float = 0.5, background: int = 1,
) -> AdversarySpace:  # fmt: skip
    """The adversarial-track space of a pair's actors.

    Args:
        scenario_a: the pair's Route A (concrete; the actors are chosen on it).
        family_code: ``"PE"``, ...
        actors: groups of :func:`lantern_jax.scenarios.adversary.adversary_slots`
            (``hazard``, ``background``).
        knots: knots per track N (the space has ``2 N`` dimensions per actor).
        knot_s: s, knot length.
        background: background vehicles that ``background`` names.

    Raises:
        ValueError: naming a bad number of knots, knot length, actor group or count.
    """
    if isinstance(knots, bool) or not isinstance(knots, int) or not 1 <= knots <= MAX_KNOTS:
        raise ValueError(f"knots: expected a whole number in [1, {MAX_KNOTS}], got {knots!r}")
    lo, hi = KNOT_S_RANGE
    if not (np.isfinite(knot_s) and lo <= knot_s <= hi):
        raise ValueError(f"knot_s: expected seconds in [{lo:g}, {hi:g}], got {knot_s!r}")
    if isinstance(background, bool) or not isinstance(background, int) or background < 1:
        raise ValueError(f"background: expected a whole number >= 1, got {background!r}")
    if not actors:
        raise ValueError("actors: name at least one of hazard, background")
    slots = tuple(adversary_slots(scenario_a, list(actors), background))
    kinds = tuple(int(np.asarray(scenario_a.actors.kind)[s]) for s in slots)
    names = tuple(f"slot{s}.{ch}[{k}]" for s in slots for ch in ("accel", "lateral")
                  for k in range(knots))  # fmt: skip
    one = np.ones(len(names), np.float32)
    return AdversarySpace(family(family_code).code, names, -one, one, slots=slots, kinds=kinds,
                          knots=knots, knot_s=float(knot_s))  # fmt: skip


def search_space(
    family_code: str,
    knobs: Sequence[str] | None = None,
    ranges: dict[str, tuple[float, float]] | None = None,
    suite: Suite | None = None,
) -> SearchSpace:
    """The search space of a family, optionally restricted to some knobs and narrowed ranges.

    Args:
        family_code: ``"PE"``, ...
        knobs: knob names to search (default: every knob of the family).
        ranges: narrower ``(lo, hi)`` per knob (default: the family's documented ranges).
        suite: when given, every range must contain the knob's value in each of the suite's
            pairs of this family.

    Raises:
        ValueError: naming the unknown family, a knob not in the family's space, an empty or
            inverted range, a range outside the documented one, or one that excludes a suite
            value (naming the pair).
    """
    rec = family(family_code)
    table = rec.knobs
    if not table:
        raise ValueError(f"{rec.code}: the family has no stress-testing knobs (its record's knobs)")
    names = tuple(knobs) if knobs else tuple(table)
    unknown = [n for n in names if n not in table]
    if unknown:
        raise ValueError(
            f"{rec.code}: knob(s) {', '.join(unknown)} not in the family's search space "
            f"({', '.join(table)})"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"{rec.code}: a knob is named twice in {list(names)}")
    ranges = dict(ranges or {})
    extra = sorted(set(ranges) - set(names))
    if extra:
        raise ValueError(f"{rec.code}: range given for knob(s) not searched: {', '.join(extra)}")
    lo, hi = [], []
    for n in names:
        d_lo, d_hi = table[n]
        r_lo, r_hi = (float(x) for x in ranges.get(n, (d_lo, d_hi)))
        if not (np.isfinite(r_lo) and np.isfinite(r_hi) and r_lo < r_hi):
            raise ValueError(f"{rec.code}.{n}: range [{r_lo}, {r_hi}] is empty or not finite")
        if r_lo < d_lo - 1e-9 or r_hi > d_hi + 1e-9:
            raise ValueError(
                f"{rec.code}.{n}: range [{r_lo:g}, {r_hi:g}] leaves the documented "
                f"[{d_lo:g}, {d_hi:g}]"
            )
        lo.append(r_lo)
        hi.append(r_hi)
    space = SearchSpace(rec.code, names, np.asarray(lo, np.float32), np.asarray(hi, np.float32))
    if suite is not None:
        _check_contains_suite(space, suite)
    return space


def _check_contains_suite(space: SearchSpace, suite: Suite) -> None:
    for pair in (p for p in suite.pairs if p.family == space.family):
        a, _, _ = build_pair(pair.params)
        current = get_knobs(a, list(space.names))
        for i, n in enumerate(space.names):
            v = float(current[n])
            if not space.lo[i] - 1e-5 <= v <= space.hi[i] + 1e-5:
                raise ValueError(
                    f"{space.family}.{n}: range [{space.lo[i]:g}, {space.hi[i]:g}] excludes "
                    f"the suite's own value {v:g} (pair {pair.pair_id})"
                )
