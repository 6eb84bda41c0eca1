"""Hard checks of the fragility radius (:mod:`lantern_jax.apps.stress.fragility`): probes along the
predicted direction, and uniform draws around each scene.

Every probe or draw is an ordinary suite pair (the pair's parameters plus a ``knobs`` field,
:func:`probe_pair`) evaluated by :func:`lantern_jax.apps.evaluation.evaluate` with the privileged
expert beside the policy; a **verified failure** is a probe where the policy fails (a gate, or
a pair CUS below :data:`~lantern_jax.apps.stress.plausibility.FAIL_BELOW_CUS`) while the expert
passes every Route A gate with a clearance of at least
:data:`~lantern_jax.apps.stress.plausibility.EXPERT_MARGIN_M`.

* :func:`verify_probes` — the scene at ``u0 + t d`` for ``t`` = 0.5, 1, 1.5 and 2 radii
  (:data:`MULTIPLES`) and at :data:`LINE_POINTS` evenly spaced points of the line inside the box;
* :func:`sampling_check` — each pair's share of verified failures among uniform draws within
  :data:`SAMPLING_SCALE` of its scene, and per family the rank correlation of the radius with
  that share (:func:`spearman_interval`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.apps.stress import plausibility as rules
from lantern_jax.apps.stress.knob_box import Boxes
from lantern_jax.core.constants import GATE_COLUMN_NAMES, GATE_COLUMNS, ROUTE_A_GATE_NAMES
from lantern_jax.policies.base import Policy
from lantern_jax.scenarios.families import KNOBS_FIELD, family
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, Suite, suite_hash
from lantern_jax.scoring.uncertainty import CONFIDENCE, RESAMPLES, SEED
from lantern_jax.sim.settings import Settings

MULTIPLES = (0.5, 1.0, 1.5, 2.0)  # radii at which the prediction is checked
LINE_POINTS = 4  # evenly spaced probes of the whole line inside the box, besides MULTIPLES
SAMPLING_SCALE = 0.5  # normalised: draws around a pair lie within this distance of its scene


def probe_pair(pair: PairSpec, names: Sequence[str], values: np.ndarray, tag: str) -> PairSpec:
    """``pair`` with its family's knobs set to ``values`` (K,) (one probe), as a suite pair
    whose id ends in ``tag``; values are clipped into the family's ranges (float rounding)."""
    ranges = family(pair.family).knobs
    knobs = dict(pair.params.get(KNOBS_FIELD, {}))
    for n, v in zip(names, values, strict=True):
        if n in ranges:
            knobs[n] = float(min(max(float(v), ranges[n][0]), ranges[n][1]))
    params = dict(pair.params, **{KNOBS_FIELD: knobs})
    return PairSpec(f"{pair.pair_id}{tag}", pair.family, pair.weather, params,
                    content_hash(params))  # fmt: skip


def _suite_of(pairs: list[PairSpec], suite_id: str) -> Suite:
    return Suite(suite_id, tuple(pairs), suite_hash(pairs), 0, {})


def _pair_rows(result: Any, policy: str, condition: str) -> pd.DataFrame:
    """Per pair (index pair_id) of one condition: the policy's CUS, whether it failed (a gate
    or a CUS below the threshold), which gates, and whether the expert passed with margin."""
    rt = result.route_table
    rt = rt[rt["condition"] == condition]
    pol = rt[rt["model"] == policy].set_index("pair_id")
    exp = rt[rt["model"] == "expert"].set_index("pair_id").reindex(pol.index)
    gates = list(GATE_COLUMN_NAMES)
    passed = pol[gates].astype(bool)
    out = pd.DataFrame(index=pol.index)
    out["CUS"] = pol["CUS"].astype(float)
    out["policy_failed"] = ~passed.all(axis=1) | (out["CUS"] < rules.FAIL_BELOW_CUS)
    out["failed_gates"] = passed.apply(lambda r: " + ".join(g for g in gates if not r[g]), axis=1)
    clear = exp["clearance_min_m"].astype(float)
    expert_a = exp[[GATE_COLUMNS[g] for g in ROUTE_A_GATE_NAMES]].astype(bool).all(axis=1)
    out["expert_ok"] = expert_a & (clear.isna() | (clear >= rules.EXPERT_MARGIN_M))
    return out


def evaluate_pairs(
    pairs: list[PairSpec], policy: Policy, condition: str, settings: Settings, suite_id: str
) -> pd.DataFrame:
    """:func:`_pair_rows` of ``pairs`` evaluated as one suite by
    :func:`lantern_jax.apps.evaluation.evaluate` (the policy and the expert together)."""
    members = [policy] if policy.name == "expert" else [policy, "expert"]
    res = evaluate(members, suite=_suite_of(pairs, suite_id), progress=False, settings=settings)
    return _pair_rows(res, policy.name, condition)


def verify_probes(
    suite: Suite, policy: Policy, boxes: Boxes, direction: np.ndarray, distances: np.ndarray,
    condition: str, settings: Settings, say: Any = None,
) -> pd.DataFrame:  # fmt: skip
    """Hard evaluation of every probe ``u0 + t d`` (``distances`` (P, J), NaN = none): one
    evaluation of the suite per probe column, the policy and the expert together.

    Returns:
        One row per existing probe: pair_id, family, probe (column), t, multiple (of the
        radius; NaN for a line point), the policy's CUS, ``policy_failed``, ``failed_gates``,
        ``expert_ok``, ``failed`` (verified and plausible), and the probe's suite pair
        (``spec``).
    """
    rows = []
    for j in range(distances.shape[1]):
        have = np.isfinite(distances[:, j])
        if not have.any():
            continue
        t = np.where(have, distances[:, j], 0.0)
        values = boxes.values(np.clip(boxes.u0 + t[:, None] * direction, 0.0, 1.0))
        specs = [probe_pair(p, boxes.names, values[i], f"_p{j}")
                 for i, p in enumerate(suite.pairs)]  # fmt: skip
        got = evaluate_pairs(specs, policy, condition, settings, f"fragility-p{j}")
        if say:
            say(f"probe {j + 1}/{distances.shape[1]}: {int(have.sum())} pairs, "
                f"{int((got['policy_failed'] & got['expert_ok']).to_numpy()[have].sum())} "
                "verified failures")  # fmt: skip
        for i, p in enumerate(suite.pairs):
            if not have[i]:
                continue
            r = got.loc[specs[i].pair_id]
            rows.append(dict(
                pair_id=p.pair_id, family=p.family, probe=j, t=float(distances[i, j]),
                multiple=float(MULTIPLES[j]) if j < len(MULTIPLES) else np.nan,
                CUS=float(r["CUS"]), policy_failed=bool(r["policy_failed"]),
                failed_gates=r["failed_gates"], expert_ok=bool(r["expert_ok"]),
                failed=bool(r["policy_failed"] and r["expert_ok"]), spec=specs[i],
            ))  # fmt: skip
    return pd.DataFrame(rows, columns=PROBE_COLUMNS)


#: The probe table's columns (``spec`` is dropped from :attr:`Fragility.probes`).
PROBE_COLUMNS = ("pair_id", "family", "probe", "t", "multiple", "CUS", "policy_failed",
                 "failed_gates", "expert_ok", "failed", "spec")  # fmt: skip


def ball_draws(u0: np.ndarray, active: np.ndarray, draws: int, scale: float,
               seed: int) -> np.ndarray:  # fmt: skip
    """(draws, P, K) points uniform in the ball of radius ``scale`` around each pair's ``u0``
    (its active knobs; the rest left at ``u0``), clipped into the box ``[0, 1]^K``."""
    rng = np.random.default_rng(seed)
    p, k = u0.shape
    dims = np.maximum(active.sum(axis=1), 1)  # (P,)
    z = rng.standard_normal((draws, p, k)) * active[None]
    z /= np.maximum(np.linalg.norm(z, axis=2, keepdims=True), 1e-12)
    rad = scale * rng.uniform(0.0, 1.0, (draws, p)) ** (1.0 / dims[None])
    return np.clip(u0[None] + rad[..., None] * z, 0.0, 1.0)


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of two samples (average ranks for ties; NaN when either
    is constant)."""
    rx, ry = pd.Series(x).rank().to_numpy(), pd.Series(y).rank().to_numpy()
    if np.std(rx) == 0 or np.std(ry) == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def spearman_interval(x: np.ndarray, y: np.ndarray, seed: int = SEED,
                      resamples: int = RESAMPLES) -> tuple[float, float, float]:  # fmt: skip
    """Spearman's correlation of ``x`` and ``y`` and its percentile bootstrap interval over the
    pairs (:data:`~lantern_jax.scoring.uncertainty.CONFIDENCE`; resamples where either side is
    constant are left out)."""
    rng = np.random.default_rng(seed)
    n = len(x)
    reps = [spearman(x[i], y[i]) for i in (rng.integers(0, n, n) for _ in range(resamples))]
    reps = np.asarray(reps)
    reps = reps[np.isfinite(reps)]
    if not len(reps):
        return spearman(x, y), float("nan"), float("nan")
    a = (1.0 - CONFIDENCE) / 2
    return spearman(x, y), float(np.quantile(reps, a)), float(np.quantile(reps, 1 - a))


def sampling_check(
    suite: Suite, policy: Policy, boxes: Boxes, table: pd.DataFrame, condition: str,
    settings: Settings, draws: int, scale: float = SAMPLING_SCALE, seed: int = 0,
    say: Any = None,
) -> tuple[np.ndarray, pd.DataFrame]:  # fmt: skip
    """The radius against sampling: each pair's share of verified failures among ``draws``
    uniform draws within ``scale`` of its scene (:func:`ball_draws`; one evaluation of the
    suite per draw), and per family and pooled the rank correlation of the radius with that
    share (:func:`spearman_interval`; a fragile pair, small radius, should fail more often:
    a negative correlation; per family only, the radii of different families being on the
    scales of different knob ranges).

    Returns:
        ``(rate (P,), correlations)``; the correlations have family, pairs, spearman, its
        interval (``spearman_lo``, ``spearman_hi``) and the mean failure rate.
    """
    pts = ball_draws(boxes.u0, boxes.active, draws, scale, seed)
    failed = np.zeros((draws, len(suite)), bool)
    for j in range(draws):
        values = boxes.values(pts[j])
        specs = [probe_pair(p, boxes.names, values[i], f"_s{j}")
                 for i, p in enumerate(suite.pairs)]  # fmt: skip
        got = evaluate_pairs(specs, policy, condition, settings, f"fragility-s{j}")
        got = got.loc[[s.pair_id for s in specs]]
        failed[j] = (got["policy_failed"] & got["expert_ok"]).to_numpy(bool)
        if say:
            say(f"sampling draw {j + 1}/{draws}: {int(failed[j].sum())} verified failures")
    rate = failed.mean(axis=0)
    radius = np.minimum(table["radius"].to_numpy(float), 1e6)
    rows = []
    # per family only: radii of different families are on different scales (knob ranges),
    # so a pooled rank correlation would mix the families' levels with the ranking within each
    for fam in dict.fromkeys(table["family"]):
        on = (table["family"] == fam).to_numpy()
        rho, lo, hi = spearman_interval(radius[on], rate[on], seed)
        rows.append(dict(family=fam, pairs=int(on.sum()), spearman=rho, spearman_lo=lo,
                         spearman_hi=hi, failure_rate=float(rate[on].mean())))  # fmt: skip
    return rate, pd.DataFrame(rows)
