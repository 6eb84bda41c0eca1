"""``lantern-jax unseen``: the paper's unseen-hazard tables for one policy.

::

    lantern-jax unseen --policy coop                      # the shipped lantern-unseen suite
    lantern-jax unseen --policy learned-coop --out runs/unseen
    lantern-jax --families my_families.py unseen --policy coop --suite my_suite.json

runs every pair of the suite under no warning, the exact (free-form) warning and the held-out
paraphrase (:mod:`lantern_jax.apps.transfer`), prints the paper's two tables (the occluded cyclist;
the emergency vehicle crossing and the reversing vehicle; one more for any other family of the
suite) with the paper's figures beneath, and writes them with the per-pair rows as CSV and
Markdown into ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out, write_and_list

DEFAULT_OUT = "results/unseen"


def unseen_files() -> tuple[str, ...]:
    """Every file ``unseen`` may write: ``unseen_<k>`` for each of the paper's tables and one
    for other families (:func:`lantern_jax.apps.transfer.table_groups`), and ``unseen_pairs``, each
    as ``.csv`` and ``.md``; checked up front so that no entry of the user's is in the way."""
    from lantern_jax.apps.transfer import PAPER_TABLES

    stems = [f"unseen_{k + 1}" for k in range(len(PAPER_TABLES) + 1)] + ["unseen_pairs"]
    return tuple(f"{stem}{ext}" for stem in stems for ext in (".csv", ".md"))


def cmd_unseen(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the unseen-hazard tables for one policy; returns the exit code."""
    del argv
    from tabulate import tabulate

    try:  # registers the shipped unseen hazards: refused if a family of yours took a code
        from lantern_jax.apps import transfer
    except ValueError as e:
        raise UsageError(
            f"the unseen hazards cannot be registered: {e} (a --families file registered a "
            "family under one of their codes)"
        ) from None
    from lantern_jax.commands.common import resolve_policies
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.scenarios.suite import SuiteError, load_suite

    names = resolve_policies([args.policy])  # a registered name, or file.py:NAME
    if len(names) != 1:
        raise UsageError(f"--policy: give one policy, got {', '.join(names)}")
    policy = get_policy(names[0])
    check_out(args.out, owned=unseen_files())
    try:
        suite = transfer.unseen_suite() if args.suite is None else load_suite(args.suite)
    except (FileNotFoundError, SuiteError, ValueError) as e:
        raise UsageError(str(e).strip("'\"")) from None
    if not args.quiet:
        print(f"[unseen] {policy.name} on {suite.suite_id} ({len(suite)} pairs): no warning, "
              "exact warning, held-out paraphrase", file=sys.stderr)  # fmt: skip
    result = transfer.run_transfer(policy, suite)
    tables = {}
    for k, (title, families) in enumerate(transfer.table_groups(result.summary)):
        rows = transfer.table_rows(result.summary, families)
        heading = (f"{title}  ({policy.name}, suite {suite.suite_id}; mean over pairs "
                   "[95 % bootstrap interval]; RC, Coll., Block in % of pairs)")  # fmt: skip
        print(heading)
        print(tabulate(rows, headers="keys", showindex=False, disable_numparse=True))
        note = transfer.paper_note(families)
        if note:
            print(note)
        print()
        tables[f"unseen_{k + 1}"] = (heading, rows)
    tables["unseen_pairs"] = (f"Unseen hazards, per pair ({policy.name})", result.rows)
    print("Lead: event-on time minus the first of three consecutive 20-Hz control steps with "
          "brake signal >= 0.5 (commanded deceleration / brake limit), searched from the warning "
          "point; Resp.: pairs with such a response.")  # fmt: skip
    return write_and_list(tables, args.out)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``unseen`` to the sub-command parsers."""
    p = sub.add_parser(
        "unseen",
        allow_abbrev=False,
        help="the paper's unseen-hazard tables (cyclist, emergency vehicle, reversing vehicle)",
        description="Run a policy on the unseen-hazard suite under no warning, the exact "
        "warning and a held-out paraphrase and print the paper's tables: response lead, "
        "pre-event speed reduction, route completion, collision, blocking and CUS per condition.",
    )
    p.add_argument("--policy", required=True, metavar="NAME", help="a registered policy")
    p.add_argument(
        "--suite",
        metavar="PATH",
        help="a suite file of registered families (default: the shipped lantern-unseen suite)",
    )
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output folder (default: {DEFAULT_OUT})")  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no stage line")
    p.set_defaults(func=cmd_unseen)
