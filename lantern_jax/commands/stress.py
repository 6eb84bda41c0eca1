"""``lantern-jax stress``: search a family's scenario knobs for the hazards that break a policy.

::

    lantern-jax stress --policy coop --family PE --budget-s 60 --out runs/stress_pe

runs gradient search, random search and CMA-ES at equal wall-clock budget on one pair of the
suite (default: the family's first pair), prints the comparison table and writes
``comparison.csv``, ``found.csv``, ``found_suite.json`` (runnable with ``lantern-jax evaluate
--suite``) and ``convergence.png`` (see :mod:`lantern_jax.stress.report`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out, write_failed
from lantern_jax.constants import CONDITIONS


def _ranges(items: Sequence[str] | None) -> dict[str, tuple[float, float]]:
    out = {}
    for item in items or []:
        name, sep, span = item.partition("=")
        lo, sep2, hi = span.partition(":")
        try:
            if not (sep and sep2):
                raise ValueError
            out[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise UsageError(f"--range {item!r}: expected KNOB=LO:HI") from None
        if not (math.isfinite(out[name.strip()][0]) and math.isfinite(out[name.strip()][1])):
            raise UsageError(f"--range {item!r}: LO and HI must be finite numbers")
    return out


def _check_numbers(args: argparse.Namespace, methods: tuple[str, ...]) -> None:
    """Refuse search settings that cannot run, before anything is compiled."""
    least_samples = 2 if "cmaes" in methods else 1  # CMA-ES needs a population of two
    checks = (
        ("--budget-s", args.budget_s, math.isfinite(args.budget_s) and args.budget_s > 0,
         "a finite number of seconds > 0"),
        ("--restarts", args.restarts, args.restarts >= 1, "a whole number >= 1"),
        ("--samples", args.samples, args.samples >= least_samples,
         f"a whole number >= {least_samples}" + (" (CMA-ES's population)" if
                                                 least_samples == 2 else "")),
        ("--sigma", args.sigma, math.isfinite(args.sigma) and args.sigma >= 0,
         "a finite number >= 0"),
        ("--temperature", args.temperature,
         math.isfinite(args.temperature) and args.temperature > 0, "a finite number > 0"),
    )  # fmt: skip
    for flag, value, ok, want in checks:
        if not ok:
            raise UsageError(f"{flag}: must be {want}, got {value:g}")


def cmd_stress(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the stress test and write its files; returns the exit code."""
    del argv
    from tabulate import tabulate

    from lantern_jax.constants import FAMILIES
    from lantern_jax.report import interval_note
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.stress import report, search
    from lantern_jax.viz.stress import convergence_plot

    if args.family not in FAMILIES:
        raise UsageError(f"--family {args.family!r}: not one of {', '.join(FAMILIES)}")
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    bad = [m for m in methods if m not in search.METHODS]
    if bad or not methods:
        raise UsageError(f"--methods: {bad or 'none'}; valid: {', '.join(search.METHODS)}")
    _check_numbers(args, methods)
    ranges = _ranges(args.range)
    check_out(args.out)
    try:
        suite = load_suite(args.suite) if args.suite else load_suite()
    except (OSError, ValueError) as e:
        raise UsageError(str(e)) from None
    pairs = [p for p in suite.pairs if p.family == args.family]
    if args.pair:
        pairs = [p for p in pairs if p.pair_id == args.pair]
        if not pairs:
            raise UsageError(f"--pair {args.pair!r}: no {args.family} pair of that id")
    knobs = tuple(k.strip() for k in args.knobs.split(",") if k.strip()) if args.knobs else None
    cfg = report.StressConfig(
        budget_s=args.budget_s, restarts=args.restarts, samples=args.samples,
        sigma=args.sigma, temperature=args.temperature, objective=args.objective,
        condition=args.condition, seed=args.seed, methods=methods,
    )  # fmt: skip
    try:
        _, traces = report.stress_test(pairs[0], args.policy, cfg, suite, knobs, ranges,
                                       progress=not args.quiet)  # fmt: skip
    except (ValueError, KeyError) as e:
        raise UsageError(str(e).strip("'\"")) from None
    from lantern_jax.stress.space import search_space

    space = search_space(args.family, knobs, ranges)
    title = f"{pairs[0].pair_id} ({args.family}), {args.policy}, {args.condition}, {args.objective}"
    fig = convergence_plot(traces, title)
    try:
        files = report.write_results(args.out, pairs[0], space, traces, fig)
    except OSError as e:
        return write_failed(args.out, e)
    table = report.comparison_table(traces)
    print(f"Stress test  ({title}; {args.budget_s:g} s per method, {args.restarts} restarts)")
    print(tabulate(table, headers="keys", showindex=False, floatfmt=".2f"))
    print(f"failure_rate_lo, _hi: {interval_note(over='restarts')}")
    print(f"Wrote {len(files)} files to {args.out}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``stress`` on the command line's sub-parsers."""
    st = sub.add_parser(
        "stress",
        help="search scenario knobs for failures (gradient vs random search vs CMA-ES)",
        description=__doc__.splitlines()[0],
        allow_abbrev=False,
    )
    st.add_argument("--policy", default="coop", metavar="NAME", help="policy under test")
    st.add_argument("--family", required=True, metavar="F", help="PE, VC, OR, LWW, RWW or RTY")
    st.add_argument("--budget-s", type=float, default=60.0, metavar="S",
                    help="wall-clock seconds per method, compilation excluded")  # fmt: skip
    st.add_argument("--out", default="results/stress", metavar="DIR", help="output folder")
    st.add_argument("--suite", default=None, metavar="ID|PATH", help="suite (default built-in)")
    st.add_argument("--pair", metavar="ID", help="pair to stress (default: the family's first)")
    st.add_argument("--knobs", metavar="K[,K...]", help="knobs to search (default: all)")
    st.add_argument("--range", action="append", metavar="KNOB=LO:HI",
                    help="narrow a knob's range (may be repeated)")  # fmt: skip
    st.add_argument("--restarts", type=int, default=8, metavar="R")
    st.add_argument("--samples", type=int, default=8, metavar="M",
                    help="perturbations per gradient step / CMA-ES population")  # fmt: skip
    st.add_argument("--sigma", type=float, default=0.3, help="gradient smoothing scale")
    st.add_argument("--temperature", type=float, default=0.1, help="soft-score temperature")
    st.add_argument("--objective", default="clearance", choices=("clearance", "margin", "soft_cus"))
    st.add_argument("--condition", default=CONDITIONS[0], choices=CONDITIONS)
    st.add_argument("--methods", default="gradient,random,cmaes", metavar="M[,M...]")
    st.add_argument("--seed", type=int, default=0)
    st.add_argument("--quiet", action="store_true", help="no progress lines")
    st.set_defaults(func=cmd_stress)
