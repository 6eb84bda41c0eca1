"""``lantern-jax evaluate --fresh-suites K --seed S``: the main table on more than one suite.

One suite is one sample of pairs; a conclusion that holds on it may not hold on another drawn
the same way.  This generates ``K`` fresh suites with the suite generator
(:func:`lantern_jax.apps.suite_generation.generate_suite`, the same design and the same validator as
the ``--suite`` they are compared with), from seeds ``S, S + 1, ..., S + K - 1``, evaluates the
``--suite`` and every fresh one with the same policies and ablation, and reports:

* every suite's tables with their intervals (its result set in ``OUT/<suite id>/``);
* the family table and the decomposition across suites: per cell the mean over suites and the
  sample standard deviation across them (``across_suites.md|csv``), with ``across_suites.json``
  recording every suite's id, seed, hash and result folder.

The fresh manifests are written to ``OUT/suites/<suite id>.json`` (``lantern-jax evaluate
--suite`` runs them again); a manifest already there with the same seed and validator is
loaded instead of generated again.
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError

SUITES_DIR = "suites"


def fresh_seeds(seed: int, count: int) -> list[int]:
    """The generation seeds of ``count`` fresh suites starting at ``seed``."""
    return [seed + k for k in range(count)]


def fresh_suite_id(seed: int) -> str:
    """The id of the suite the generator draws from ``seed`` (its design is ``SUITE_ID``'s)."""
    from lantern_jax.core.constants import SUITE_ID

    return f"{SUITE_ID}-seed{seed}"


def _fresh_suite(base, seed: int, out: Path, progress: bool):
    """Generate (or load, when written before from the same seed and validator) one suite."""
    from lantern_jax.apps.suite_generation import generate_suite, suite_validator
    from lantern_jax.scenarios.suite import load_suite, write_manifest

    validator = suite_validator(base.report)
    sid = fresh_suite_id(seed)
    path = out / SUITES_DIR / f"{sid}.json"
    if path.is_file():
        kept = load_suite(path)
        if kept.seed == seed and suite_validator(kept.report) == validator:
            return kept, path, False
    manifest = generate_suite(seed, progress=progress, validator=validator)
    manifest["suite_id"] = sid
    path.parent.mkdir(parents=True, exist_ok=True)
    write_manifest(manifest, path)
    return load_suite(path), path, True


def run_fresh_suites(
    args: argparse.Namespace,
    argv: Sequence[str],
    policies: list[str],
    base,
    stage,
    evaluate_kwargs: dict,
) -> int:
    """Evaluate ``base`` and ``args.fresh_suites`` fresh suites; print and write the tables.

    Args:
        args: the ``evaluate`` options (``fresh_suites``, ``seed``, ``pairs_per_family``,
            ``pairs``, ``out``, ``quiet``).
        argv: the command line (recorded in the manifests).
        policies: the policies to evaluate.
        base: the loaded ``--suite`` (already cut to ``--pairs-per-family``).
        stage: ``stage(message)`` prints a stage line.
        evaluate_kwargs: further arguments of :func:`lantern_jax.apps.evaluation.evaluate`.

    Returns:
        The exit code.

    Raises:
        UsageError: for a missing ``--seed``, ``--pairs`` (fresh suites have other pairs), or a
            seed that is the base suite's own.
    """
    from lantern_jax.apps.evaluation import evaluate
    from lantern_jax.report import format_tables, write_outputs

    out = Path(args.out)
    command = shlex.join(["lantern-jax", *argv])
    suites = [(base, None, None)] + _fresh_suites(args, base, out, stage)
    results, records = [], []
    for suite, seed, path in suites:
        stage(f"evaluating {', '.join(policies)} on {suite.suite_id} ({len(suite)} pairs)")
        result = evaluate(policies, suite=suite, progress=not args.quiet, **evaluate_kwargs)
        folder = out / suite.suite_id
        write_outputs(result, folder, extra_manifest={"command": command})
        print(format_tables(result))
        print()
        results.append(result)
        records.append(dict(
            suite_id=suite.suite_id, suite_seed=suite.seed, suite_sha256=suite.suite_sha256,
            num_pairs=len(suite), fresh=seed is not None,
            manifest=None if path is None else str(path), results=str(folder),
        ))  # fmt: skip
    record = dict(command=command, suites=records, policies=policies,
                  intervals=results[0].manifest.get("intervals"))  # fmt: skip
    from lantern_jax.report.compare import write_across_suites

    print(write_across_suites(results, record, out))
    return 0


def _fresh_suites(args: argparse.Namespace, base, out: Path, stage) -> list[tuple]:
    """``(suite, seed, manifest path)`` of every fresh suite, generated or loaded (cut to
    ``--pairs-per-family``), after checking the options."""
    if args.seed is None:
        raise UsageError("--fresh-suites needs --seed S (suite k is generated from S + k)")
    if args.pairs is not None:
        raise UsageError("--pairs cannot select pairs of fresh suites; use --pairs-per-family")
    if args.fresh_suites < 1:
        raise UsageError(f"--fresh-suites must be >= 1 (got {args.fresh_suites})")
    seeds = fresh_seeds(args.seed, args.fresh_suites)
    if base.seed in seeds:
        raise UsageError(f"--seed: seed {base.seed} generated {base.suite_id} itself")
    suites = []
    for seed in seeds:
        stage(f"suite from seed {seed}: generating (or loading) {fresh_suite_id(seed)}")
        suite, path, made = _fresh_suite(base, seed, out, progress=not args.quiet)
        if args.pairs_per_family is not None:
            suite = suite.subset(args.pairs_per_family)
        stage(f"{suite.suite_id}: {len(suite)} pairs, hash {suite.suite_sha256[:12]} "
              f"({'generated' if made else 'loaded'} {path})")  # fmt: skip
        suites.append((suite, seed, path))
    return suites
