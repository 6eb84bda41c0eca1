"""``lantern-jax plot``: one pair's executions recorded again and drawn: the bird's-eye view at
the most telling tick beside the timeline of both Route A conditions, collisions, the first
failed gate, warning on/off, event onset and clearance marked
(:func:`lantern_jax.viz.pair.plot_pair`)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import (
    add_one_policy,
    check_out,
    list_written,
    one_policy,
    stage,
    write_failed,
)
from lantern_jax.core.constants import SUITE_ID

#: Executions ``--condition`` may name (:data:`lantern_jax.viz.pair.EXECUTIONS`).
CONDITION_CHOICES = ("warning", "no-warning", "route-b")
DEFAULT_OUT = "plots"


def cmd_plot(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax plot``: record one pair's executions for one policy and write the figure
    (and with ``--animate`` the animation) into ``--out``."""
    del argv
    name = one_policy(args)
    from lantern_jax.scenarios.suite import SuiteError, load_suite
    from lantern_jax.viz.pair import figure_stem, plot_pair

    stem = figure_stem(args.pair, name, args.condition)
    check_out(args.out, in_place=True, owned=(f"{stem}.png", f"{stem}.gif"))

    try:
        suite = load_suite(args.suite)
    except (FileNotFoundError, SuiteError) as e:
        raise UsageError(f"--suite: {str(e).strip(chr(39) + chr(34))}") from None
    stage(args, f"recording {args.pair} under {name} (compiles once per policy)")
    try:
        _, paths = plot_pair(name, pair_id=args.pair, condition=args.condition, out=args.out,
                             animate=args.animate, suite=suite)  # fmt: skip
    except ValueError as e:
        raise UsageError(f"--pair / --condition: {e}") from None
    except OSError as e:
        return write_failed(args.out, e)
    list_written(paths)
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``plot`` on the command line's sub-parsers."""
    pl = sub.add_parser(
        "plot",
        help="draw one pair's execution: bird's-eye view and timeline, collisions marked",
        description="Record one pair's three executions (Route A with and without the warning, "
        "Route B) for one policy and draw the chosen one's bird's-eye view at its most telling "
        "tick (first collision, else least clearance) beside the timeline of both Route A "
        "conditions, with collisions, the first failed gate, the warning's delivery, event "
        "onset and clearance marked.",
        allow_abbrev=False,
    )
    add_one_policy(pl)
    pl.add_argument("--pair", required=True, metavar="ID", help="pair id, e.g. pe_0001")
    pl.add_argument("--condition", choices=CONDITION_CHOICES, default="warning",
                    help="the execution of the bird's-eye view (default: warning)")  # fmt: skip
    pl.add_argument(
        "--suite",
        default=SUITE_ID,
        metavar="ID|PATH",
        help=f"suite id or path (default: {SUITE_ID})",
    )
    pl.add_argument(
        "--out", default=DEFAULT_OUT, metavar="DIR", help=f"output folder (default: {DEFAULT_OUT})"
    )
    pl.add_argument("--animate", action="store_true", help="also write the animation (GIF)")
    pl.add_argument("--quiet", action="store_true", help="no stage lines")
    pl.set_defaults(func=cmd_plot)
