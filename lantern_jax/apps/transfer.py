"""Transfer to unseen hazards: the paper's case-study tables (appendix "Protocol Extension to
Unseen Hazards") for any registered policy.

Every pair of a suite of unseen-hazard families (default: the shipped ``lantern-unseen`` suite
of :mod:`lantern_jax.scenarios.unseen`, ten pairs per family) runs Route A under three
conditions — **no warning**, the family's **exact (free-form) warning** and its **held-out
paraphrase** — and Route B once, in one jitted, vmapped call with full per-tick records
(:func:`lantern_jax.apps.diagnostics.run_recorded`).  Route geometry, weather, background traffic,
the policy and the hazard's script are the same in the three conditions; only the delivered text
differs.  Each Route A execution gives (:mod:`lantern_jax.scoring.response`):

* **response lead** (s): event-on time minus the start of the first of three consecutive 20-Hz
  control steps with brake signal >= 0.5, searched from the warning point on (positive: braking
  before the hazard starts to move); undefined when the policy never brakes that hard;
* **pre-event speed reduction** Δv (m/s): speed at warning onset (the warning point without a
  warning) minus the lowest speed before event-on;
* **route completion** (%), **collision** and **blocking** (% of pairs failing the gate) and
  the pair's **CUS** against its Route B (the benchmark's pair score).

Each table row is the mean over a family's pairs with a 95 % percentile-bootstrap interval over
pairs (:func:`bootstrap_interval`, 2,000 resamples, seed 0) where there is more than one pair;
the lead is averaged over the pairs with a response, and ``Resp.`` counts them.
"""

from __future__ import annotations

import dataclasses
from importlib import resources
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.apps.diagnostics import live_mask, run_recorded
from lantern_jax.core.constants import WARNING_CONDITION
from lantern_jax.core.times import time_or_nan
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios import unseen  # noqa: F401  (registers the unseen families)
from lantern_jax.scenarios.families import family
from lantern_jax.scenarios.suite import Suite, build_suite_scenarios, load_suite
from lantern_jax.scenarios.warnings import paraphrase_text_id
from lantern_jax.scoring.response import (
    brake_signals,
    pre_event_speed_drop,
    response_time,
    step_start_speeds,
)
from lantern_jax.scoring.table import build_route_table
from lantern_jax.sim.settings import default_settings
from lantern_jax.types.world import Scenario

#: The shipped suite of the three unseen families (generated with
#: ``generate_suite(UNSEEN_SEED, pairs_per_slot=2, families=UNSEEN_CODES, suite_id=...)``).
UNSEEN_SUITE_ID = "lantern-unseen"
UNSEEN_SEED = 20260612
NO_WARNING, PARAPHRASE = "no warning", "held-out paraphrase"
#: The three conditions of every pair; the family's own warning is the route table's warning
#: condition (its rows get the warning-onset column).
CONDITIONS = (NO_WARNING, WARNING_CONDITION, PARAPHRASE)
#: How the paper names the warning condition of each event.
WARNING_LABEL = {"CYC": "free-form warning"}
DEFAULT_WARNING_LABEL = "exact warning"
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
#: The paper's two tables: (title, families).
PAPER_TABLES = (
    ("Held-out occluded-cyclist case study", ("CYC",)),
    ("Controlled transfer to two additional physical events", ("EMV", "REV")),
)
#: The paper's figures (Coop-SimLingo, one route per event): family -> condition ->
#: (lead s, Δv m/s, RC %, collisions, blocking).
PAPER = {
    "CYC": {NO_WARNING: (-0.60, 0.0, 100, 0, 0), WARNING_CONDITION: (1.95, 9.5, 100, 0, 0),
            PARAPHRASE: (1.80, 9.3, 100, 0, 0)},
    "EMV": {NO_WARNING: (-0.55, 0.0, 55.1, 1, 0), WARNING_CONDITION: (2.00, 8.9, 100, 0, 0),
            PARAPHRASE: (1.35, 3.5, 55.1, 1, 0)},
    "REV": {NO_WARNING: (-0.45, 1.8, 100, 0, 0), WARNING_CONDITION: (1.95, 10.6, 100, 0, 0),
            PARAPHRASE: (-0.60, 0.0, 100, 0, 0)},
}  # fmt: skip


def unseen_suite() -> Suite:
    """The shipped ``lantern-unseen`` suite (its families, :data:`unseen.UNSEEN_CODES`, are
    registered when this module is imported)."""
    path = resources.files("lantern_jax") / "data" / f"{UNSEEN_SUITE_ID}.json"
    return load_suite(str(path))


def condition_label(family: str, condition: str) -> str:
    """A condition as the paper's tables name it for ``family``."""
    if condition != WARNING_CONDITION:
        return condition
    return WARNING_LABEL.get(family, DEFAULT_WARNING_LABEL)


def _conditions(a: Scenario, family: str) -> list[Scenario]:
    """Route A of one pair under the three :data:`CONDITIONS`."""
    cfg = a.config
    none = a.replace(config=cfg.replace(warning_enabled=np.asarray(False)))
    warned = a.replace(config=cfg.replace(warning_enabled=np.asarray(True)))
    para = paraphrase_text_id(family)
    paraphrase = warned.replace(config=warned.config.replace(text_id=np.int32(para)))
    return [none, warned, paraphrase]


def bootstrap_interval(
    values: np.ndarray, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the mean over pairs (NaN, NaN for fewer than two
    finite values).

    Args:
        values: (n,) one value per pair (NaN values are left out).
        resamples: bootstrap resamples.
        seed: NumPy seed of the resampling.
    """
    x = np.asarray(values, np.float64)
    x = x[np.isfinite(x)]
    if len(x) < 2:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), (resamples, len(x)))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


@dataclasses.dataclass
class TransferResult:
    """What :func:`run_transfer` produces.

    Attributes:
        policy: the policy's name.
        rows: one row per (pair, condition): ``pair_id, family, weather, condition, lead_s,
            response_s, t_event_s``, ``t_on_s`` (warning onset, or the warning point without a
            warning), ``t_seen_s`` (direct observation: the warning's termination),
            ``t_clear_s``, ``dv_mps, rc, collision, blocked, CUS`` (s, m/s, %, CUS points).
        summary: one row per (family, condition): ``family, condition, label, n, responded``
            and ``mean``, ``lo``, ``hi`` of ``lead_s, dv_mps, rc, collision, blocked, CUS``.
    """

    policy: str
    rows: pd.DataFrame
    summary: pd.DataFrame


MEASURES = ("lead_s", "dv_mps", "rc", "collision", "blocked", "CUS")


def summarize(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (family, condition): the number of pairs, how many responded, and the mean with a
    95 % bootstrap interval over pairs of every measure (:data:`MEASURES`).

    Args:
        rows: :attr:`TransferResult.rows`.
    """
    out = []
    for fam in dict.fromkeys(rows["family"]):
        for cond in CONDITIONS:
            g = rows[(rows["family"] == fam) & (rows["condition"] == cond)]
            rec: dict[str, Any] = dict(family=fam, condition=cond,
                                       label=condition_label(fam, cond), n=len(g),
                                       responded=int(np.isfinite(g["lead_s"]).sum()))  # fmt: skip
            for m in MEASURES:
                x = g[m].to_numpy(np.float64)
                rec[m] = float(np.nanmean(x)) if np.isfinite(x).any() else float("nan")
                rec[f"{m}_lo"], rec[f"{m}_hi"] = bootstrap_interval(x)
            out.append(rec)
    return pd.DataFrame(out)


def run_transfer(
    policy: Policy | str, suite: Suite | None = None, policy_params: Any = None
) -> TransferResult:
    """The unseen-hazard measures of one policy on a suite (see the module docstring).

    Args:
        policy: a registered name or a :class:`~lantern_jax.policies.base.Policy`.
        suite: a suite of registered families (default: :func:`unseen_suite`).
        policy_params: the policy's parameters (default: its ``init``).
    """
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    s = unseen_suite() if suite is None else suite
    route_a, route_b, _ = build_suite_scenarios(s)
    n = len(s.pairs)
    execs = [c for a, p in zip(route_a, s.pairs, strict=True) for c in _conditions(a, p.family)]
    final, rec, metrics = run_recorded(pol, params, execs + list(route_b), default_settings())
    live = live_mask(rec)
    friction = np.asarray([float(sc.config.friction) for sc in execs])
    v0 = np.asarray([float(sc.ego0.speed) for sc in execs])
    t_ref = np.asarray(time_or_nan(final.protocol.t_warn_point))
    t_on = np.asarray(time_or_nan(final.protocol.t_warn_on))
    t_event = np.asarray(time_or_nan(final.protocol.t_event))
    t_seen = np.asarray(time_or_nan(final.protocol.t_warn_off))
    t_clear = np.asarray(time_or_nan(final.protocol.t_clear))
    rows = []
    for i in range(len(execs)):
        j, cond = divmod(i, len(CONDITIONS))
        pair = s.pairs[j]
        speed_end = np.asarray(rec.ego_speed[i])
        brake = np.asarray(brake_signals(step_start_speeds(v0[i], speed_end),
                                         np.asarray(rec.waypoints[i]), friction[i]))  # fmt: skip
        t_end = np.asarray(rec.t[i])
        t_resp = response_time(t_end, brake, live[i], t_ref[i])
        onset = t_on[i] if np.isfinite(t_on[i]) else t_ref[i]
        dv = pre_event_speed_drop(t_end, speed_end, live[i], v0[i], onset, t_event[i])
        rows.append(dict(
            pair_id=pair.pair_id, family=pair.family, weather=pair.weather,
            condition=CONDITIONS[cond], lead_s=t_event[i] - t_resp, response_s=t_resp,
            t_event_s=t_event[i], t_on_s=onset, t_seen_s=t_seen[i], t_clear_s=t_clear[i],
            dv_mps=dv,
        ))  # fmt: skip
    table = pd.DataFrame(rows)
    k = len(CONDITIONS)
    metrics_b = jax.tree.map(lambda x: x[k * n :], metrics)
    for c, cond in enumerate(CONDITIONS):
        idx = np.arange(n) * k + c
        a = jax.tree.map(lambda x, idx=idx: x[idx], metrics)
        route = build_route_table(
            a, metrics_b, model=pol.name, condition=cond, pair_ids=[p.pair_id for p in s.pairs],
            families=[p.family for p in s.pairs], weathers=[p.weather for p in s.pairs],
            d_safe=[float(route_a[j].config.d_safe) for j in range(n)],
        )  # fmt: skip
        sel = table.index[table["condition"] == cond]
        table.loc[sel, "rc"] = 100.0 * route["A_progress"].to_numpy()
        table.loc[sel, "collision"] = 100.0 * (1 - route["no_collision"].to_numpy())
        table.loc[sel, "blocked"] = 100.0 * (1 - route["not_blocked"].to_numpy())
        table.loc[sel, "CUS"] = route["CUS"].to_numpy()
    return TransferResult(pol.name, table, summarize(table))


# ---------------------------------------------------------------------------------------------
# tables
# ---------------------------------------------------------------------------------------------
def _cell(rec: dict, m: str, digits: int) -> str:
    v, lo, hi = rec[m], rec[f"{m}_lo"], rec[f"{m}_hi"]
    if not np.isfinite(v):
        return "–"
    text = f"{v:+.{digits}f}" if m == "lead_s" else f"{v:.{digits}f}"
    return text if not np.isfinite(lo) else f"{text} [{lo:.{digits}f}, {hi:.{digits}f}]"


HEADERS = ("Event", "Condition", "n", "Lead (s)", "Resp.", "Δv (m/s)", "RC", "Coll.", "Block",
           "CUS")  # fmt: skip


def table_rows(summary: pd.DataFrame, families: tuple[str, ...]) -> pd.DataFrame:
    """The printed form of the summary rows of ``families`` (:data:`HEADERS`; mean and
    ``[95 % interval]`` where there is more than one pair; ``–``: no pair responded).

    Args:
        summary: :attr:`TransferResult.summary`.
        families: the family codes of the table, in row order.
    """

    out = []
    for fam in families:
        for rec in summary[summary["family"] == fam].to_dict("records"):
            out.append({
                "Event": family(fam).name, "Condition": rec["label"], "n": rec["n"],
                "Lead (s)": _cell(rec, "lead_s", 2), "Resp.": f"{rec['responded']}/{rec['n']}",
                "Δv (m/s)": _cell(rec, "dv_mps", 1), "RC": _cell(rec, "rc", 1),
                "Coll.": _cell(rec, "collision", 0), "Block": _cell(rec, "blocked", 0),
                "CUS": _cell(rec, "CUS", 1),
            })  # fmt: skip
    return pd.DataFrame(out, columns=list(HEADERS))


def paper_note(families: tuple[str, ...]) -> str:
    """One line per family with the paper's figures (Coop-SimLingo, one route), or ``""``."""
    lines = []
    for fam in families:
        if fam not in PAPER:
            continue
        parts = [
            f"{condition_label(fam, c)} {lead:+.2f} s / {dv:.1f} m/s / RC {rc:g} / coll. {coll} / "
            f"block {block}"
            for c, (lead, dv, rc, coll, block) in PAPER[fam].items()
        ]
        lines.append(f"paper (Coop-SimLingo, one route), {fam}: " + "; ".join(parts))
    return "\n".join(lines)


def table_groups(summary: pd.DataFrame) -> list[tuple[str, tuple[str, ...]]]:
    """The tables to print: the paper's two for the families they cover, then one for any
    other family of the summary.

    Args:
        summary: :attr:`TransferResult.summary`.

    Returns:
        ``[(title, family codes), ...]``.
    """
    present = list(dict.fromkeys(summary["family"]))
    groups = []
    for title, fams in PAPER_TABLES:
        have = tuple(f for f in fams if f in present)
        if have:
            groups.append((title, have))
    rest = tuple(f for f in present if all(f not in g for _, g in PAPER_TABLES))
    if rest:
        groups.append(("Other families", rest))
    return groups
