"""``lantern-jax ablations``: list the protocol ablations, or run the paper's ablation table.

::

    lantern-jax ablations --list         # the protocol ablations
    lantern-jax ablations --policy coop  # the paper's ablation table for one policy
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import (
    check_out,
    list_written,
    load_selected_suite,
    resolve_policies,
    run_record,
    stage,
    write_failed,
)
from lantern_jax.commands.values import count
from lantern_jax.core.constants import CONDITIONS, EXECUTIONS_PER_PAIR, SUITE_ID


def list_ablations() -> None:
    """Print every protocol ablation with its description."""
    from tabulate import tabulate

    from lantern_jax.scenarios.protocol_variants import ABLATIONS

    rows = [[a.name, a.description] for a in ABLATIONS]
    print(tabulate(rows, headers=["ablation", "description"], disable_numparse=True))


def cmd_ablations(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax ablations``: list the protocol ablations, or run the ablation table."""
    if args.list or args.policy is None:
        list_ablations()
        if args.policy is None and not args.list:
            print("\n(run the table with: lantern-jax ablations --policy NAME)")
        return 0
    policies = resolve_policies([args.policy])
    if len(policies) != 1:
        raise UsageError(f"--policy: give one policy, got {', '.join(policies)}")
    from lantern_jax.report.outputs import ABLATION_FILES

    check_out(args.out, owned=ABLATION_FILES)
    suite = load_selected_suite(args)
    from lantern_jax.apps.ablation_table import run_ablations
    from lantern_jax.apps.evaluation import PolicyError
    from lantern_jax.report import format_ablation_table, interval_note, write_ablation_outputs
    from lantern_jax.scenarios.protocol_variants import ABLATIONS

    stage(
        args,
        f"suite {suite.suite_id}: {len(suite)} pairs; policy {policies[0]}; "
        f"{len(ABLATIONS)} protocol variants x {EXECUTIONS_PER_PAIR * len(suite)} executions",
    )
    t0 = time.perf_counter()
    try:
        result = run_ablations(policies[0], suite=suite, progress=not args.quiet)
    except PolicyError as e:
        print(f"lantern-jax ablations: error: {e}", file=sys.stderr)
        return 1
    stage(args, f"done in {time.perf_counter() - t0:.1f} s; writing {args.out}")
    try:
        files = write_ablation_outputs(result, args.out, run_record=run_record(argv))
    except OSError as e:
        return write_failed(args.out, e)
    m = result.manifest
    print(
        f"Ablations  (suite {m['suite_id']}, {m['num_pairs']} pairs, policy {policies[0]}, "
        f"{CONDITIONS[0]} condition; all entries 0-100)"
    )
    print(format_ablation_table(result.table, intervals=result.intervals))
    print(interval_note(m.get("intervals")))
    print()
    list_written(files.values())
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``ablations`` on the command line's sub-parsers."""
    ab = sub.add_parser(
        "ablations",
        allow_abbrev=False,
        help="list the protocol ablations, or run the ablation table for a policy",
        description="Without --policy (or with --list): list the protocol ablations. With "
        "--policy NAME: evaluate the policy under the full temporal protocol and each of the "
        "five variants, print the paper's ablation table (CUS, A-Prog., Event Exp., Ant., "
        "Rec., Coll.-A, Block-A; warning condition) and write it with every variant's "
        "route-level rows.",
    )
    ab.add_argument("--list", action="store_true", help="list the ablations and exit")
    ab.add_argument("--policy", metavar="NAME", help="run the table for this policy")
    ab.add_argument(
        "--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or manifest path"
    )
    ab.add_argument(
        "--pairs-per-family", type=count(), metavar="N",
        help="only the first N pairs of each family",
    )
    ab.add_argument("--pairs", action="append", metavar="ID[,ID...]", help="only these pair ids")
    ab.add_argument(
        "--out",
        default="results/ablations",
        metavar="DIR",
        help="output folder "
        "(default: results/ablations; the set replaces an earlier one there as a whole)",
    )
    ab.add_argument("--quiet", action="store_true", help="no progress bar or stage lines")
    ab.set_defaults(func=cmd_ablations)
