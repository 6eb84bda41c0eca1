"""``lantern-jax diagnostics nonactionable|distance|language``: the paper's appendix diagnostics
of warning language.

::

    lantern-jax diagnostics nonactionable --policy coop   # non-actionable warnings, empty road
    lantern-jax diagnostics distance --policy coop        # near vs far warning on Route B
    lantern-jax diagnostics language --policy coop        # does the policy read the words?
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import (
    add_one_policy,
    check_out,
    load_selected_suite,
    one_policy,
    print_and_write,
    stage,
)
from lantern_jax.commands.values import count, number
from lantern_jax.core.constants import FAMILIES, SUITE_ID

#: Options of ``diagnostics`` that only the distance diagnostic reads.
DISTANCE_OPTIONS = ("suite", "family", "routes", "window")
#: The options each diagnostic reads.
READS = {
    "nonactionable": (),
    "distance": DISTANCE_OPTIONS,
    "language": ("suite", "pairs_per_family"),
}


def _check_options(args: argparse.Namespace) -> None:
    """Refuse options the chosen diagnostic does not read."""
    given = [
        f"--{k.replace('_', '-')}"
        for k in (*DISTANCE_OPTIONS, "pairs_per_family")
        if getattr(args, k) is not None and k not in READS[args.which]
    ]
    if given:
        raise UsageError(f"{', '.join(given)}: the {args.which} diagnostic does not read "
                         f"{'it' if len(given) == 1 else 'them'}")  # fmt: skip


#: The tables each diagnostic writes (``STEM.csv`` and ``STEM.md`` into ``--out``).
OUTPUT_STEMS = {
    "nonactionable": ("nonactionable",),
    "distance": ("distance_open_loop", "distance_closed_loop", "distance_summary"),
    "language": ("language",),
}


def cmd_diagnostics(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax diagnostics nonactionable|distance|language``."""
    del argv
    _check_options(args)
    policy = one_policy(args)
    check_out(args.out, owned=[f"{stem}{ext}" for stem in OUTPUT_STEMS[args.which]
                               for ext in (".csv", ".md")])  # fmt: skip
    run = {"nonactionable": _nonactionable, "distance": _distance, "language": _language}
    return run[args.which](args, policy)


def _language(args: argparse.Namespace, policy: str) -> int:
    """The warning condition with the delivered text and with each replacement of it
    (:data:`lantern_jax.apps.language_sensitivity.LANGUAGE_VARIANTS`)."""
    from lantern_jax.apps import language_sensitivity as ls
    from lantern_jax.report import interval_display, interval_note

    args.suite = args.suite or SUITE_ID
    suite = load_selected_suite(args)
    stage(args, f"{policy} on {suite.suite_id} ({len(suite)} pairs): "
                f"{', '.join(ls.LANGUAGE_VARIANTS)}")  # fmt: skip
    table = ls.language_table(policy, suite)
    title = (
        f"Language sensitivity  ({policy}, suite {suite.suite_id}; Route A CUS per family; "
        "texts at the hazard's position: other family's text: PE<->LWW, VC<->RWW, OR<->RTY "
        "canonical texts; same road type: PE->VC->OR->PE, LWW->RWW->RTY->LWW first "
        "paraphrases; irrelevant and negated sentences: held out, see docs/language.md)"
    )
    note = (
        "gain kept = (variant - no warning) / (delivered text - no warning); a policy that "
        "reads the words keeps little of its gain under every replacement ('-' where the gain "
        f"is below {ls.MIN_GAIN_FOR_SHARE:.0f} point). "
        + interval_note(over="route pairs, stratified by family; gain kept paired")
        + "."
    )
    columns = [c for c in table.columns if c not in ("Variant", "n") and not c.endswith(
        ("_lo", "_hi"))]  # fmt: skip
    display = interval_display(table, columns, "n").drop(columns="n")
    return print_and_write({"language": (title, table, display)}, args.out, note)


def _nonactionable(args: argparse.Namespace, policy: str) -> int:
    """The five non-actionable warnings on an empty road."""
    from lantern_jax.apps import diagnostics as dg

    stage(args, f"{policy}: non-actionable warnings on an empty road")
    table = dg.nonactionable_table(policy)
    title = (
        f"Non-actionable warnings  ({policy}; empty {dg.EMPTY_ROAD_LENGTH_M:.0f} m road at "
        f"{dg.EMPTY_ROAD_SPEED_MPS:.0f} m/s, warning from t = {dg.ONSET_S:.0f} s to the end)"
    )
    note = (
        "dv_max: largest additional speed reduction vs no warning; Stop: longest standstill; "
        "non-actionable = dv_max < 2 m/s, no stop >= 1 s, RC drop <= 5 points. Each row is "
        "one execution on one road (n = 1): there is no sample to give an interval."
    )
    return print_and_write({"nonactionable": (title, table)}, args.out, note)


def _distance_suite(args: argparse.Namespace):
    """Fill the distance diagnostic's defaults, check them, and load its suite."""
    from lantern_jax.apps import diagnostics as dg

    args.suite = args.suite or SUITE_ID
    args.family = args.family or dg.DISTANCE_FAMILY
    args.routes = dg.DISTANCE_ROUTES if args.routes is None else args.routes
    args.window = dg.DISTANCE_WINDOW_S if args.window is None else args.window
    if args.routes < 1:
        raise UsageError(f"--routes must be >= 1 (got {args.routes})")
    if not (math.isfinite(args.window) and args.window > 0):
        raise UsageError(f"--window must be a finite number of seconds > 0 (got {args.window})")
    suite = load_selected_suite(args)
    available = sum(p.family == args.family for p in suite.pairs)
    if args.routes > available:
        raise UsageError(f"--routes {args.routes}: suite {suite.suite_id} has {available} "
                         f"{args.family} pairs")  # fmt: skip
    return suite


def _distance(args: argparse.Namespace, policy: str) -> int:
    """A family's warning at a near vs a far ego-frame position on Route B."""
    from lantern_jax.apps import diagnostics as dg
    from lantern_jax.report import interval_display, interval_note

    suite = _distance_suite(args)
    stage(args, f"{policy}: near vs far {args.family} warning on Route B of {suite.suite_id}")
    try:
        open_loop, closed_loop = dg.distance_table(
            policy, suite, family=args.family, routes=args.routes, window_s=args.window
        )
    except ValueError as e:
        raise UsageError(str(e)) from None
    near, far = dg.DISTANCE_POSITIONS["near"], dg.DISTANCE_POSITIONS["far"]
    summary = dg.distance_summary(open_loop)
    tables = {
        "distance": (
            f"Distance-conditioned warning  ({policy}; Route B, {args.family} template at "
            f"{near} m (near) or {far} m (far) in the ego frame from the warning point): final "
            "predicted progress (m) of the plan at the warning point",
            open_loop,
        ),
        "distance_closed_loop": (
            f"Same runs in closed loop (warning window {args.window:.1f} s)",
            closed_loop,
        ),
        "distance_summary": (
            f"Over the {len(open_loop)} routes: mean predicted progress (m) and retention",
            summary,
            interval_display(summary, dg.DISTANCE_COLUMNS, "Routes"),
        ),
    }
    note = (
        f"Retention = far / no-warning predicted progress. Summary: {interval_note(over='routes')}."
    )
    return print_and_write(tables, args.out, note)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``diagnostics`` on the command line's sub-parsers."""
    dg = sub.add_parser(
        "diagnostics",
        allow_abbrev=False,
        help="non-actionable, distance-conditioned and language-sensitivity diagnostics",
        description="nonactionable: the paper's five non-actionable warnings on an empty road "
        "(max additional speed reduction, longest stop, route completion, criterion). "
        "distance: a family's warning at a near vs a far ego-frame position on Route B "
        "(final predicted progress; closed-loop speed, stop and completion). "
        "language: the warning condition with the delivered text, another family's text at the "
        "same position, an empty text and no warning (CUS per family, share of the gain kept).",
    )
    dg.add_argument("which", choices=tuple(READS), help="which diagnostic")
    add_one_policy(dg)
    dg.add_argument(
        "--suite", metavar="ID|PATH", help=f"suite (distance, language; default: {SUITE_ID})"
    )
    dg.add_argument(
        "--pairs-per-family",
        type=count(),
        metavar="N",
        help="only the first N pairs of each family (language)",
    )
    dg.add_argument(
        "--family", choices=FAMILIES, help="family (distance; default: diagnostics.DISTANCE_FAMILY)"
    )
    dg.add_argument(
        "--routes", type=count(), metavar="N",
        help="Route B count (distance; default: diagnostics.DISTANCE_ROUTES)",
    )  # fmt: skip
    dg.add_argument(
        "--window", type=number(0.0, 60.0, low_open=True), metavar="S",
        help="warning window, s (distance; default: diagnostics.DISTANCE_WINDOW_S)",
    )  # fmt: skip
    dg.add_argument("--out", default="results/language", metavar="DIR", help="output folder")
    dg.add_argument("--quiet", action="store_true", help="no stage lines")
    dg.set_defaults(func=cmd_diagnostics, pairs=None)
