"""``lantern-jax stress``: search a scenario for the hazards that break a policy.

::

    lantern-jax stress --policy coop --family PE --budget-s 60 --out runs/stress_pe
    lantern-jax stress --policy coop --family PE --space adversary --actors hazard,background \\
        --knots 16 --budget-rollouts 128 --out runs/stress_pe_adv

runs gradient search, random search and CMA-ES interleaved at equal budget (seconds per
method and/or rollouts per restart) on one pair of the suite (default: the family's first pair),
in the family's knobs (``--space knobs``), in adversarial tracks of its actors
(``--space adversary``) or in both; prints a ``compiling`` line, the comparison table and the
failure catalogue, and writes ``comparison.csv``, ``found.csv``, ``found_suite.json``, the
catalogue (``catalogue.csv``, ``catalogue_suite.json`` — runnable with ``lantern-jax evaluate
--suite`` — and ``catalogue.png``) and ``convergence.png`` (see
:mod:`lantern_jax.apps.stress.report`).

::

    lantern-jax stress --fragility --policy learned-closed-loop --sampling 16 --out runs/frag

runs no search: every pair's fragility radius (the first-order distance to a collision over its
family's normalised knobs) from one vmapped backward pass, verified by hard rollouts along the
predicted direction (:mod:`lantern_jax.apps.stress.fragility`); writes ``fragility.csv``,
``fragility_probes.csv``, ``fragility_families.csv``, ``fragility_sampling.csv`` (with
``--sampling``), ``fragility_suite.json`` and ``fragility.png``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import check_out, files_count, write_failed
from lantern_jax.commands.values import count, number, seed, whole
from lantern_jax.core.constants import (
    CONDITIONS,
    KNOT_S_RANGE,
    MAX_BACKGROUND,
    MAX_KNOTS,
    MAX_VERIFY_S,
)

#: Options only a knob space reads, and options only an adversary space reads (None = not given).
KNOB_OPTIONS = ("knobs", "range")
ADVERSARY_OPTIONS = ("actors", "knots", "knot_s", "background")


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
    popsize_from_samples = "cmaes" in methods and args.space == "knobs" and not args.popsize
    least_samples = 2 if popsize_from_samples else 1  # CMA-ES needs a population of two
    checks = [
        (
            "--budget-s",
            args.budget_s,
            math.isfinite(args.budget_s) and args.budget_s > 0,
            "a finite number of seconds > 0",
        ),
        ("--restarts", args.restarts, args.restarts >= 1, "a whole number >= 1"),
        ("--hybrid-draws", args.hybrid_draws, args.hybrid_draws >= 1, "a whole number >= 1"),
        ("--hybrid-steps", args.hybrid_steps, args.hybrid_steps >= 1, "a whole number >= 1"),
        (
            "--sigma",
            args.sigma,
            args.sigma is None or (math.isfinite(args.sigma) and args.sigma >= 0),
            "a finite number >= 0",
        ),
        (
            "--temperature",
            args.temperature,
            math.isfinite(args.temperature) and args.temperature > 0,
            "a finite number > 0",
        ),
        (
            "--popsize",
            args.popsize,
            args.popsize == 0 or args.popsize >= 2,
            "0 (cma's default) or a whole number >= 2",
        ),
    ]
    if args.expert_weight is not None:
        checks.append(
            (
                "--expert-weight",
                args.expert_weight,
                math.isfinite(args.expert_weight) and args.expert_weight >= 0,
                "a finite number >= 0",
            )
        )
    if args.samples is not None:
        checks.append(
            (
                "--samples",
                args.samples,
                args.samples >= least_samples,
                f"a whole number >= {least_samples}"
                + (" (CMA-ES's population)" if least_samples == 2 else ""),
            )
        )
    if args.budget_rollouts is not None:
        checks.append(
            (
                "--budget-rollouts",
                args.budget_rollouts,
                args.budget_rollouts >= 1,
                "a whole number >= 1",
            )
        )
    if args.lr is not None:
        checks.append(
            ("--lr", args.lr, math.isfinite(args.lr) and args.lr > 0, "a finite number > 0")
        )
    if args.horizon_s is not None:
        checks.append(
            (
                "--horizon-s",
                args.horizon_s,
                math.isfinite(args.horizon_s) and args.horizon_s > 0,
                "a finite number of seconds > 0",
            )
        )
    for flag, value, ok, want in checks:
        if not ok:
            raise UsageError(f"{flag}: must be {want}, got {value:g}")


def _check_space_options(args: argparse.Namespace) -> None:
    """Options the chosen space does not read are refused."""
    unread = ADVERSARY_OPTIONS if args.space == "knobs" else ()
    unread += KNOB_OPTIONS if args.space == "adversary" else ()
    given = [f"--{k.replace('_', '-')}" for k in unread if getattr(args, k) is not None]
    if given:
        raise UsageError(
            f"{', '.join(given)}: --space {args.space} does not read "
            f"{'it' if len(given) == 1 else 'them'}"
        )


def _config(args: argparse.Namespace, methods: tuple[str, ...]):
    """The :class:`~lantern_jax.apps.stress.report.StressConfig` of the command's options (None for
    an option not given: the space's default)."""
    from lantern_jax.apps.stress import report

    actors = tuple(a.strip() for a in (args.actors or "hazard").split(",") if a.strip())
    given = {
        k: getattr(args, k)
        for k in ("budget_rollouts", "knots", "knot_s", "background", "expert_weight")
        if getattr(args, k) is not None
    }
    return report.StressConfig(
        budget_s=args.budget_s,
        restarts=args.restarts,
        samples=args.samples,
        popsize=args.popsize,
        sigma=args.sigma,
        lr=args.lr,
        temperature=args.temperature,
        objective=args.objective,
        condition=args.condition,
        seed=args.seed,
        methods=methods,
        hybrid_draws=args.hybrid_draws,
        hybrid_steps=args.hybrid_steps,
        space=args.space,
        actors=actors,
        horizon_s=args.horizon_s,
        watch=args.watch,
        actor_temperature=args.actor_temperature,
        **given,
    )


def _print_summary(args: argparse.Namespace, table, problem, title: str, files: dict) -> None:
    """Print the comparison table, its interval note and the head of the failure catalogue."""
    from tabulate import tabulate

    from lantern_jax.apps.stress import report
    from lantern_jax.report import MISSING, interval_note, missing_shown

    budget = f"{args.budget_s:g} s per method"
    if args.budget_rollouts is not None:
        budget += f", {args.budget_rollouts} rollouts per restart"
    print(f"Stress test  ({title}; {budget}, {args.restarts} restarts)")
    if problem is not None and problem.info:
        print(f"compile {problem.info['compile_s']:.1f} s (apart from the search times below)")
    shown = [c for c in report.SUMMARY_COLUMNS if c in table]
    print(tabulate(missing_shown(table[shown]), headers="keys", showindex=False, floatfmt=".2f",
                   missingval=MISSING))  # fmt: skip
    print(f"failure_rate_lo, _hi: {interval_note(over='restarts')}")
    cat = args.out.rstrip("/") + "/catalogue.csv"
    if "catalogue.csv" in {p.name for p in files.values()}:
        import pandas as pd

        entries = pd.read_csv(cat)
        print(f"Failure catalogue: {len(entries)} distinct failures")
        for _, e in entries.head(10).iterrows():
            print(f"  {e['pair_id']} ({e['method']}): CUS {e['hard_cus']:.1f}; {e['description']}")


def cmd_stress(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the stress test and write its files; returns the exit code."""
    del argv

    from lantern_jax.apps.stress import report, search
    from lantern_jax.commands.common import resolve_policies
    from lantern_jax.core.constants import FAMILIES
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.viz.stress import catalogue_figure, convergence_plot

    policies = resolve_policies([args.policy])  # a registered name, or file.py:NAME
    if len(policies) != 1:
        raise UsageError(f"--policy: give one policy, got {', '.join(policies)}")
    args.policy = policies[0]
    if args.fragility:
        return _cmd_fragility(args)
    if args.sampling is not None:
        raise UsageError("--sampling: only --fragility reads it")
    if args.family is None:
        raise UsageError("--family is required (or --fragility: every pair of the suite)")
    if args.family not in FAMILIES:
        raise UsageError(f"--family {args.family!r}: not one of {', '.join(FAMILIES)}")
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    bad = [m for m in methods if m not in search.ALL_METHODS]
    if bad or not methods:
        raise UsageError(f"--methods: {bad or 'none'}; valid: {', '.join(search.ALL_METHODS)}")
    _check_numbers(args, methods)
    _check_space_options(args)
    ranges = _ranges(args.range)
    from lantern_jax.apps.stress.report import RESULT_FILES

    check_out(args.out, owned=RESULT_FILES)
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
    cfg = _config(args, methods)
    try:
        problem, traces = report.stress_test(
            pairs[0], args.policy, cfg, suite, knobs, ranges, progress=not args.quiet
        )
    except (ValueError, KeyError) as e:
        raise UsageError(str(e).strip("'\"")) from None
    space = problem.space if problem is not None else None
    title = f"{pairs[0].pair_id} ({args.family}), {args.policy}, {args.condition}, {args.space}"
    fig = convergence_plot(traces, title)

    def views(entries):
        return catalogue_figure(problem, entries)

    try:
        files = report.write_results(
            args.out,
            pairs[0],
            space,
            traces,
            fig,
            problem,
            args.policy,
            views if problem is not None else None,
        )
    except OSError as e:
        return write_failed(args.out, e)
    _print_summary(args, report.comparison_table(traces, problem), problem, title, files)
    print(f"Wrote {files_count(len(files))} to {args.out}")
    return 0


#: Search options --fragility does not read (refused when given with another value).
SEARCH_ONLY = ("space", "budget_s", "budget_rollouts", "knobs", "range", "restarts", "samples",
               "popsize", "sigma", "lr", "objective", "expert_weight", "horizon_s", "methods",
               "hybrid_draws", "hybrid_steps", "watch", *ADVERSARY_OPTIONS)  # fmt: skip


def _cmd_fragility(args: argparse.Namespace) -> int:
    """``stress --fragility``: the fragility radius of every pair (of ``--family``), verified."""
    from lantern_jax.apps.stress import fragility as frag
    from lantern_jax.core.constants import FAMILIES
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.viz.fragility import fragility_figure

    given = [f"--{k.replace('_', '-')}" for k in SEARCH_ONLY
             if getattr(args, k) != args.search_defaults[k]]  # fmt: skip
    if given:
        raise UsageError(f"{', '.join(given)}: --fragility does not read "
                         f"{'it' if len(given) == 1 else 'them'} (it runs no search)")  # fmt: skip
    if args.family is not None and args.family not in FAMILIES:
        raise UsageError(f"--family {args.family!r}: not one of {', '.join(FAMILIES)}")
    check_out(args.out, owned=frag.FRAGILITY_FILES)
    try:
        suite = load_suite(args.suite) if args.suite else load_suite()
    except (OSError, ValueError) as e:
        raise UsageError(str(e)) from None
    ids = [p.pair_id for p in suite.pairs
           if (args.family is None or p.family == args.family)
           and (args.pair is None or p.pair_id == args.pair)]  # fmt: skip
    if not ids:
        raise UsageError(f"--pair/--family: no pair of {suite.suite_id} matches")
    try:
        result = frag.fragility(suite.select(ids), args.policy, args.condition,
                                args.temperature, progress=not args.quiet,
                                sampling=args.sampling or 0, seed=args.seed)  # fmt: skip
    except (ValueError, KeyError) as e:
        raise UsageError(str(e).strip("'\"")) from None
    title = f"{args.policy}, {args.condition}, {suite.suite_id} ({len(ids)} pairs)"
    try:
        files = frag.write_fragility(args.out, result, fragility_figure(result.table, title))
    except OSError as e:
        return write_failed(args.out, e)
    cols = ["family", "pairs", "median_radius", "bounded_radius", "bounded_radius_lo",
            "bounded_radius_hi", "fails_on_line", "within_2r", "within_2r_lo", "within_2r_hi",
            "within_2r_n"]  # fmt: skip
    fmt = lambda v: f"{v:.3f}"  # noqa: E731
    print(result.families[cols].to_string(index=False, float_format=fmt))
    if result.sampling is not None:
        print("\nRank correlation of the radius with the failure rate of draws around each pair:")
        print(result.sampling.to_string(index=False, float_format=fmt))
    print(f"Wrote {files_count(len(files))} to {args.out}")
    return 0


def _add_adversary_options(st: argparse.ArgumentParser) -> None:
    """The options only an adversary space reads (:data:`ADVERSARY_OPTIONS`)."""
    st.add_argument(
        "--actors",
        default=None,
        metavar="G[,G...]",
        help="adversary: actors with tracks, hazard and/or background (default: hazard)",
    )
    st.add_argument(
        "--knots",
        type=count(MAX_KNOTS),
        default=None,
        metavar="N",
        help="adversary: knots per track, 2 N dimensions per actor (default 16)",
    )
    st.add_argument(
        "--knot-s",
        type=number(*KNOT_S_RANGE),
        default=None,
        metavar="S",
        help="adversary: seconds per knot (default 0.5)",
    )
    st.add_argument(
        "--background",
        type=count(MAX_BACKGROUND),
        default=None,
        metavar="N",
        help="adversary: background vehicles nearest the route (default 1)",
    )


def _add_method_options(st: argparse.ArgumentParser) -> None:
    """The options of the search methods: draws, CMA-ES, Adam, the surrogate, the methods
    compared and the hybrid's cycle."""
    st.add_argument(
        "--samples",
        type=count(4096),
        default=None,
        metavar="M",
        help="random draws per restart and iteration; gradient perturbations with "
        "--sigma > 0 (default: 8 knobs, 1 adversary)",
    )
    st.add_argument(
        "--popsize",
        type=whole(0, 4096),
        default=0,
        metavar="P",
        help="CMA-ES population per restart (default: --samples for knobs, cma's "
        "4 + 3 ln K otherwise)",
    )
    st.add_argument(
        "--sigma",
        type=number(0.0, 10.0),
        default=None,
        help="gradient smoothing scale (default: 0.3 knobs, 0 adversary)",
    )
    st.add_argument("--lr", type=number(0.0, 10.0, low_open=True), default=None,
                    help="Adam step size (default: 0.3 knobs, 0.2 adversary)")  # fmt: skip
    st.add_argument("--temperature", type=number(0.0, 10.0, low_open=True), default=0.1,
                    help="soft-score temperature")  # fmt: skip
    st.add_argument(
        "--objective",
        default="plausible",
        choices=("plausible", "margin", "clearance", "soft_cus"),
        help="what the gradient and CMA-ES minimise (docs/stress.md)",
    )
    st.add_argument("--actor-temperature", type=number(0.0, 100.0, low_open=True), default=None,
                    metavar="M", help="temperature (m) of the surrogate's soft minimum over the "
                    "watched actors (default: --temperature, in effect the nearest actor's "
                    "margin; docs/stress.md)")  # fmt: skip
    st.add_argument("--watch", default="hazard", choices=("hazard", "all"),
                    help="the actors the surrogate's margin and the verification watch: the "
                    "hazard and the tracked ones, or every actor of the scene (docs/stress.md)")
    st.add_argument(
        "--expert-weight",
        type=number(0.0, 1000.0),
        default=None,
        help="weight of the expert's margin in the surrogate (0: none; default 2)",
    )
    st.add_argument(
        "--horizon-s",
        type=number(0.0, MAX_VERIFY_S, low_open=True),
        default=None,
        help="seconds of soft rollout (default: from the pair)",
    )
    st.add_argument("--condition", default=CONDITIONS[0], choices=CONDITIONS,
                    help="the Route A execution searched")  # fmt: skip
    st.add_argument("--methods", default="gradient,random,cmaes", metavar="M[,M...]",
                    help="search methods compared, of gradient, random, cmaes, hybrid "
                    "(draws, then descent from the best) and king (KING's recipe): "
                    "docs/stress.md")  # fmt: skip
    st.add_argument("--hybrid-draws", type=count(4096), default=8, metavar="N",
                    help="hybrid: uniform draws per restart before each descent")  # fmt: skip
    st.add_argument("--hybrid-steps", type=count(4096), default=8, metavar="N",
                    help="hybrid: Adam steps per descent")  # fmt: skip


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``stress`` on the command line's sub-parsers."""
    st = sub.add_parser(
        "stress",
        help="search a scenario for failures (gradient vs random search vs CMA-ES)",
        description=__doc__.splitlines()[0],
        allow_abbrev=False,
    )
    st.add_argument("--policy", default="coop", metavar="NAME", help="policy under test")
    st.add_argument("--family", default=None, metavar="F",
                    help="PE, VC, OR, LWW, RWW or RTY (required, except with --fragility: "
                    "then the pairs of that family only)")  # fmt: skip
    st.add_argument("--fragility", action="store_true",
                    help="no search: every pair's fragility radius from one backward pass, "
                    "verified by hard rollouts (reads --policy, --suite, --family, --pair, "
                    "--condition, --temperature, --sampling, --seed, --out, --quiet)")  # fmt: skip
    st.add_argument("--sampling", type=count(4096), default=None, metavar="N",
                    help="--fragility: also N uniform draws around every pair, and the rank "
                    "correlation of the radius with their failure rate (default: none)")
    st.add_argument(
        "--space",
        default="knobs",
        choices=("knobs", "adversary", "both"),
        help="what is searched: the family's knobs, adversarial actor tracks, or both",
    )
    st.add_argument(
        "--budget-s",
        type=number(0.0, 10.0**6, low_open=True),
        default=60.0,
        metavar="S",
        help="wall-clock seconds per method, compilation excluded",
    )
    st.add_argument(
        "--budget-rollouts",
        type=count(),
        default=None,
        metavar="N",
        help="rollouts per restart and method, every kind counted (default: none)",
    )
    st.add_argument("--out", default="results/stress", metavar="DIR", help="output folder")
    st.add_argument("--suite", default=None, metavar="ID|PATH", help="suite (default built-in)")
    st.add_argument("--pair", metavar="ID", help="pair to stress (default: the family's first)")
    st.add_argument("--knobs", metavar="K[,K...]", help="knobs to search (default: all)")
    st.add_argument(
        "--range",
        action="append",
        metavar="KNOB=LO:HI",
        help="narrow a knob's range (may be repeated)",
    )
    _add_adversary_options(st)
    st.add_argument("--restarts", type=count(4096), default=8, metavar="R",
                    help="independent restarts of every method")  # fmt: skip
    _add_method_options(st)
    st.add_argument("--seed", type=seed(), default=0, help="seed of every method's restarts")
    st.add_argument("--quiet", action="store_true", help="no progress lines")
    # what --fragility compares the search options with (a value other than these was given)
    st.set_defaults(func=cmd_stress,
                    search_defaults={k: st.get_default(k) for k in SEARCH_ONLY})  # fmt: skip
