"""The normalised knob space of a suite's pairs: every family knob's documented range mapped
onto ``[0, 1]`` (:attr:`lantern_jax.scenarios.families.FamilyRecord.knobs`).

The knobs of all the families of a suite form one vector (:func:`knob_union`); a knob outside a
pair's family is *inactive* there (an empty range at the scene's own value), so every pair of
the suite lives in one box of the same shape (:class:`Boxes`) and one compiled program serves
them all (:mod:`lantern_jax.apps.stress.fragility`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import numpy as np

from lantern_jax.scenarios.families import family
from lantern_jax.scenarios.knobs import knob
from lantern_jax.scenarios.suite import Suite
from lantern_jax.types.world import Scenario


def knob_union(families: Sequence[str]) -> tuple[str, ...]:
    """The knobs of every family named, each once, in order of first appearance."""
    out: list[str] = []
    for f in families:
        out += [k for k in family(f).knobs if k not in out]
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class Boxes:
    """Per-pair knob boxes over :func:`knob_union`'s knobs (P pairs, K knobs)."""

    names: tuple[str, ...]
    lo: np.ndarray  # (P, K) float64, the family's lower bounds (the scene's value where masked)
    hi: np.ndarray  # (P, K) float64, the upper bounds (equal to lo where masked)
    active: np.ndarray  # (P, K) bool, the knob belongs to the pair's family
    u0: np.ndarray  # (P, K) float64, the pair's own scene, normalised (0 where masked)
    in_box: np.ndarray  # (P,) bool, the scene's own values lie inside the family's ranges

    def values(self, u: np.ndarray) -> np.ndarray:
        """(P, K) knob values of normalised points ``u`` (P, K)."""
        return self.lo + (self.hi - self.lo) * u


def knob_boxes(suite: Suite, scenario_a: Scenario) -> Boxes:
    """The normalised knob box of every pair of ``suite`` (its Route A batch ``scenario_a``,
    leading pair axis, gives the scene's own values)."""
    names = knob_union([p.family for p in suite.pairs])
    now = np.stack(
        [np.asarray(jax.vmap(knob(n).get)(scenario_a), np.float64) for n in names], axis=1
    )  # (P, K)
    lo, hi = now.copy(), now.copy()
    active = np.zeros(now.shape, bool)
    for i, p in enumerate(suite.pairs):
        for k, n in enumerate(names):
            rng = family(p.family).knobs.get(n)
            if rng is not None:
                lo[i, k], hi[i, k] = rng
                active[i, k] = True
    width = np.where(active, hi - lo, 1.0)
    u_raw = np.where(active, (now - lo) / width, 0.0)
    in_box = np.all((u_raw >= -1e-6) & (u_raw <= 1 + 1e-6), axis=1)
    return Boxes(names, lo, hi, active, np.clip(u_raw, 0.0, 1.0), in_box)
