"""Language sensitivity (beyond the paper): does a policy's warning gain go with the words?

:func:`language_table` runs the warning condition of a suite with the delivered text replaced,
one replacement per variant (:data:`LANGUAGE_VARIANTS`), and reports each family's Route A CUS
and the share of the warning gain (delivered text - no warning) that each replacement keeps:

* **other family's text** -- the canonical text of a family of the other road type at the same
  position (:data:`OTHER_FAMILY`: PE<->LWW, VC<->RWW, OR<->RTY);
* **same road type, other family's paraphrase** -- the first low-ambiguity paraphrase of
  another family of the *same* road type (:data:`SAME_ROAD_OTHER_FAMILY`: PE->VC->OR->PE,
  LWW->RWW->RTY->LWW), at the same position: a hazard that could be on this road, but not
  the one ahead;
* **irrelevant sentence with the position** -- :data:`~lantern_jax.scenarios.warning_texts.
  PROBE_IRRELEVANT`, a sentence about a bakery that states the hazard's position;
* **negated sentence with the position** -- :data:`~lantern_jax.scenarios.warning_texts.
  PROBE_NEGATED`, "nothing is at the position; the lane is clear";
* **empty text** -- no words; under the observation's information boundary a policy cannot tell
  it from no warning (:mod:`lantern_jax.types.observation`), so it keeps nothing by
  construction: the row checks that.

A policy that reads the words keeps little of its gain under every replacement; one that
answers "a warning is on, here is a position" keeps most of it.  The two probe sentences and
the paraphrases are *held out*: no suite, dataset or training recipe of the package delivers
them (the paraphrases are read only by the wording diagnostic and the ``held_out_paraphrase``
ablation; the probes live in no bank but the one this function builds), so a learned model is
tested on words it never trained on.  The "other family's text" swap is, by contrast, among the
counterfactual texts of the closed-loop training recipe
(:mod:`lantern_jax.apps.training.counterfactual`).

The probe sentences are appended to the settings' text bank, whose tables are an argument of
the compiled program: every variant runs the evaluation's program.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import numpy as np
import pandas as pd

from lantern_jax.apps.evaluation import build_executions, run_policy
from lantern_jax.core.constants import FAMILIES, NO_WARNING_CONDITION, SUITE_ID, WARNING_CONDITION
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import Suite, load_suite
from lantern_jax.scenarios.warning_texts import (
    PROBE_IRRELEVANT,
    PROBE_NEGATED,
    TextBank,
)
from lantern_jax.scenarios.warnings import EMPTY_TEXT_ID, paraphrase_text_id
from lantern_jax.scoring.aggregate import OVERALL
from lantern_jax.scoring.uncertainty import SEED, by_family, interval, interval_columns, resampling
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings
from lantern_jax.sim.switch import shared_program

#: The family whose canonical text replaces each family's (index -> index): straight-road
#: families get a junction family's text and the other way round, so the text asks for another
#: response (PE <-> LWW, VC <-> RWW, OR <-> RTY).
OTHER_FAMILY = {f: (f + 3) % len(FAMILIES) for f in range(len(FAMILIES))}
#: The family whose first low-ambiguity paraphrase replaces each family's text: the next family
#: of the same road type (PE -> VC -> OR -> PE on the straight road, LWW -> RWW -> RTY -> LWW at
#: the junction).
SAME_ROAD_OTHER_FAMILY = {f: 3 * (f // 3) + (f + 1) % 3 for f in range(len(FAMILIES))}
#: Every row of :func:`language_table`, in order; the first and the last are always run.
LANGUAGE_VARIANTS = (
    "delivered text",
    "other family's text",
    "same road type, other family's paraphrase",
    "irrelevant sentence with the position",
    "negated sentence with the position",
    "empty text",
    "no warning",
)
#: The variants whose texts are the probe sentences (appended to the bank; one program).
PROBE_VARIANTS = {
    "irrelevant sentence with the position": PROBE_IRRELEVANT,
    "negated sentence with the position": PROBE_NEGATED,
}
MIN_GAIN_FOR_SHARE = 1.0  # CUS points: a smaller warning gain gets no "share kept" (it is noise)


def probe_bank(bank: TextBank) -> tuple[TextBank, dict[str, int]]:
    """``bank`` with the probe sentences appended (as non-actionable texts: they name no hazard
    of the route), and each probe variant's text id in it."""
    bank, ids = bank.with_unrelated_texts(tuple(PROBE_VARIANTS.values()))
    return bank, dict(zip(PROBE_VARIANTS, ids, strict=True))


def with_text_ids(execs: Any, text_ids: np.ndarray) -> Any:
    """The executions with every execution's protocol text replaced by ``text_ids`` ((n,)
    int32, one per execution; Route B and the no-warning condition deliver no text anyway)."""
    cfg = execs.scenarios.config
    text_ids = jax.device_put(np.asarray(text_ids, np.int32).reshape(np.shape(cfg.text_id)))
    return dataclasses.replace(
        execs, scenarios=execs.scenarios.replace(config=cfg.replace(text_id=text_ids))
    )


def _replacement_ids(variant: str, families: np.ndarray, probe_ids: dict[str, int]) -> np.ndarray:
    """(n,) int32: the text each execution of ``families`` ((n,) family index) reads under
    ``variant``."""
    if variant == "other family's text":  # canonical text id == family index
        return np.asarray([OTHER_FAMILY[f] for f in families], np.int32)
    if variant == "same road type, other family's paraphrase":
        return np.asarray([paraphrase_text_id(SAME_ROAD_OTHER_FAMILY[f]) for f in families],
                          np.int32)  # fmt: skip
    if variant == "empty text":
        return np.full(len(families), EMPTY_TEXT_ID, np.int32)
    return np.full(len(families), probe_ids[variant], np.int32)


def _pair_values(runs: dict[str, pd.DataFrame], chosen: Sequence[str], pair_ids: Sequence[str]
                 ) -> np.ndarray:  # fmt: skip
    """(n, V) Route A CUS of every pair (``pair_ids`` order) under every chosen variant: the
    warning condition's, or the no-warning condition's for "no warning"."""
    cols = []
    for v in chosen:
        condition = NO_WARNING_CONDITION if v == "no warning" else WARNING_CONDITION
        rows = runs[v][runs[v]["condition"] == condition].set_index("pair_id")
        cols.append(rows["CUS"].reindex(list(pair_ids)).to_numpy(np.float64))
    return np.column_stack(cols)


def _shares(means: np.ndarray, chosen: Sequence[str]) -> np.ndarray:
    """(..., C, S) share (%) of the warning gain each replaced text keeps, from (..., C, V) means
    (C: the table's columns; S: the variants but "delivered text" and "no warning"); NaN where
    the gain is below :data:`MIN_GAIN_FOR_SHARE`."""
    base = means[..., chosen.index("delivered text")]
    none = means[..., chosen.index("no warning")]
    gain = base - none
    replaced = [i for i, v in enumerate(chosen) if v not in ("delivered text", "no warning")]
    kept = means[..., replaced] - none[..., None]
    ok = gain >= MIN_GAIN_FOR_SHARE
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok[..., None], 100.0 * kept / np.where(ok, gain, 1.0)[..., None], np.nan)


def _with_intervals(runs: dict[str, pd.DataFrame], chosen: Sequence[str], seed: int
                    ) -> pd.DataFrame:  # fmt: skip
    """The table of :func:`language_table` from its runs' route tables."""
    warned = runs["delivered text"]
    warned = warned[warned["condition"] == WARNING_CONDITION]
    res = resampling(warned["pair_id"], warned["family"], seed=seed)
    values = _pair_values(runs, chosen, res.pair_ids)
    ones = np.ones((1, len(res.pair_ids)))
    est, reps = by_family(res, values, ones)[0], by_family(res, values)  # (C, V), (B, C, V)
    columns = [*res.table_families, OVERALL]
    lo, hi = interval(reps)
    share_est, share_reps = _shares(est, chosen), _shares(reps, chosen)
    share_lo, share_hi = interval(share_reps) if share_est.size else (share_est, share_est)
    fewest = min(int(res.family_mask(f).sum()) for f in set(res.families))
    rows = []
    for label, e, a, b in (
        *((v, est[:, k], lo[:, k], hi[:, k]) for k, v in enumerate(chosen)),
        *((f"gain kept by {v} (%)", share_est[:, k], share_lo[:, k], share_hi[:, k])
          for k, v in enumerate(x for x in chosen if x not in ("delivered text", "no warning"))),
    ):  # fmt: skip
        row: dict[str, Any] = {"Variant": label, "n": fewest}
        for j, col in enumerate(columns):
            names = interval_columns(col)
            row[col], row[names[0]], row[names[1]] = float(e[j]), float(a[j]), float(b[j])
        rows.append(row)
    # the six built-in families are always columns (NaN without pairs), registered ones follow
    ordered = ["Variant", "n", *columns,
               *(x for c in columns for x in interval_columns(c)[:2])]  # fmt: skip
    return pd.DataFrame(rows)[ordered]


def language_table(
    policy: Policy | str,
    suite: Suite | str = SUITE_ID,
    policy_params: Any = None,
    variants: Sequence[str] = LANGUAGE_VARIANTS,
    settings: Settings = DEFAULT_SETTINGS,
    bootstrap_seed: int = SEED,
) -> pd.DataFrame:
    """Language sensitivity of one policy on a suite (see the module docstring).

    Args:
        policy: a :class:`Policy` or a registered name.
        suite: a suite or its id.
        policy_params: the policy's parameters (default: its ``init``).
        variants: the rows to run, a subset of :data:`LANGUAGE_VARIANTS` ("delivered text" and
            "no warning" are always run); listed in that order.
        settings: scoring, protocol and text bank (the probes are appended to its bank).
        bootstrap_seed: seed of the intervals' pair bootstrap.

    Returns:
        One row per variant (Route A CUS per family and Overall, the macro-average of the
        families: the warning condition's, the no-warning condition's for "no warning"), then
        one row per replaced text with the share (%) of the warning gain it keeps,
        ``(variant - no warning) / (delivered - no warning)`` (NaN where the gain is below
        :data:`MIN_GAIN_FOR_SHARE` points); ``n`` the fewest pairs of a family in the suite
        (what a family cell's interval rests on), and ``<column>_lo`` /
        ``<column>_hi`` the 95 % interval of every cell over the suite's pairs (bootstrap
        stratified by family; a share's interval paired: the ratio of each replicate's means,
        NaN replicates -- gain below the threshold -- left out).

    Raises:
        ValueError: naming a variant not in :data:`LANGUAGE_VARIANTS`.
    """
    unknown = [v for v in variants if v not in LANGUAGE_VARIANTS]
    if unknown:
        raise ValueError(f"variants: {unknown} not among {list(LANGUAGE_VARIANTS)}")
    chosen = [v for v in LANGUAGE_VARIANTS
              if v in variants or v in ("delivered text", "no warning")]  # fmt: skip
    s = load_suite(suite) if isinstance(suite, str) else suite
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    execs = build_executions(s, bucket=True)
    fam = np.asarray(execs.scenarios.config.family).astype(int)
    shared = shared_program([pol], [params])  # a reference policy: the evaluation's program
    probes, probe_ids = probe_bank(settings.bank)
    probe_settings = settings.replace(bank=probes)
    runs = {"delivered text": run_policy(pol, execs, params, shared=shared,
                                         settings=settings).route_table}  # fmt: skip
    for v in chosen:
        if v in ("delivered text", "no warning"):
            continue
        replaced = with_text_ids(execs, _replacement_ids(v, fam, probe_ids))
        run_settings = probe_settings if v in PROBE_VARIANTS else settings
        runs[v] = run_policy(pol, replaced, params, shared=shared,
                             settings=run_settings).route_table  # fmt: skip
    runs["no warning"] = runs["delivered text"]
    return _with_intervals(runs, chosen, bootstrap_seed)
