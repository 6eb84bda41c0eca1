"""The paper's ablation table in one call (paper §"Ablations and Robustness", Table
"Sensitivity to warning timing, event activation, localization, and wording").

:func:`run_ablations` evaluates one policy under the full temporal protocol and each of its five
variants (:data:`lantern_jax.scenarios.protocol_variants.ABLATIONS`; every variant changes one
rule of the protocol) on the same suite, with the same Route B control and
the same CUS, and collects one row per variant:

=============  ===================================================================================
CUS            Overall CUS (macro-average over families), points
A-Prog.        mean Route A progress x 100
Event Exp.     Event Exposure: % of Route A executions in which the intended physical event
               began (``event_exposed``; the anti-deadlock rule exists to keep this at 100 %)
Ant., Rec.     mean anticipation / recovery x 100 (available pairs)
Coll.-A        % of pairs with a Route A collision
Block-A        % of pairs failing the Route A blocking / timeout gate
=============  ===================================================================================

The paper's table is the cooperative model under the *warning* condition; both conditions are
computed (``condition`` column) and the warning rows are what the command line prints.  All
variants share one compiled rollout (they change protocol data only).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.apps.evaluation import evaluate, package_versions
from lantern_jax.core.constants import CONDITIONS, DT, SUITE_ID
from lantern_jax.policies.base import Policy
from lantern_jax.report.results import AblationResult  # noqa: F401  (re-exported)
from lantern_jax.report.tables import ABLATION_TABLE_COLUMNS
from lantern_jax.scenarios.protocol_variants import ABLATIONS, get_ablation
from lantern_jax.scenarios.suite import Suite, load_suite
from lantern_jax.scoring.aggregate import (
    GROUP_COLUMNS,
    OVERALL,
    decomposition_pair_values,
    decomposition_table,
    family_scores,
)
from lantern_jax.scoring.uncertainty import (
    SEED,
    family_intervals,
    interval_columns,
    pooled_intervals,
    settings,
    table_resampling,
)

#: The ablation table's columns (their one home: the table's format).
TABLE_COLUMNS = ABLATION_TABLE_COLUMNS


def variant_condition(condition: str, variant: str) -> str:
    """The route table's condition label of a variant's row (``"warning:late_onset"``)."""
    return condition if variant == "none" else f"{condition}:{variant}"


def ablation_rows(route_table: pd.DataFrame) -> pd.DataFrame:
    """The table's columns for every (model, condition) group of one variant's route rows.

    Returns:
        DataFrame with ``model, condition`` and :data:`TABLE_COLUMNS`.
    """
    fam = family_scores(route_table)
    dec = decomposition_table(route_table)
    rows = []
    for (model, cond), g in route_table.groupby(["model", "condition"], sort=False):
        d = dec.loc[(model, cond)]
        rows.append({
            "model": model,
            "condition": cond,
            "CUS": float(fam.loc[(model, cond), OVERALL]),
            "A-Prog.": float(d["A-Prog."]),
            "Event Exp.": 100.0 * float(np.mean(g["event_exposed"].to_numpy() == 1)),
            "Ant.": float(d["Ant."]),
            "Rec.": float(d["Rec."]),
            "Coll.-A": float(d["Coll.-A"]),
            "Block-A": float(d["Block-A"]),
        })  # fmt: skip
    return pd.DataFrame(rows, columns=["model", "condition", *TABLE_COLUMNS])


def ablation_intervals(route_table: pd.DataFrame, seed: int = SEED) -> pd.DataFrame:
    """Pair-level bootstrap intervals of :func:`ablation_rows` (one variant's route rows):
    ``CUS`` as the family table's ``Overall`` (stratified, macro-average), the other columns
    pooled over the group's pairs (:mod:`lantern_jax.scoring.uncertainty`).

    Returns:
        ``model, condition`` then ``<c>_lo, <c>_hi, <c>_n`` for every :data:`TABLE_COLUMNS`.
    """
    res = table_resampling(route_table, seed=seed)
    fam = family_intervals(route_table, res)
    fam = fam[fam["condition"].isin(set(route_table["condition"]))]
    names = dict(zip(interval_columns(OVERALL), interval_columns("CUS"), strict=True))
    cus = fam[[*GROUP_COLUMNS, *names]].rename(columns=names)
    values = decomposition_pair_values(route_table)
    values["Event Exp."] = 100.0 * (route_table["event_exposed"].to_numpy() == 1)
    rest = pooled_intervals(values, res, TABLE_COLUMNS[1:], GROUP_COLUMNS)
    return cus.merge(rest, on=list(GROUP_COLUMNS), how="left")


def run_ablations(
    policy: str | Policy,
    suite: Suite | str = SUITE_ID,
    policy_params: Any = None,
    variants: Sequence[str] | None = None,
    progress: bool = True,
    bootstrap_seed: int = SEED,
) -> AblationResult:
    """Evaluate ``policy`` under the full protocol and every variant; build the table.

    Args:
        policy: a registered name or a :class:`Policy`.
        suite: a :class:`Suite` or a suite id / manifest path.
        policy_params: the policy's parameters (default: its ``init``).
        variants: ablation names to run (default: every one of
            :data:`~lantern_jax.scenarios.protocol_variants.ABLATIONS`, in that order).
        progress: show progress bars.
        bootstrap_seed: seed of the intervals' bootstrap (recorded in the manifest).

    Raises:
        ValueError: for an unknown variant (listing the valid ones).
    """
    known = {a.name: a.label for a in ABLATIONS}
    names = list(known) if variants is None else list(variants)
    for v in names:
        get_ablation(v)  # refuses an unknown name, listing the valid ones
    s = load_suite(suite) if isinstance(suite, str) else suite
    results, tables, routes, intervals = {}, [], [], []
    for v in names:
        r = evaluate(
            [policy], [policy_params], suite=s, ablation=v, progress=progress,
            bootstrap_seed=bootstrap_seed,
        )  # fmt: skip
        results[v] = r
        t = ablation_rows(r.route_table)
        t.insert(2, "variant", v)
        t.insert(3, "label", known[v])
        tables.append(t)
        iv = ablation_intervals(r.route_table, bootstrap_seed)
        iv.insert(2, "variant", v)
        intervals.append(iv)
        rt = r.route_table.copy()
        rt["condition"] = [variant_condition(c, v) for c in rt["condition"]]
        routes.append(rt)
    first = results[names[0]].manifest
    manifest = dict(
        suite_id=s.suite_id, suite_sha256=s.suite_sha256, suite_seed=s.seed,
        num_pairs=len(s.pairs), conditions=list(CONDITIONS), dt_s=DT,
        variants=[dict(name=v, label=known[v], policies=results[v].manifest["policies"])
                  for v in names],
        policy_init_seed=first["policy_init_seed"], intervals=settings(bootstrap_seed),
        packages=package_versions(),
    )  # fmt: skip
    return AblationResult(
        table=pd.concat(tables, ignore_index=True),
        route_table=pd.concat(routes, ignore_index=True),
        manifest=manifest,
        results=results,
        intervals=pd.concat(intervals, ignore_index=True),
    )
