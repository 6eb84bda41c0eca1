"""The failure catalogue: every distinct verified failure as a suite pair, a view and a line.

Failures are **deduplicated** by the paper's near-duplicate rule
(:mod:`lantern_jax.scenarios.duplicates`: at least 70 % of one's samples within 3 m of the
other's, both ways) applied to the adversary's trajectory: the positions of every actor with a
track (the hazard's in a knob space) every 0.25 s of the policy's verification rollout, compared
at equal times — two failures are the same when every such actor moved the same way.  The first
of a group (in the order found: by method, then time) stands for it.

Each distinct failure becomes a pair of a suite file (the pair's parameters with the candidate's
``knobs`` or ``adversary`` field, :meth:`lantern_jax.apps.stress.space.Space.params`), which
``lantern-jax evaluate --suite`` re-evaluates to the hard CUS the search verified (within the
evaluation's reproducibility promise); a one-line description says which gate failed when and
what the adversary did (:func:`describe`); a bird's-eye view of the policy's rollout at the
failure (:func:`lantern_jax.viz.stress.catalogue_figure`) draws every tracked actor's path.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from lantern_jax.apps.stress.objective import Problem
from lantern_jax.apps.stress.space import AdversarySpace, ProductSpace, Space
from lantern_jax.core.constants import KIND_NAMES
from lantern_jax.dynamics.adversary import limits_of_kind, scale_actions, track_profile
from lantern_jax.scenarios.duplicates import NEAR_M, NEAR_SHARE
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, suite_hash


def _columns(problem: Problem) -> list[int]:
    """Watch columns compared by the rule: the tracked actors, else the hazard."""
    cols = [i for i, t in enumerate(problem.tracked_mask) if t]
    return cols or [0]


def same_manoeuvre(a: np.ndarray, b: np.ndarray, columns: list[int]) -> bool:
    """The near-duplicate rule on two failures' trajectories (K, W, 2) at equal times.

    For every compared actor: at least :data:`NEAR_SHARE` of the samples where it is present in
    ``a`` have it within :data:`NEAR_M` of its place in ``b`` at the same time, and the other way
    round (an actor absent in one counts as far).
    """
    n = min(len(a), len(b))
    for c in columns:
        pa, pb = a[:n, c], b[:n, c]
        here_a, here_b = ~np.isnan(pa[:, 0]), ~np.isnan(pb[:, 0])
        near = here_a & here_b & (np.linalg.norm(np.nan_to_num(pa - pb, nan=1e9), axis=1) <= NEAR_M)
        for here in (here_a, here_b):
            if here.any() and np.mean(near[here]) < NEAR_SHARE:
                return False
    return True


def distinct(failures: list[dict], problem: Problem) -> list[int]:
    """Indices of the failures that stand for their group (first of each), in order."""
    cols = _columns(problem)
    keep: list[int] = []
    for i, f in enumerate(failures):
        if f.get("traj") is None or not any(
            same_manoeuvre(f["traj"], failures[j]["traj"], cols) for j in keep
        ):
            keep.append(i)
    return keep


def _adversary_part(space: Space) -> tuple[AdversarySpace | None, slice]:
    if isinstance(space, AdversarySpace):
        return space, slice(0, space.dim)
    if isinstance(space, ProductSpace):
        start = 0
        for p in space.parts:
            if isinstance(p, AdversarySpace):
                return p, slice(start, start + p.dim)
            start += p.dim
    return None, slice(0, 0)


def manoeuvres(problem: Problem, values: np.ndarray) -> list[str]:
    """What each tracked actor does, from its track: speed extremes and when, lateral offset."""
    adv, sl = _adversary_part(problem.space)
    if adv is None:
        return [", ".join(f"{k} {v:.2f}" for k, v in problem.space.as_dict(values).items())]
    acc, lat = adv.actions(np.asarray(values)[sl])
    script = problem.scenario_a.actors
    out = []
    for i, (s, kind) in enumerate(zip(adv.slots, adv.kinds, strict=True)):
        lim = limits_of_kind(kind)
        a, l_rate = scale_actions(acc[i], lat[i], lim)
        v0 = float(np.asarray(script.v_post)[s])
        prof = track_profile(a, l_rate, adv.knot_s, jnp.float32(v0), lim)
        v = v0 + np.asarray(prof["dv"])
        dlat = np.asarray(prof["dlat"])
        t = np.arange(len(v)) * adv.knot_s
        lo, hi, side = int(np.argmin(v)), int(np.argmax(v)), int(np.argmax(np.abs(dlat)))
        out.append(
            f"{KIND_NAMES[kind]} (slot {s}) from {v0:.1f} m/s: min {v[lo]:.1f} at +{t[lo]:.1f} s, "
            f"max {v[hi]:.1f} at +{t[hi]:.1f} s, lateral {dlat[side]:+.1f} m at +{t[side]:.1f} s"
        )
    return out


def describe(problem: Problem, failure: dict) -> str:
    """One line: which gate failed when (or the CUS), and what the adversary did."""
    gates = [g.removeprefix("gate_").replace("_", " ") for g in failure.get("gates", [])]
    t = failure.get("t_fail_s", np.nan)
    what = (
        f"{' + '.join(gates)} at {t:.1f} s"
        if gates and np.isfinite(t)
        else (f"CUS {failure['cus']:.1f} below the threshold")
    )
    return f"{what}; " + "; ".join(manoeuvres(problem, np.asarray(failure["values"])))


def catalogue_entries(
    problem: Problem, pair: PairSpec, traces: list[Any], policy_name: str
) -> list[dict]:
    """Every distinct failure of every method (in method order), with its pair id, parameters,
    content hash and description."""
    found = [(t.method, f) for t in traces for f in t.failures]
    keep = distinct([f for _, f in found], problem)
    entries = []
    for n, i in enumerate(keep):
        method, f = found[i]
        params = dict(pair.params, **problem.space.params(np.asarray(f["values"])))
        entries.append(
            dict(
                pair_id=f"{pair.pair_id}_{policy_name}_{n:03d}",
                method=method,
                restart=f["restart"],
                hard_cus=f["cus"],
                gates=" + ".join(f["gates"]),
                t_fail_s=f["t_fail_s"],
                rollouts=f["rollouts"],
                seconds=f["seconds"],
                description=describe(problem, f),
                params=params,
                sha256=content_hash(params),
                values=f["values"],
            )
        )
    return entries


def catalogue_suite(pair: PairSpec, entries: list[dict], policy_name: str) -> dict:
    """The catalogue as a suite manifest (``lantern-jax evaluate --suite`` runs it)."""
    specs = [
        PairSpec(e["pair_id"], pair.family, pair.weather, e["params"], e["sha256"]) for e in entries
    ]
    pairs = [
        dict(
            pair_id=s.pair_id, family=s.family, weather=s.weather, sha256=s.sha256, params=s.params
        )
        for s in specs
    ]
    return dict(
        suite_id=f"stress-{pair.pair_id}-{policy_name}",
        format_version=1,
        seed=0,
        pairs=pairs,
        suite_sha256=suite_hash(specs),
        generation_report={},
    )
