"""Where along the approach the front camera first sees the hazard, per Route A execution.

The main command reports, per family, the share of Route A executions whose hazard stays hidden
from the 110-degree front camera for the whole approach before the warning point
(``hazard_hidden_before_warning``).  This script says *where* it was seen when it was: the
first tick before the warning point at which the camera saw the hazard, the ego-hazard
distance and the hazard's bearing in the ego frame then (0 = straight ahead, + = left), and in
how many of the approach ticks it was visible.  A large bearing at a long distance means the
line of sight runs across a bend, past whatever was meant to hide the hazard::

    python docs/investigations/hazard_first_seen.py          # OR, coop, warning condition
    python docs/investigations/hazard_first_seen.py --family PE --policy expert
    python docs/investigations/hazard_first_seen.py --family OR --csv first_seen_or.csv

Visibility is the simulator's own (``TickRecord.visible``, the state at the end of each tick);
the approach is every tick that ends before the ego reaches the warning point.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np
import pandas as pd

from lantern_jax.apps.diagnostics import run_recorded
from lantern_jax.core.constants import FAMILIES
from lantern_jax.policies.registry import get_policy, policy_names
from lantern_jax.scenarios.suite import SUITE_ID, build_suite_scenarios, load_suite
from lantern_jax.types.world import tree_stack


def recorded_route_a(family: str, policy: str, suite: str = SUITE_ID):
    """Roll out every Route A execution of ``family`` (warning condition) with full records
    (:func:`lantern_jax.apps.diagnostics.run_recorded`).

    Returns:
        (suite, pair indices into ``suite.pairs``, batched scenarios, final states, tick
        records, hard metrics), the last three as NumPy arrays with leading axis = execution;
        the horizon covers the longest route timeout.

    Raises:
        ValueError: naming ``family`` when the suite has no pair of it.
    """
    s = load_suite(suite)
    wa, _, _ = build_suite_scenarios(s)
    idx = [i for i, p in enumerate(s.pairs) if p.family == family]
    if not idx:
        raise ValueError(f"family: {family!r} has no pairs in suite {s.suite_id!r}")
    pol = get_policy(policy)
    scenarios = [wa[i] for i in idx]
    final, rec, metrics = run_recorded(pol, pol.init(jax.random.PRNGKey(0)), scenarios)
    return s, idx, tree_stack(scenarios), final, rec, metrics


def first_seen_table(family: str, policy: str, suite: str = SUITE_ID) -> pd.DataFrame:
    """One row per Route A execution of ``family`` (warning condition).

    Columns: ``pair``; ``t_warn_point`` (s, when the ego reached the warning point);
    ``first_seen_s`` (s, first approach tick with the hazard visible, NaN if never);
    ``distance_m`` and ``bearing_deg`` (ego to hazard centre at that tick, ego frame, + left);
    ``seen_ticks`` and ``approach_ticks`` (visible / all ticks before the warning point).
    """
    s, idx, batch, final, rec, _ = recorded_route_a(family, policy, suite)
    hazard = np.asarray(batch.config.hazard_index)
    rows = []
    for k, i in enumerate(idx):
        h = int(hazard[k])
        t_wp = float(final.protocol.t_warn_point[k])
        live = ~np.concatenate([[False], rec.done[k][:-1]])
        approach = live & (rec.t[k] < t_wp)  # (T,) ticks that end before the warning point
        seen = approach & rec.visible[k][:, h]
        row = {
            "pair": s.pairs[i].pair_id,
            "t_warn_point": t_wp,
            "first_seen_s": np.nan,
            "distance_m": np.nan,
            "bearing_deg": np.nan,
            "seen_ticks": int(seen.sum()),
            "approach_ticks": int(approach.sum()),
        }
        if seen.any():
            j = int(np.flatnonzero(seen)[0])
            d = rec.actor_xy[k][j, h] - rec.ego_xy[k][j]  # (2,) m, world frame
            yaw = float(rec.ego_yaw[k][j])
            fwd = d[0] * np.cos(yaw) + d[1] * np.sin(yaw)
            left = -d[0] * np.sin(yaw) + d[1] * np.cos(yaw)
            row.update(
                first_seen_s=float(rec.t[k][j]),
                distance_m=float(np.hypot(*d)),
                bearing_deg=float(np.degrees(np.arctan2(left, fwd))),
            )
        rows.append(row)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="OR", choices=FAMILIES)
    ap.add_argument("--policy", default="coop", help=f"one of {', '.join(policy_names())}")
    ap.add_argument("--suite", default=SUITE_ID)
    ap.add_argument("--csv", default=None, help="also write the table here")
    a = ap.parse_args()
    df = first_seen_table(a.family, a.policy, a.suite)
    hidden = int(df["first_seen_s"].isna().sum())
    print(
        f"{a.family}, {a.policy}, warning condition: hazard hidden for the whole approach in "
        f"{hidden} of {len(df)} Route A executions ({100.0 * hidden / len(df):.0f} %)"
    )
    print(df.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    if a.csv:
        df.to_csv(a.csv, index=False)


if __name__ == "__main__":
    main()
