"""``lantern-jax suite``: list, verify or regenerate a suite.

::

    lantern-jax suite --list             # pairs, suite hash, generation report
    lantern-jax suite --verify           # regenerate lantern-v3 from its seed, compare hashes
    lantern-jax suite --regenerate suite.json
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import load_selected_suite, resolve_policies, stage
from lantern_jax.commands.runtime import add_cache_flag
from lantern_jax.commands.values import seed
from lantern_jax.core.constants import SUITE_ID


def suite_to_manifest(suite, suite_id: str | None = None) -> dict:
    """A suite manifest dict (the format :func:`~lantern_jax.scenarios.suite.load_suite` reads)
    of a loaded :class:`~lantern_jax.scenarios.suite.Suite` (e.g. a ``select``-ed part of one).

    Args:
        suite: the suite.
        suite_id: id stored in the manifest (default: the suite's id).
    """

    def pair(p) -> dict:
        d = dict(pair_id=p.pair_id, family=p.family, weather=p.weather, sha256=p.sha256,
                 params=p.params)  # fmt: skip
        if p.route_2m is not None:
            d["route_2m"] = p.route_2m
        return d

    return dict(
        suite_id=suite_id or suite.suite_id,
        format_version=1,
        seed=suite.seed,
        pairs=[pair(p) for p in suite.pairs],
        suite_sha256=suite.suite_sha256,
        generation_report=suite.report,
    )


def print_suite(suite) -> None:
    """Print a suite's pairs, its counts per family, hash and seed, and its generation report."""
    from tabulate import tabulate

    from lantern_jax.core import family_codes

    families = family_codes.table_codes(p.family for p in suite.pairs)  # the six, then others
    rows = [
        [
            p.pair_id,
            p.family,
            p.weather,
            f"{float(p.params.get('route_length', float('nan'))):.1f}",
            p.sha256[:12],
        ]
        for p in suite.pairs
    ]
    print(
        tabulate(
            rows,
            headers=["pair", "family", "weather", "route (m)", "sha256"],
            disable_numparse=True,
            colalign=("left", "left", "left", "right", "left"),
        )
    )
    print()
    counts = {f: sum(p.family == f for p in suite.pairs) for f in families}
    per_family = ", ".join(f"{f} {n}" for f, n in counts.items())
    print(f"suite {suite.suite_id}: {len(suite)} pairs ({per_family})")
    print(f"suite sha256: {suite.suite_sha256}")
    print(f"seed: {suite.seed}")
    _print_generation_report(suite.report or {}, families)


def _print_generation_report(rep: dict, families: Sequence[str]) -> None:
    """The expert pass rate per family before filtering and the rejects of each filter."""
    rate = rep.get("expert_pass_rate")
    if not rate:
        print("generation report: none in the manifest")
        return
    tried = rep.get("dynamic_tried", {})
    who = rep.get("validator", "expert-v1")
    print(f"generation report: expert pass rate before filtering (candidates run; "
          f"validator {who})")  # fmt: skip
    for f in families:
        if f in rate:
            print(f"  {f:<4} {100.0 * float(rate[f]):5.1f} %  ({tried.get(f, '?')})")
    for key, label in (("static_rejected", "static rejects"),
                       ("premise_rejected", "premise rejects (hazard visible)"),
                       ("near_duplicate_rejected", "near-duplicate rejects")):  # fmt: skip
        counts = rep.get(key)
        if counts:
            print(f"  {label}: " + ", ".join(f"{f} {counts.get(f, 0)}" for f in families))


def _check_regenerate_path(path: str) -> None:
    """Refuse a ``--regenerate`` path that is no file to write, before generating."""
    where = os.path.dirname(os.path.abspath(path))
    if not path.strip() or os.path.isdir(path):
        raise UsageError(f"--regenerate {path!r}: give the path of a file to write")
    if os.path.exists(where) and not os.path.isdir(where):
        raise UsageError(f"--regenerate {path}: {where} is a file, not a folder")


def _regenerate(args: argparse.Namespace) -> tuple[int, dict]:
    """Generate a fresh manifest into ``--regenerate``; returns the exit code and the
    manifest."""
    from lantern_jax.apps.suite_generation import DEFAULT_SEED, generate_suite, suite_validator
    from lantern_jax.scenarios.suite import write_manifest

    seed = DEFAULT_SEED if args.seed is None else args.seed
    validator = args.validator or suite_validator(load_selected_suite(args).report)
    resolve_policies([validator])
    stage(args, f"generating a suite from seed {seed} (runs {validator} on every candidate)")
    manifest = generate_suite(seed, progress=not args.quiet, validator=validator)
    try:
        write_manifest(manifest, args.regenerate)
    except OSError as e:
        print(f"lantern-jax suite: error: cannot write {args.regenerate}: {e}", file=sys.stderr)
        return 1, manifest
    print(f"wrote {args.regenerate}: {len(manifest['pairs'])} pairs, "
          f"suite sha256 {manifest['suite_sha256']}")  # fmt: skip
    return 0, manifest


def cmd_suite(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax suite``: list, verify or regenerate a suite."""
    del argv
    from lantern_jax.apps.suite_generation import (
        DEFAULT_SEED,
        regenerates_suite,
        suite_validator,
        verify_regeneration,
    )

    if args.regenerate is not None:
        _check_regenerate_path(args.regenerate)
    if args.list or not (args.verify or args.regenerate):
        print_suite(load_selected_suite(args))
    fresh = None
    if args.regenerate:
        rc, fresh = _regenerate(args)
        if rc:
            return rc
    if args.verify:
        suite = load_selected_suite(args)  # hash check of the manifest itself
        seed = DEFAULT_SEED if args.seed is None else args.seed
        validator = args.validator or suite_validator(suite.report)
        if fresh is not None and regenerates_suite(args.suite, seed, validator):
            stage(args, f"comparing the manifest just generated with {args.suite}")
        else:  # nothing generated, or another seed or validator: generate the suite's own
            fresh = None
            stage(args, f"regenerating {args.suite} from its seed and comparing hashes")
        ok, msg = verify_regeneration(args.suite, fresh)
        print(f"{'OK' if ok else 'MISMATCH'}: {args.suite}: {msg}")
        return 0 if ok else 1
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``suite`` on the command line's sub-parsers."""
    su = sub.add_parser(
        "suite",
        allow_abbrev=False,
        help="list, verify or regenerate a suite",
        description="Inspect a suite manifest (default: list its pairs), check that it "
        "regenerates from its seed, or generate a fresh manifest.",
    )
    su.add_argument("--list", action="store_true", help="list pairs, hash and generation report")
    su.add_argument(
        "--verify", action="store_true", help="regenerate from the seed and compare every hash"
    )
    su.add_argument("--regenerate", metavar="PATH", help="write a freshly generated manifest")
    su.add_argument("--seed", type=seed(), help="generation seed for --regenerate")
    su.add_argument(
        "--validator",
        metavar="POLICY",
        help="policy of the dynamic validation for --regenerate (default: the one that "
        "filtered --suite, as its manifest records; expert-v1 for lantern-v3)",
    )
    su.add_argument(
        "--suite", default=SUITE_ID, metavar="ID|PATH", help="suite id or manifest path"
    )
    su.add_argument("--quiet", action="store_true", help="no stage lines")
    add_cache_flag(su)
    su.set_defaults(func=cmd_suite)
