"""Language diagnostics of the paper's appendices, for any registered policy.

* :func:`wording_table` — "Additional Ablation Analysis", warning wording by ambiguity: the
  suite's pairs fall into three disjoint tiers (low / medium / high ambiguity,
  :func:`lantern_jax.scenarios.warnings.paraphrase_tiers`; 40 each on the 120-pair suite); each
  pair's Route A warning execution is run with its tier's paraphrase (the ``held_out_paraphrase``
  ablation) and with the canonical template, and every tier reports the paraphrase CUS, the
  matched canonical CUS on the same pairs, retention (their ratio) and the paraphrase
  executions' collision rate.
* :func:`nonactionable_table` — "Diagnostics with Non-Actionable Language Inputs": the five
  non-actionable warnings delivered on one empty-road route (a warning override from
  ``ONSET_S`` to the end), each compared with the same route without a warning: the maximum
  additional speed reduction, the longest standstill, route completion, and the paper's
  criterion (``NONACTIONABLE_*`` in :mod:`lantern_jax.scoring.thresholds`).
* :func:`distance_table` — the distance-conditioned diagnostic: on Route B of the first pairs of a
  family, the family's canonical warning is delivered at an ego-frame position near the ego
  (12.0, 0.5) m or far from it (100.0, 0.5) m, from the warning point on for ``window_s``
  seconds; the table reports the final predicted progress of the policy's plan at the warning
  point (the paper's open-loop measure: the length of the 10-waypoint plan, 2.5 s ahead) and, in
  closed loop, the lowest speed in the window, the longest standstill and route completion.

* :func:`language_table` — language sensitivity (beyond the paper): the warning condition with
  the delivered text replaced by another family's text, another family's paraphrase of the same
  road type, two held-out sentences that state the position, or the empty text, and the share of
  the warning gain each keeps (:mod:`lantern_jax.apps.language_sensitivity`, re-exported here).

The paper measures the distance diagnostic open-loop on held-out dataset frames with a
checkpoint fine-tuned for it; here the frame is the closed-loop state at Route B's warning
point, and the same runs also give the closed-loop effect.  The empty-road route is a straight
150 m road without actors (:func:`lantern_jax.scenarios.handmade.straight_scene`) at 8 m/s.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.apps.evaluation import build_executions, run_policy
from lantern_jax.apps.language_sensitivity import (  # noqa: F401  (re-exported)
    LANGUAGE_VARIANTS,
    MIN_GAIN_FOR_SHARE,
    OTHER_FAMILY,
    language_table,
)
from lantern_jax.core.constants import (
    DT,
    FAMILIES,
    NO_WARNING_CONDITION,
    RECORD_BATCH_STEP,
    RECORD_HORIZON_STEP_S,
    RECORD_MIN_HORIZON_S,
    SUITE_ID,
    WARNING_CONDITION,
)
from lantern_jax.core.times import ticks, ticks_covering
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.report.outputs import write_tables  # noqa: F401 (re-exported)
from lantern_jax.scenarios.handmade import straight_scene
from lantern_jax.scenarios.spec import route_timeout_s
from lantern_jax.scenarios.suite import Suite, build_suite_scenarios, load_suite
from lantern_jax.scenarios.warnings import (
    DISTANCE_POSITIONS,
    TIERS,
    get_text,
    non_actionable_text_ids,
    paraphrase_tiers,
    set_override,
)
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.thresholds import (
    DEFAULT_SCORING,
    NONACTIONABLE_MAX_DV_MPS,
    NONACTIONABLE_MAX_RC_DROP,
    NONACTIONABLE_MAX_STOP_S,
)
from lantern_jax.scoring.uncertainty import (
    SEED,
    interval,
    interval_columns,
    pooled,
    resampling,
    sample_interval,
)
from lantern_jax.sim.engine import Program, check_texts
from lantern_jax.sim.rollout import rollout
from lantern_jax.sim.settings import Settings, default_settings
from lantern_jax.sim.switch import reference_driver, shared_program
from lantern_jax.types.world import Scenario, tree_stack

EMPTY_ROAD_LENGTH_M = 150.0  # m, the non-actionable diagnostic's empty straight route
EMPTY_ROAD_SPEED_MPS = 8.0  # m/s, its reference (and initial) speed
ONSET_S = 2.0  # s, non-actionable warnings are delivered from this time to the end
DISTANCE_WINDOW_S = 5.0  # s, distance-conditioned warning window after the warning point
DISTANCE_FAMILY = "PE"  # the family whose warning the distance diagnostic moves
DISTANCE_ROUTES = 3  # Route B scenes of the distance diagnostic (the family's first pairs)


def _policy(policy: Policy | str, policy_params: Any) -> tuple[Policy, Any]:
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    return pol, params


# ---------------------------------------------------------------------------------------------
# warning wording by ambiguity
# ---------------------------------------------------------------------------------------------
def _tier_groups(
    canonical: pd.DataFrame, paraphrase: pd.DataFrame, tiers: np.ndarray, pair_ids: list[str]
) -> list[tuple[str, list[str]]]:
    """``(label, pair ids)`` of every tier and of all tiers, leaving out pairs whose CUS is
    missing on either side (``canonical`` and ``paraphrase`` indexed by ``pair_id``)."""
    groups = [(f"{t.capitalize()} ambiguity", tiers == k) for k, t in enumerate(TIERS)]
    groups.append(("All tiers", np.ones(len(pair_ids), bool)))
    out = []
    for label, mask in groups:
        ids = [i for i, m in zip(pair_ids, mask, strict=True) if m]
        ok = [
            i
            for i in ids
            if np.isfinite(canonical.at[i, "CUS"]) and np.isfinite(paraphrase.at[i, "CUS"])
        ]
        out.append((label, ok))
    return out


#: The wording table's value columns (each with an interval, :func:`wording_intervals`).
WORDING_COLUMNS = (
    "Paraphrase CUS",
    "Matched canonical",
    "Retention (%)",
    "Coll. (%)",
    "Matched no-warning",
)


def wording_intervals(
    canonical: pd.DataFrame,
    paraphrase: pd.DataFrame,
    no_warning: pd.DataFrame,
    tiers: np.ndarray,
    pair_ids: list[str],
    seed: int = SEED,
) -> pd.DataFrame:
    """Pair-level bootstrap intervals of the wording table (:func:`tier_rows` plus the matched
    no-warning CUS), resampling each row's pairs (all of a row's values with the same draws,
    so retention, the ratio of each replicate's two means, has a paired interval).  Not
    stratified by family: a tier of a small suite holds one or two pairs of a family, which a
    stratified draw could not vary.

    Args:
        canonical, paraphrase, no_warning: route-level rows (``pair_id``, ``CUS``,
            ``no_collision``) of the three runs.
        tiers: (n,) int, tier index of every pair of ``pair_ids``.
        pair_ids: (n,) pair ids in the order of ``tiers``.
        seed: the bootstrap's seed.

    Returns:
        One row per tier and one for all tiers: ``<c>_lo, <c>_hi`` for every
        :data:`WORDING_COLUMNS` (the rows of :func:`tier_rows`, in order).
    """
    c, p = canonical.set_index("pair_id"), paraphrase.set_index("pair_id")
    nw = no_warning.set_index("pair_id")
    rows = []
    for _, ok in _tier_groups(c, p, tiers, pair_ids):
        row = {}
        if ok:
            values = np.column_stack([
                p.loc[ok, "CUS"], c.loc[ok, "CUS"],
                100.0 * (p.loc[ok, "no_collision"].to_numpy() == 0), nw.loc[ok, "CUS"],
            ])  # fmt: skip
            res = resampling(ok, ["all"] * len(ok), seed=seed)
            reps = pooled(res, values)
            with np.errstate(divide="ignore", invalid="ignore"):
                ret = np.where(reps[:, 1] > 0, 100.0 * reps[:, 0] / reps[:, 1], np.nan)
            lo, hi = interval(np.column_stack([reps[:, 0], reps[:, 1], ret, reps[:, 2:]]))
        else:
            lo = hi = np.full(len(WORDING_COLUMNS), np.nan)
        for k, col in enumerate(WORDING_COLUMNS):
            names = interval_columns(col)
            row[names[0]], row[names[1]] = float(lo[k]), float(hi[k])
        rows.append(row)
    return pd.DataFrame(rows)


def tier_rows(
    canonical: pd.DataFrame,
    paraphrase: pd.DataFrame,
    tiers: np.ndarray,
    pair_ids: list[str],
) -> pd.DataFrame:
    """The wording table from route-level rows (warning condition) of both runs.

    Args:
        canonical: route-level rows (``pair_id``, ``CUS``, ``no_collision``) with the
            canonical template, warning condition.
        paraphrase: the same with the held-out paraphrases.
        tiers: (n,) int, tier index of every pair of ``pair_ids``.
        pair_ids: (n,) pair ids in the order of ``tiers``.

    Returns:
        One row per tier and one for all tiers: ``Wording, n, Paraphrase CUS, Matched canonical,
        Retention (%), Coll. (%), Matched no-warning`` (the last filled by the caller when it
        has no-warning rows; NaN otherwise).  Pairs whose CUS is missing on either side are
        left out of both sides.
    """
    c = canonical.set_index("pair_id")
    p = paraphrase.set_index("pair_id")
    rows = []
    for label, ok in _tier_groups(c, p, tiers, pair_ids):
        para = float(p.loc[ok, "CUS"].mean()) if ok else np.nan
        canon = float(c.loc[ok, "CUS"].mean()) if ok else np.nan
        coll = 100.0 * float((p.loc[ok, "no_collision"] == 0).mean()) if ok else np.nan
        rows.append(
            {
                "Wording": label + (", no position" if label.startswith("High") else ""),
                "n": len(ok),
                "Paraphrase CUS": para,
                "Matched canonical": canon,
                "Retention (%)": 100.0 * para / canon if canon > 0 else np.nan,
                "Coll. (%)": coll,
            }
        )
    return pd.DataFrame(rows)


def wording_table(
    policy: Policy | str,
    suite: Suite | str = SUITE_ID,
    policy_params: Any = None,
    bootstrap_seed: int = SEED,
) -> pd.DataFrame:
    """Warning wording by ambiguity for one policy on a suite (paper appendix table).

    Runs the suite twice (canonical templates; tiered held-out paraphrases), both in the
    warning condition of Route A, and adds each tier's matched no-warning CUS, which shows what
    a policy that ignores a text would score on those pairs, and every value's pair-level
    bootstrap interval (:func:`wording_intervals`: ``<c>_lo``, ``<c>_hi`` columns).
    """
    s = load_suite(suite) if isinstance(suite, str) else suite
    pol, params = _policy(policy, policy_params)
    runs = {}
    shared = shared_program([pol], [params])  # a reference policy: the evaluation's program
    for ablation in ("none", "held_out_paraphrase"):
        execs = build_executions(s, ablation, bucket=True)
        runs[ablation] = run_policy(pol, execs, params, shared=shared).route_table
        if ablation == "held_out_paraphrase":
            tiers = paraphrase_tiers(execs.take(execs.scenarios.config, WARNING_CONDITION))
    pair_ids = [p.pair_id for p in s.pairs]
    canon, para = (r[r["condition"] == WARNING_CONDITION] for r in runs.values())
    table = tier_rows(canon, para, tiers, pair_ids)
    none_rows = runs["none"][runs["none"]["condition"] == NO_WARNING_CONDITION]
    none = none_rows.set_index("pair_id")["CUS"]
    groups = [tiers == k for k in range(len(TIERS))] + [np.ones(len(pair_ids), bool)]
    table["Matched no-warning"] = [
        float(none.loc[[i for i, m in zip(pair_ids, g, strict=True) if m]].mean()) for g in groups
    ]
    intervals = wording_intervals(canon, para, none_rows, tiers, pair_ids, bootstrap_seed)
    return pd.concat([table, intervals], axis=1)


# ---------------------------------------------------------------------------------------------
# recorded rollouts of a few executions
# ---------------------------------------------------------------------------------------------
@functools.partial(jax.jit, static_argnames=("program", "horizon"))
def _recorded(batch, params, settings, *, program: Program, horizon: int):
    """Recorded rollouts of a batch; compiled once per (policy program, horizon)."""
    return jax.vmap(lambda sc: rollout(sc, program.driver, params, horizon, True, settings))(batch)


def run_recorded(
    policy: Policy, params: Any, scenarios: list[Scenario], settings: Settings | None = None
) -> tuple[Any, Any, Any]:
    """Roll out a few executions with full records (one jitted, vmapped call) under
    ``settings`` (default :func:`~lantern_jax.sim.settings.default_settings`); returns (final
    states, tick records, hard metrics), NumPy, leading axis = execution (one per scenario, in
    order), over a horizon covering the longest route timeout, rounded up to a multiple of
    :data:`~lantern_jax.core.constants.RECORD_HORIZON_STEP_S` and at least
    :data:`~lantern_jax.core.constants.RECORD_MIN_HORIZON_S` (the ticks past an execution's end
    repeat its final state, ``done`` set).  The batch runs padded to a multiple of
    :data:`~lantern_jax.core.constants.RECORD_BATCH_STEP` executions (copies of the last one,
    dropped here), so that a pair's figure and a family's diagnostics share one program.  A
    reference policy runs as its member of the reference switch
    (:func:`~lantern_jax.sim.switch.reference_driver`).

    Raises:
        ValueError: for an empty list of scenarios.
    """
    n = len(scenarios)
    if n == 0:
        raise ValueError("run_recorded: no scenarios to roll out")
    n_run = -(-n // RECORD_BATCH_STEP) * RECORD_BATCH_STEP
    batch = tree_stack(list(scenarios) + [scenarios[-1]] * (n_run - n))
    settings = default_settings() if settings is None else settings
    check_texts(settings, batch)
    longest = float(np.max(np.asarray(batch.config.timeout_s)))
    horizon_s = max(np.ceil(longest / RECORD_HORIZON_STEP_S) * RECORD_HORIZON_STEP_S,
                    RECORD_MIN_HORIZON_S)  # fmt: skip
    horizon = ticks_covering(horizon_s, slack=1e-6)
    # a reference policy runs as its member of the reference switch: every reference policy's
    # recorded rollouts share one program (and the evaluation's bits)
    driver, params = reference_driver(policy, params)
    final, rec = _recorded(batch, params, settings, program=Program(driver), horizon=horizon)
    metrics = jax.vmap(lambda t: finalize(t, settings.scoring))(final.telemetry)
    return jax.tree.map(lambda x: np.asarray(x)[:n], (final, rec, metrics))


def live_mask(rec: Any) -> np.ndarray:
    """(..., T) bool: ticks at whose start the execution had not yet ended."""
    done = np.asarray(rec.done, bool)
    before = np.concatenate([np.zeros_like(done[..., :1]), done[..., :-1]], axis=-1)
    return ~before


def longest_stop_s(speed: np.ndarray, live: np.ndarray) -> float:
    """s, the longest run of live ticks with speed below the block gate's standstill speed
    (``ScoringSettings.still_speed_mps``).

    Args:
        speed: (T,) m/s, speed at the end of every tick.
        live: (T,) bool, the tick was simulated.
    """
    best = run = 0
    still_speed = DEFAULT_SCORING.still_speed_mps
    for still in (np.asarray(speed) < still_speed) & np.asarray(live, bool):
        run = run + 1 if still else 0
        best = max(best, run)
    return best * DT


def response_metrics(
    v_ref: np.ndarray,
    live_ref: np.ndarray,
    v: np.ndarray,
    live: np.ndarray,
    rc_ref: float,
    rc: float,
) -> dict[str, Any]:
    """A warned execution against the same route without a warning (paper's criterion).

    Args:
        v_ref: (T,) m/s, speed of the execution without a warning, per tick.
        live_ref: (T,) bool, its simulated ticks.
        v: (T,) m/s, speed of the warned execution, same ticks.
        live: (T,) bool, its simulated ticks.
        rc_ref: route completion without the warning, percent.
        rc: route completion with it, percent.

    Returns:
        ``dv_max`` (m/s, the largest ``v_ref - v`` over the ticks both simulated, never below 0),
        ``stop_s`` (s, the warned execution's longest standstill), ``rc`` and ``rc_drop``
        (percentage points), and ``non_actionable`` (``dv_max < 2 m/s``, ``stop_s < 1 s``,
        ``rc_drop <= 5``).
    """
    both = np.asarray(live_ref, bool) & np.asarray(live, bool)
    diff = np.where(both, np.asarray(v_ref) - np.asarray(v), 0.0)
    dv = max(float(np.max(diff)) if diff.size else 0.0, 0.0)
    stop = longest_stop_s(v, live)
    drop = float(rc_ref) - float(rc)
    ok = dv < NONACTIONABLE_MAX_DV_MPS and stop < NONACTIONABLE_MAX_STOP_S
    ok = ok and drop <= NONACTIONABLE_MAX_RC_DROP
    return dict(dv_max=dv, stop_s=stop, rc=float(rc), rc_drop=drop, non_actionable=bool(ok))


# ---------------------------------------------------------------------------------------------
# non-actionable warnings on an empty road
# ---------------------------------------------------------------------------------------------
def empty_road(length: float = EMPTY_ROAD_LENGTH_M, speed: float = EMPTY_ROAD_SPEED_MPS):
    """The empty straight route of the non-actionable diagnostic (no actors, no protocol
    warning; the suite's route timeout, :func:`~lantern_jax.scenarios.spec.route_timeout_s`)."""
    return straight_scene(
        [], length=length, speed=speed, warning_enabled=False, timeout_s=route_timeout_s(length)
    )


def nonactionable_table(
    policy: Policy | str, policy_params: Any = None, text_ids: tuple[int, ...] | None = None
) -> pd.DataFrame:
    """The non-actionable diagnostic for one policy.

    Returns:
        One row for the route without a warning, then one per text: ``Warning input,
        dv_max (m/s), Stop (s), RC (%), RC drop, Non-actionable``.
    """
    pol, params = _policy(policy, policy_params)
    ids = non_actionable_text_ids() if text_ids is None else tuple(text_ids)
    base = empty_road()
    scenarios = [base] + [set_override(base, i, on_s=ONSET_S) for i in ids]
    _, rec, metrics = run_recorded(pol, params, scenarios)
    live = live_mask(rec)
    rc = 100.0 * metrics.progress
    rows = [
        {
            "Warning input": "(no warning)",
            "dv_max (m/s)": 0.0,
            "Stop (s)": longest_stop_s(rec.ego_speed[0], live[0]),
            "RC (%)": float(rc[0]),
            "RC drop": 0.0,
            "Non-actionable": "",
        }
    ]
    for k, tid in enumerate(ids, start=1):
        m = response_metrics(rec.ego_speed[0], live[0], rec.ego_speed[k], live[k], rc[0], rc[k])
        rows.append(
            {
                "Warning input": get_text(tid).text,
                "dv_max (m/s)": m["dv_max"],
                "Stop (s)": m["stop_s"],
                "RC (%)": m["rc"],
                "RC drop": m["rc_drop"],
                "Non-actionable": "yes" if m["non_actionable"] else "no",
            }
        )
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------------------------
# distance-conditioned warnings on Route B
# ---------------------------------------------------------------------------------------------
#: The distance diagnostic's three runs of every route: no warning, the near one, the far one.
DISTANCE_CONDITIONS = (NO_WARNING_CONDITION, "near", "far")


def plan_length(waypoints: np.ndarray) -> float:
    """m, length of the polyline from the ego (origin) through the (10, 2) waypoints."""
    pts = np.concatenate([np.zeros((1, 2)), np.asarray(waypoints, np.float64)])
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def distance_scenarios(
    suite: Suite,
    family: str = DISTANCE_FAMILY,
    routes: int = DISTANCE_ROUTES,
    window_s: float = DISTANCE_WINDOW_S,
) -> tuple[list[str], list[Scenario]]:
    """Route B of the first ``routes`` pairs of ``family``, each as ``[no warning, near, far]``.

    Returns:
        (pair ids, scenarios in the order pair-major, condition-minor).
    """
    if family not in FAMILIES:
        raise ValueError(f"family: {family!r} not one of {', '.join(FAMILIES)}")
    pairs = [p for p in suite.pairs if p.family == family][:routes]
    if not pairs:
        raise ValueError(f"suite {suite.suite_id!r} has no {family} pair")
    sub = dataclasses.replace(suite, pairs=tuple(pairs))
    _, route_b, _ = build_suite_scenarios(sub)
    text = FAMILIES.index(family)  # the family's canonical template
    out = []
    for b in route_b:
        out.append(b)
        for where in ("near", "far"):
            pos = DISTANCE_POSITIONS[where]
            out.append(set_override(b, text, pos, "ego", 0.0, window_s, "warning_point"))
    return [p.pair_id for p in pairs], out


def distance_table(
    policy: Policy | str,
    suite: Suite | str = SUITE_ID,
    policy_params: Any = None,
    family: str = DISTANCE_FAMILY,
    routes: int = DISTANCE_ROUTES,
    window_s: float = DISTANCE_WINDOW_S,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The distance-conditioned diagnostic for one policy.

    Returns:
        ``open_loop``: per route, the final predicted progress (m) of the plan at the warning
        point without a warning, with the near warning and with the far one, and retention
        (far / no warning, %), as in the paper's table;
        ``closed_loop``: per route and condition, the lowest speed in the warning window (m/s),
        the longest standstill (s) and route completion (%).
    """
    s = load_suite(suite) if isinstance(suite, str) else suite
    pol, params = _policy(policy, policy_params)
    pair_ids, scenarios = distance_scenarios(s, family, routes, window_s)
    _, rec, metrics = run_recorded(pol, params, scenarios)
    live = live_mask(rec)
    conds = DISTANCE_CONDITIONS
    n_win = ticks(window_s)
    opened, closed = [], []
    for r, pid in enumerate(pair_ids):
        row = {"Route": f"Route {r + 1}", "pair": pid}
        # The frame: the first tick at which the near warning is delivered (the ego has just
        # reached the warning point); the three runs are identical up to it.
        onset = np.flatnonzero(rec.warning_active[3 * r + 1])
        k0 = int(onset[0]) if onset.size else None
        for c, cond in enumerate(conds):
            i = 3 * r + c
            row[cond] = plan_length(rec.waypoints[i, k0]) if k0 is not None else np.nan
            window = slice(k0, k0 + n_win) if k0 is not None else slice(0, 0)
            v_win = rec.ego_speed[i, window][live[i, window]]
            closed.append(
                {
                    "Route": f"Route {r + 1}",
                    "pair": pid,
                    "condition": cond,
                    "min speed in window (m/s)": float(v_win.min()) if v_win.size else np.nan,
                    "Stop (s)": longest_stop_s(rec.ego_speed[i], live[i]),
                    "RC (%)": 100.0 * float(metrics.progress[i]),
                }
            )
        row["Retention (%)"] = 100.0 * row["far"] / row[NO_WARNING_CONDITION]
        opened.append(row)
    return pd.DataFrame(opened), pd.DataFrame(closed)


#: The distance diagnostic's open-loop columns summarised over routes.
DISTANCE_COLUMNS = (*DISTANCE_CONDITIONS, "Retention (%)")


def distance_summary(open_loop: pd.DataFrame, seed: int = SEED) -> pd.DataFrame:
    """The open-loop distance table over its routes: the mean of every column with its
    bootstrap interval over the routes (the routes are the sample; few routes give a flagged,
    unreliable interval).

    Returns:
        One row: ``Routes`` (n), then ``<c>, <c>_lo, <c>_hi`` for every
        :data:`DISTANCE_COLUMNS`.
    """
    values = open_loop[list(DISTANCE_COLUMNS)].to_numpy(np.float64)
    lo, hi, _ = sample_interval(values, seed=seed)
    row: dict[str, Any] = {"Routes": len(open_loop)}
    for k, c in enumerate(DISTANCE_COLUMNS):
        names = interval_columns(c)
        row.update({c: float(np.nanmean(values[:, k])), names[0]: lo[k], names[1]: hi[k]})
    return pd.DataFrame([row])
