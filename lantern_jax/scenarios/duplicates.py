"""Route geometry samples and the paper's near-duplicate rule (NumPy).

The paper resamples every candidate route at 2-m arc-length intervals for overlap testing and
hashing, and treats two routes of the same family as **near duplicates** when, in both
directions, at least 70 % of one route's samples lie within 3 m of the other route; the second
candidate is rejected.  The paper's routes live in shared CARLA towns, so it compares them
where they lie.  Procedural scenes all start near the origin, so here routes are compared in
the frame of their **start pose** (start point at the origin, first heading along +x): a
rotated or shifted copy of a route is a near duplicate of it.

:func:`route_samples` gives a scenario's route every 2 m in the world frame (what the suite
manifest records, so anyone can re-check near duplicates from the file alone);
:func:`near_duplicate` applies the rule to two such sample sets.
"""

from __future__ import annotations

import math

import numpy as np

from lantern_jax.scenarios.road import arc_length, distances_to_polyline, point_at

SAMPLE_STEP_M = 2.0  # m, resampling interval of the paper
NEAR_M = 3.0  # m, a sample this close to the other route counts as shared
NEAR_SHARE = 0.7  # share of samples that must be shared, in both directions


def resample_route(xy: np.ndarray, step: float = SAMPLE_STEP_M) -> np.ndarray:
    """Points every ``step`` m of arc along a polyline, from its start (the end point is added
    when the length is not a multiple of ``step``); (n, 2) float64."""
    xy = np.asarray(xy, np.float64)
    cs = arc_length(xy)
    s = np.arange(0.0, cs[-1] + 1e-9, step)
    if cs[-1] - s[-1] > 1e-6:
        s = np.append(s, cs[-1])
    return point_at(xy, s)


def route_samples(scenario) -> np.ndarray:
    """(n, 2) float64, m: the valid route points of a scenario resampled every 2 m (world
    frame)."""
    r = scenario.route
    valid = np.asarray(r.valid, bool)
    return resample_route(np.asarray(r.xy, np.float64)[valid])


def start_frame(samples: np.ndarray) -> np.ndarray:
    """Samples expressed in the frame of their start pose: first sample at the origin, the
    first segment's heading along +x."""
    p = np.asarray(samples, np.float64)
    d = p[1] - p[0]
    a = -math.atan2(d[1], d[0])
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return (p - p[0]) @ rot.T


def shared_share(a: np.ndarray, b: np.ndarray) -> float:
    """Share of the samples of ``a`` within ``NEAR_M`` of the polyline through ``b`` (both in
    the same frame)."""
    return float(np.mean(distances_to_polyline(a, b) <= NEAR_M))


def near_duplicate(a: np.ndarray, b: np.ndarray) -> bool:
    """The paper's rule on two routes' 2-m samples, compared in their start-pose frames: at
    least 70 % of each route's samples within 3 m of the other route."""
    fa, fb = start_frame(a), start_frame(b)
    return shared_share(fa, fb) >= NEAR_SHARE and shared_share(fb, fa) >= NEAR_SHARE


def near_duplicates(samples: list[np.ndarray]) -> list[tuple[int, int]]:
    """Every near-duplicate index pair ``(i, j)``, ``i < j``, among a family's routes."""
    return [
        (i, j)
        for i in range(len(samples))
        for j in range(i + 1, len(samples))
        if near_duplicate(samples[i], samples[j])
    ]
