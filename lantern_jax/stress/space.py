"""The search space of a family: its knobs, their ranges, and the unconstrained parametrisation.

A candidate is a vector ``z`` in R^K (K knobs); its knob values are ``lo + (hi - lo) *
sigmoid(z)``, so every ``z`` maps strictly inside the documented ranges and the map is smooth
(optimisers work on ``z`` without projections).  The ranges come from the family record
(:data:`lantern_jax.scenarios.families.KNOB_RANGES`) and may be narrowed by the user, but a range
that excludes the frozen suite's own value of that knob is refused: a search space must contain
the benchmark's nominal scenes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.scenarios.families import KNOB_RANGES, build_pair, family
from lantern_jax.scenarios.knobs import apply_knobs, get_knobs, knob
from lantern_jax.scenarios.suite import Suite
from lantern_jax.world import Scenario

Array = jax.Array

INTERIOR = 1e-4  # share of a range kept between a boundary value and its unconstrained image


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """The knobs searched in one family and their ranges (units of the knobs)."""

    family: str
    names: tuple[str, ...]
    lo: np.ndarray  # (K,) float32, lower bounds
    hi: np.ndarray  # (K,) float32, upper bounds

    @property
    def dim(self) -> int:
        """Number of knobs K."""
        return len(self.names)

    @property
    def shared(self) -> bool:
        """Whether some knob is part of the scene both routes share (Route B must be re-run)."""
        return any(knob(n).shared for n in self.names)

    def values(self, z: Array) -> Array:
        """(..., K) knob values strictly inside the ranges for unconstrained ``z`` (..., K)."""
        lo, hi = jnp.asarray(self.lo), jnp.asarray(self.hi)
        return lo + (hi - lo) * jax.nn.sigmoid(z)

    def unconstrained(self, values: Array) -> Array:
        """The ``z`` mapping to ``values`` (boundary values are moved ``INTERIOR`` inside)."""
        lo, hi = jnp.asarray(self.lo), jnp.asarray(self.hi)
        u = jnp.clip((jnp.asarray(values) - lo) / (hi - lo), INTERIOR, 1.0 - INTERIOR)
        return jnp.log(u) - jnp.log1p(-u)

    def as_dict(self, values: Array) -> dict[str, float]:
        """Knob values of one candidate as plain floats (for suite files and tables)."""
        v = np.asarray(values, np.float32)
        return {n: float(v[i]) for i, n in enumerate(self.names)}

    def apply(self, scenario_a: Scenario, scenario_b: Scenario, values: Array) -> tuple:
        """The pair with the knobs set (differentiable in ``values``, one candidate)."""
        return apply_knobs(scenario_a, scenario_b, {n: values[i] for i, n in enumerate(self.names)})


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
    table = KNOB_RANGES[rec.code]
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
