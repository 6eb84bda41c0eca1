"""What an evaluation and an ablation table produce, as data: the types the report's tables
and files are written from.

They live here, below the code that computes them (:mod:`lantern_jax.apps.evaluation`,
:mod:`lantern_jax.apps.ablation_table`), so that the report names them without importing its
callers.  :class:`lantern_jax.apps.evaluation.EvalResult` is :class:`Evaluation` with the
methods that write its files and its HTML report.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from lantern_jax.scoring.uncertainty import TableIntervals


@dataclasses.dataclass
class PolicyRun:
    """Raw results of one policy on one suite."""

    policy: str
    params_sha256: str
    metrics: dict[str, np.ndarray]  # per execution (Executions.num_executions), numpy
    protocol: dict[str, np.ndarray]
    route_table: pd.DataFrame
    seconds_compile: float
    seconds_run: float
    #: wall seconds by phase: "trace + lower", "XLA compile", "rollout", "scoring"
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    #: how it was rolled out and why (:class:`~lantern_jax.sim.engine.PathChoice` as text)
    program: str = ""
    #: every execution's final :class:`~lantern_jax.scoring.telemetry.Telemetry` (NumPy, leading
    #: axis Executions.num_executions; about 0.5 kB each): what the soft, differentiable score
    #: reads (:func:`~lantern_jax.scoring.cus.soft_pair_cus`), so that it needs no second rollout
    telemetry: Any = None


@dataclasses.dataclass
class Evaluation:
    """Everything an evaluation produces (:class:`lantern_jax.apps.evaluation.EvalResult` adds the
    methods that write it)."""

    route_table: pd.DataFrame
    family_table: pd.DataFrame
    decomposition: pd.DataFrame
    manifest: dict
    runs: list[PolicyRun]
    premise: pd.DataFrame  # % of Route A executions with the hazard unseen (``premise_table``)
    #: pair-level bootstrap intervals (``uncertainty.CONFIDENCE``) and counts of the three tables
    #: (:func:`lantern_jax.scoring.uncertainty.table_intervals`)
    intervals: TableIntervals | None = None
    #: wall seconds of the shared phases: "world build", "tables", "intervals" and, when the
    #: split path ran, "split programs" (the world's and the policies' programs prepared
    #: together; per policy: ``runs``)
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class AblationResult:
    """Everything :func:`lantern_jax.apps.ablation_table.run_ablations` produces."""

    table: pd.DataFrame  # model, condition, variant, label, then TABLE_COLUMNS (0..100)
    route_table: pd.DataFrame  # every variant's route rows; condition "<c>" or "<c>:<variant>"
    manifest: dict
    results: dict[str, Evaluation]  # per variant
    #: model, condition, variant, then <c>_lo, <c>_hi, <c>_n per TABLE_COLUMNS
    #: (:func:`lantern_jax.apps.ablation_table.ablation_intervals`)
    intervals: pd.DataFrame | None = None
