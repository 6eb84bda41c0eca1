"""``lantern-jax wording``: warning wording by ambiguity tier (the paper's appendix table).

::

    lantern-jax wording --policy coop    # paraphrase vs canonical CUS per ambiguity tier
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from lantern_jax.commands.common import (
    add_one_policy,
    check_out,
    load_selected_suite,
    one_policy,
    print_and_write,
    stage,
)
from lantern_jax.commands.values import count
from lantern_jax.core.constants import SUITE_ID


def cmd_wording(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax wording``: the warning-wording table by ambiguity tier."""
    del argv
    policy = one_policy(args)
    check_out(args.out, owned=("wording.csv", "wording.md"))
    suite = load_selected_suite(args)
    stage(args, f"{policy} on {suite.suite_id} ({len(suite)} pairs): canonical and tiered "
                "paraphrase warnings")  # fmt: skip
    from lantern_jax.apps.diagnostics import WORDING_COLUMNS, wording_table
    from lantern_jax.report import interval_display, interval_note

    table = wording_table(policy, suite)
    title = (
        f"Warning wording by ambiguity  ({policy}, suite {suite.suite_id}; Route A with warning; "
        "retention = paraphrase / matched canonical CUS)"
    )
    note = (
        "Matched no-warning = the same pairs without any warning (what ignoring the text scores). "
        + interval_note(over="each row's route pairs; retention paired")
        + "."
    )
    display = interval_display(table, WORDING_COLUMNS, "n")
    return print_and_write({"wording": (title, table, display)}, args.out, note)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``wording`` on the command line's sub-parsers."""
    wo = sub.add_parser(
        "wording",
        allow_abbrev=False,
        help="warning wording by ambiguity tier (paraphrase vs canonical CUS)",
        description="Run a policy on the suite with the canonical warnings and with held-out "
        "paraphrases of three ambiguity tiers (three disjoint thirds of the suite), print and "
        "write the paraphrase CUS, matched canonical CUS, retention and collision rate per tier.",
    )
    add_one_policy(wo)
    wo.add_argument("--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or path")
    wo.add_argument(
        "--pairs-per-family", type=count(), metavar="N",
        help="only the first N pairs of each family",
    )
    wo.add_argument("--out", default="results/language", metavar="DIR", help="output folder")
    wo.add_argument("--quiet", action="store_true", help="no stage lines")
    wo.set_defaults(func=cmd_wording, pairs=None)
