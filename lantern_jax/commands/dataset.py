"""``lantern-jax dataset``: record the open-loop training dataset.

::

    lantern-jax dataset --out data/lantern              # the paper-scale default
    lantern-jax dataset --out data/lantern --sequences 3360   # the shipped models' data
    lantern-jax dataset --out /tmp/small --sequences 120 --seed 1

Expert rollouts on fresh Route A and Route B scenes of every family (disjoint from the frozen
suite), recorded at 4 Hz with both perception formats, ten expert waypoints per frame and the
event timeline, written as sharded Parquet with a dataset card (see
:mod:`lantern_jax.apps.dataset`).  Re-running the same command on the same folder resumes an
interrupted generation.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out
from lantern_jax.commands.values import count, seed


def cmd_dataset(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Generate (or resume) the dataset and print its card summary."""
    del argv
    from lantern_jax.apps.dataset.generation import generate_dataset
    from lantern_jax.apps.dataset.scenes import PAIRS_PER_FAMILY, PLAN_JSON
    from lantern_jax.apps.dataset.store import CARD_JSON, CARD_MD, DatasetError, card_markdown
    from lantern_jax.core.constants import FAMILIES

    check_out(args.out, in_place=True, owned=(PLAN_JSON, CARD_JSON, CARD_MD))
    if args.sequences is not None:
        if args.sequences < 2 * len(FAMILIES):
            raise UsageError(f"--sequences: at least {2 * len(FAMILIES)} (one Route A and one "
                             f"Route B per family), got {args.sequences}")  # fmt: skip
        pairs = -(-args.sequences // (2 * len(FAMILIES)))
    else:
        pairs = PAIRS_PER_FAMILY
    try:
        card = generate_dataset(args.out, pairs_per_family=pairs, seed=args.seed,
                                progress=not args.quiet)  # fmt: skip
    except DatasetError as e:
        raise UsageError(str(e)) from None
    print(card_markdown(card))
    plan = card.get("plan_seconds")
    planned = f"planning {plan:.0f} s (once, kept in plan.json), " if plan is not None else ""
    print(f"Generation time: {planned}recording {card['seconds']:.0f} s; files in {args.out}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``dataset`` on the command line's sub-parsers."""
    from lantern_jax.core.constants import DATASET_SEED, PAIRS_PER_FAMILY  # no JAX at start-up

    ds = sub.add_parser(
        "dataset",
        help="record the open-loop training dataset (expert rollouts at 4 Hz)",
        description=__doc__.splitlines()[0],
        allow_abbrev=False,
    )
    ds.add_argument("--out", required=True, metavar="DIR", help="dataset folder (resumable)")
    ds.add_argument("--sequences", type=count(), metavar="N",
                    help="about N sequences (Route A + Route B: N/12 candidate pairs per "
                         f"family) instead of the default {PAIRS_PER_FAMILY} pairs per family, "
                         "sized to reach the paper's 236,309 frames")  # fmt: skip
    ds.add_argument("--seed", type=seed(), default=DATASET_SEED, help="generation seed")
    ds.add_argument("--quiet", action="store_true", help="no progress bar")
    ds.set_defaults(func=cmd_dataset)
