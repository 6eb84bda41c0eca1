"""How many distinct Obstacle Reveal routes a road layout admits under the near-duplicate rule.

The van hides the object from the ego's camera only while ego, van and object are lined up,
i.e. on a straight stretch, so the OR approach must be straight; the near-duplicate rule
(``scenarios.duplicates``: >= 70 % of the 2-m samples within 3 m of the other route, both ways,
in the start-pose frame) must still leave 20 distinct routes per family for the suite and
enough candidates for the dataset.  This script measures that for four layouts, drawing the OR
parameters with the family's own sampler (``families_straight.sample_or``):

* ``lantern-v3`` (shipped): straight from the route start to 2 m past the object, then a street
  corner of 20-90 degrees to either side (ego-lane radius 15-40 m), then ``curvature_2``
  (``or_centerline``); reveal point drawn in 30-50 m and route length from 90 m;
* ``lantern-v2``: the earlier layout, a gentle bend (``|k| <= MAX_CURVATURE``) up to 2 m before
  the warning point, straight from there to 2 m past the object, ``curvature_2`` after it
  (reveal point 35-80 m, any route length).  Its object was seen across the bend in 80 % of
  the approaches;
* ``straight, one curve``: straight from the route start to 2 m past the object, one gentle
  curvature after it; the reveal point drawn in its shortest range (30-45 m, at least 10 m of
  van travel) and the route in its longest (100-133 m), so that the straight part is as small a
  share of the route as the paper's ranges allow;
* ``straight, two curves``: the same with two gentle curvature pieces after the object (the
  first 20-50 m long).

For each layout it draws candidates until ``--suite-size`` mutually distinct routes are found
(or ``--candidates`` are spent), greedily as the suite generator does, and then reports the share
of ``--probe`` fresh candidates that are not near duplicates of any of them (what the dataset
generator keeps)::

    python docs/investigations/or_route_diversity.py [--candidates 5000] [--probe 500] [--seed 0]

It builds no scenario and runs no policy.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lantern_jax.core.constants import EGO_HALF_LENGTH
from lantern_jax.scenarios.duplicates import near_duplicate, resample_route
from lantern_jax.scenarios.families_straight import (
    OR_WARN_LEAD,
    or_centerline,
    sample_or,
)
from lantern_jax.scenarios.road_straight import Centerline
from lantern_jax.scenarios.spec import MAX_CURVATURE, MIN_RECOVERY_M

STEP_M = 0.5  # m, centre-line sampling before the 2-m resampling


def _route(line: Centerline, length: float) -> np.ndarray:
    xy, _ = line.pose(np.arange(0.0, length + 1e-9, STEP_M))
    return resample_route(xy)


def shipped(rng: np.random.Generator) -> np.ndarray:
    """A route of the shipped OR layout."""
    p = sample_or(rng, "clear")
    return _route(or_centerline(p), float(p["route_length"]))


def bend_before(rng: np.random.Generator) -> np.ndarray:
    """A route of lantern-v2's OR layout (gentle bend, then the straight van stretch)."""
    p = sample_or(rng, "clear")
    reveal = rng.uniform(max(35.0, p["lead_gap"] + 10.0), 80.0)
    length = rng.uniform(max(66.0, reveal + p["object_ahead"] + MIN_RECOVERY_M + 0.5), 133.0)
    conflict = reveal - 0.5 * p["van_length"] - EGO_HALF_LENGTH
    s_a = max(conflict - OR_WARN_LEAD - 2.0, 1.0)
    s_b = reveal + p["object_ahead"] + 2.0
    k1 = rng.uniform(-MAX_CURVATURE, MAX_CURVATURE)
    return _route(Centerline((s_a, s_b), (k1, 0.0, p["curvature_2"])), length)


def straight_approach(rng: np.random.Generator, pieces: int) -> np.ndarray:
    """A route straight from its start to 2 m past the object, ``pieces`` curvatures after."""
    p = sample_or(rng, "clear")
    reveal = rng.uniform(max(30.0, p["lead_gap"] + 10.0), 45.0)
    s_b = reveal + p["object_ahead"] + 2.0
    length = rng.uniform(max(100.0, reveal + p["object_ahead"] + MIN_RECOVERY_M + 0.5), 133.0)
    kappas = [0.0] + [rng.uniform(-MAX_CURVATURE, MAX_CURVATURE) for _ in range(pieces)]
    breaks = [s_b]
    for _ in range(pieces - 1):  # every curvature piece but the last is 20-50 m long
        breaks.append(breaks[-1] + rng.uniform(20.0, 50.0))
    return _route(Centerline(tuple(breaks), tuple(kappas)), length)


def diversity(draw, rng, suite_size: int, candidates: int, probe: int) -> tuple[int, int, float]:
    """(distinct routes found, candidates drawn, share of fresh candidates distinct from them)."""
    kept: list[np.ndarray] = []
    n = 0
    while len(kept) < suite_size and n < candidates:
        n += 1
        r = draw(rng)
        if not any(near_duplicate(r, k) for k in kept):
            kept.append(r)
    fresh = sum(not any(near_duplicate(draw(rng), k) for k in kept) for _ in range(probe))
    return len(kept), n, fresh / probe


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite-size", type=int, default=20)
    ap.add_argument("--candidates", type=int, default=5000)
    ap.add_argument("--probe", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    layouts = {
        "lantern-v3 (shipped)": shipped,
        "lantern-v2": bend_before,
        "straight, one curve": lambda rng: straight_approach(rng, 1),
        "straight, two curves": lambda rng: straight_approach(rng, 2),
    }
    print(f"{'layout':<24} {'distinct':>8} {'drawn':>6} {'fresh distinct':>15} {'s':>6}")
    for name, draw in layouts.items():
        t0 = time.perf_counter()
        found, n, fresh = diversity(
            draw, np.random.default_rng(args.seed), args.suite_size, args.candidates, args.probe
        )
        print(f"{name:<24} {found:>8} {n:>6} {100 * fresh:>14.1f}% "
              f"{time.perf_counter() - t0:>6.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
