"""``lantern-jax compare``: is one evaluation better than another, and by how much?

::

    lantern-jax compare results --policy coop --policy expert       # two policies, one set
    lantern-jax compare runs/before runs/after --policy coop        # one policy, two sets
    lantern-jax compare runs/v1 runs/v2 --policy mine-v1 --policy mine-v2   # each set's own

Per family and overall, under every condition both sides hold and for the warning gain: the
paired difference of mean CUS (first minus second), its bootstrap interval and a paired
bootstrap p-value (:func:`lantern_jax.report.compare.compare_runs`).  A result set is a folder
written by ``lantern-jax evaluate`` (or ``ablations``), or its route-level CSV, and it is read
as evidence (:mod:`lantern_jax.report.evidence`): every file checked against its manifest's
SHA-256, the table against its schema and the manifest's row count.  Two result sets must hold
the same pairs under one protocol (suite, ablation, settings: refused otherwise unless
``--accept-protocol-difference``); differing package versions are named above the table.  The
table is printed and written as ``comparison.md`` and ``comparison.csv`` into ``--out``.
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out, split_values
from lantern_jax.commands.values import seed


def _read(path: str):
    """The checked result set at ``path`` (:func:`lantern_jax.report.evidence.read_result_set`).

    Raises:
        UsageError: naming the file and what is wrong with it.
    """
    from lantern_jax.report.evidence import ResultSetError, read_result_set

    try:
        return read_result_set(path)
    except ResultSetError as e:
        raise UsageError(str(e)) from None


def _rows(df, model: str, where: str):
    rows = df[df["model"] == model]
    if rows.empty:
        there = ", ".join(sorted(set(df["model"])))
        raise UsageError(f"--policy {model!r}: not in {where} (models there: {there})")
    return rows


def cmd_compare(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Compare two policies of one result set, one policy in two, or the first set's policy
    with the second set's; returns the exit code."""
    from lantern_jax.report import interval_note
    from lantern_jax.report.compare import COMPARISON_FILES, compare_runs, write_comparison
    from lantern_jax.scoring.uncertainty import SEED, settings

    policies = split_values(args.policy)
    sets = list(args.results)
    notes: list[str] = []
    if len(sets) == 1 and len(policies) == 2:
        if policies[0] == policies[1]:
            raise UsageError(f"--policy {policies[0]!r} given twice: a policy compared with "
                             "itself differs by nothing")  # fmt: skip
        df = _read(sets[0]).table
        a, b = (_rows(df, p, sets[0]) for p in policies)
        labels = policies
    elif len(sets) == 2 and len(policies) in (1, 2):
        ra, rb = _read(sets[0]), _read(sets[1])
        pa, pb = policies[0], policies[-1]
        if ra.csv.resolve() == rb.csv.resolve() and pa == pb:
            raise UsageError(f"{sets[0]} and {sets[1]} are the same result set: a policy "
                             "compared with itself differs by nothing")  # fmt: skip
        notes = _protocol_notes(ra.manifest, rb.manifest, sets, args.accept_protocol_difference)
        a = _rows(ra.table, pa, sets[0])
        b = _rows(rb.table, pb, sets[1])
        labels = [f"{pa} ({sets[0]})", f"{pb} ({sets[1]})"]
    else:
        raise UsageError(
            "give one result set and two --policy names, or two result sets and one --policy "
            "(or two: the first set's against the second's) "
            f"(got {len(sets)} result set(s) and {len(policies)} policy name(s))"
        )
    seed = SEED if args.bootstrap_seed is None else args.bootstrap_seed
    check_out(args.out, owned=COMPARISON_FILES)
    try:
        table = compare_runs(a, b, seed=seed)
    except ValueError as e:
        raise UsageError(str(e)) from None
    command = shlex.join(["lantern-jax", *argv])
    print(write_comparison(table, labels, notes, interval_note(settings(seed)), command,
                           Path(args.out)))  # fmt: skip
    print("Wrote " + " and ".join(str(Path(args.out) / f) for f in COMPARISON_FILES))
    return 0


def _protocol_notes(ma: dict, mb: dict, sets: list[str], accept: bool) -> list[str]:
    """The lines to show above the table: differences of protocol (refused unless ``accept``)
    and of package versions.

    Raises:
        UsageError: naming every protocol field that differs, when not ``accept``.
    """
    from lantern_jax.report.evidence import protocol_differences, version_differences

    protocol = protocol_differences(ma, mb)
    if protocol and not accept:
        raise UsageError(
            f"{sets[0]} and {sets[1]} were not run under one protocol ({'; '.join(protocol)}); "
            "a difference would mix the policy with the protocol (--accept-protocol-difference "
            "compares them anyway, saying so above the table)"
        )
    notes = [f"protocol differs (accepted): {line}" for line in protocol]
    return notes + [f"package versions differ: {line}" for line in version_differences(ma, mb)]


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``compare`` on the command line's sub-parsers."""
    co = sub.add_parser(
        "compare",
        help="paired difference of two evaluations, with intervals and p-values",
        description="Paired difference of mean CUS (first minus second) per family and overall, "
        "under every shared condition and for the warning gain, with its bootstrap interval "
        "and p-value: two policies of one result set, or one policy in two result sets over "
        "the same pairs, or the first set's policy against the second set's.",
        allow_abbrev=False,
    )
    co.add_argument(
        "results",
        nargs="+",
        metavar="RESULTS",
        help="one or two result folders (or route-level CSV files)",
    )
    co.add_argument(
        "--policy",
        action="append",
        metavar="NAME",
        help="the policy (two result sets) or each of the two policies (one result set; with "
        "two result sets, the first set's policy then the second's)",
    )
    co.add_argument(
        "--bootstrap-seed", type=seed(), metavar="N", help="seed of the bootstrap (default fixed)"
    )
    co.add_argument(
        "--out", default="results/compare", metavar="DIR", help="output folder (comparison.md)"
    )
    co.add_argument(
        "--accept-protocol-difference",
        action="store_true",
        help="compare two result sets run under different protocols (suite, ablation, "
        "settings); the differences are printed above the table and kept in comparison.md",
    )
    co.set_defaults(func=cmd_compare)
