"""``lantern-jax compare``: is one evaluation better than another, and by how much?

::

    lantern-jax compare results --policy coop --policy expert       # two policies, one set
    lantern-jax compare runs/before runs/after --policy coop        # one policy, two sets

Per family and overall, under every condition both sides hold and for the warning gain: the
paired difference of mean CUS (first minus second), its bootstrap interval and a paired
bootstrap p-value (:func:`lantern_jax.compare.compare_runs`).  Two result sets must hold the
same pairs (and, where both manifests record it, the same suite hash).  A result set is a
folder written by ``lantern-jax evaluate`` (or ``ablations``), or its route-level CSV.  The
table is printed and written as ``comparison.md`` and ``comparison.csv`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import shlex
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out, split_values

COMPARISON_MD = "comparison.md"
COMPARISON_CSV = "comparison.csv"
#: Route-level CSVs a result folder may hold, with the manifest beside each.
RESULT_FILES = (
    ("route_level_results.csv", "reproducibility_manifest.json"),
    ("ablation_route_level_results.csv", "ablations_manifest.json"),
)


def _result_set(path: str) -> tuple[Path, dict]:
    """The route-level CSV of a result folder (or the CSV itself) and its manifest ({} if none).

    Raises:
        UsageError: when there is no route-level CSV there.
    """
    p = Path(path)
    if p.is_file():
        manifests = [m for c, m in RESULT_FILES if c == p.name]
        m = p.with_name(manifests[0]) if manifests else None
        return p, json.loads(m.read_text()) if m is not None and m.is_file() else {}
    for csv, manifest in RESULT_FILES:
        if (p / csv).is_file():
            m = p / manifest
            return p / csv, json.loads(m.read_text()) if m.is_file() else {}
    names = " or ".join(c for c, _ in RESULT_FILES)
    raise UsageError(f"{path}: no result set there (expected a folder with {names})")


def _rows(df, model: str, where: str):
    rows = df[df["model"] == model]
    if rows.empty:
        there = ", ".join(sorted(set(df["model"])))
        raise UsageError(f"--policy {model!r}: not in {where} (models there: {there})")
    return rows


def cmd_compare(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Compare two policies of one result set, or one policy in two; returns the exit code."""
    from lantern_jax.compare import compare_runs, format_comparison
    from lantern_jax.files import StagedFolder, atomic_write
    from lantern_jax.report import interval_note
    from lantern_jax.scoring.table import read_route_table
    from lantern_jax.scoring.uncertainty import SEED, settings

    policies = split_values(args.policy)
    sets = list(args.results)
    if len(sets) == 1 and len(policies) == 2:
        (path, manifest) = _result_set(sets[0])
        df = read_route_table(path)
        a, b = (_rows(df, p, sets[0]) for p in policies)
        labels = policies
    elif len(sets) == 2 and len(policies) == 1:
        (pa, ma), (pb, mb) = _result_set(sets[0]), _result_set(sets[1])
        ha, hb = ma.get("suite_sha256"), mb.get("suite_sha256")
        if ha and hb and ha != hb:
            raise UsageError(
                f"{sets[0]} and {sets[1]} were evaluated on different suites (suite hashes "
                f"{ha[:12]} and {hb[:12]}); a paired comparison needs the same pairs"
            )
        a = _rows(read_route_table(pa), policies[0], sets[0])
        b = _rows(read_route_table(pb), policies[0], sets[1])
        labels = [f"{policies[0]} ({s})" for s in sets]
    else:
        raise UsageError(
            "give one result set and two --policy names, or two result sets and one --policy "
            f"(got {len(sets)} result set(s) and {len(policies)} policy name(s))"
        )
    seed = SEED if args.bootstrap_seed is None else args.bootstrap_seed
    check_out(args.out)
    try:
        table = compare_runs(a, b, seed=seed)
    except ValueError as e:
        raise UsageError(str(e)) from None
    title = f"Paired comparison of mean CUS: {labels[0]} - {labels[1]}"
    note = (
        f"{interval_note(settings(seed))}; p: two-sided paired bootstrap p-value of a zero "
        "difference; n: pairs compared."
    )
    print(title)
    print(format_comparison(table, *labels))
    print(note)
    md = f"# {title}\n\n{note}\n\n{format_comparison(table, *labels, tablefmt='github')}\n"
    command = shlex.join(["lantern-jax", *argv])
    with StagedFolder(args.out, (COMPARISON_MD, COMPARISON_CSV)) as stage:
        atomic_write(stage.path / COMPARISON_MD, f"{md}\nCommand: `{command}`\n".encode())
        csv = table.to_csv(index=False, float_format="%.6f", lineterminator="\n")
        atomic_write(stage.path / COMPARISON_CSV, csv.encode())
        stage.commit()
    print(f"Wrote {Path(args.out) / COMPARISON_MD} and {Path(args.out) / COMPARISON_CSV}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``compare`` on the command line's sub-parsers."""
    co = sub.add_parser(
        "compare",
        help="paired difference of two evaluations, with intervals and p-values",
        description="Paired difference of mean CUS (first minus second) per family and overall, "
        "under every shared condition and for the warning gain, with its bootstrap interval "
        "and p-value: two policies of one result set, or one policy in two result sets over "
        "the same pairs.",
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
        help="the policy (two result sets) or each of the two policies (one result set)",
    )
    co.add_argument(
        "--bootstrap-seed", type=int, metavar="N", help="seed of the bootstrap (default fixed)"
    )
    co.add_argument(
        "--out", default="results/compare", metavar="DIR", help="output folder (comparison.md)"
    )
    co.set_defaults(func=cmd_compare)
