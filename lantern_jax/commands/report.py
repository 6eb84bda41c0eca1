"""``lantern-jax report``: one HTML page of one or more result folders, to look at rather than
read (:mod:`lantern_jax.report.page`).

::

    lantern-jax report results --out report.html                 # tables, plots, failures
    lantern-jax report results --out report.html --figures       # + every failure's figure
    lantern-jax report runs/before runs/after --out diff.html    # two runs side by side

The page is built from the folders alone (each checked against its manifest); ``--figures``
records every failing pair again (:func:`lantern_jax.viz.pair.record_pair`, once per pair and
policy) and keeps its figure in ``<out>_files/``, where a later report finds it instead of
recording it again.
"""

from __future__ import annotations

import argparse
import collections
import sys
from collections.abc import Sequence
from pathlib import Path

from lantern_jax.commands import UsageError
from lantern_jax.commands.common import stage

#: recordings of pairs kept in memory while the gallery's figures are drawn (the rest are dropped)
KEPT_RECORDINGS = 8


def _figure_maker(sets, quiet: bool):
    """The ``figures`` function of :func:`~lantern_jax.report.page.build_report`: a failing
    execution's figure, recorded once per pair and policy, kept in the report's folder."""
    from lantern_jax.policies.registry import get_policy, register_policy_source
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.viz.common import save_figure
    from lantern_jax.viz.pair import pair_figure, record_pair, safe_name

    owner = {}  # policy name -> the result set that holds it (its suite and ablation)
    for rs in sets:
        for model in dict.fromkeys(rs.table["model"]):
            owner.setdefault(model, rs)
    # the pair's recordings drawn last, for its other failing executions: a few are kept (each
    # holds every tick of three executions), the oldest dropped and recorded again if needed
    recordings: collections.OrderedDict[tuple, object] = collections.OrderedDict()

    def make(model: str, pair_id: str, condition: str, folder: Path) -> Path:
        png = folder / f"{safe_name(pair_id)}_{safe_name(model)}_{condition}.png"
        if png.is_file():  # drawn by an earlier report: kept, not recorded again
            return png
        rs = owner[model]
        spec = _source_spec(rs, model)
        name = register_policy_source(spec) if spec else model
        key = (model, pair_id)
        if key not in recordings:
            if not quiet:
                print(f"[lantern-jax] recording {pair_id} under {model}", file=sys.stderr)
            suite = load_suite(rs.manifest.get("suite_id"))
            recordings[key] = record_pair(get_policy(name), pair_id, suite,
                                          ablation=rs.manifest.get("ablation", "none"))  # fmt: skip
            while len(recordings) > KEPT_RECORDINGS:
                recordings.popitem(last=False)
        recordings.move_to_end(key)
        return save_figure(pair_figure(recordings[key], condition), png)

    return make


def _source_spec(rs, model: str) -> str | None:
    """The ``file.py:NAME`` a policy of the result set came from (its run record), if any."""
    import json

    record = rs.folder / "run_record.json"
    try:
        runs = json.loads(record.read_text()).get("policies", [])
    except (OSError, ValueError):
        return None
    for run in runs:
        if run.get("name") == model and run.get("source_spec"):
            return run["source_spec"]
    return None


def cmd_report(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Write the report; returns the exit code."""
    del argv
    from lantern_jax.report.evidence import ResultSetError, read_result_set
    from lantern_jax.report.page import build_report

    out = Path(args.out)
    if out.suffix.lower() not in (".html", ".htm"):
        raise UsageError(f"--out {args.out}: the report is one HTML file (name it *.html)")
    if out.is_dir():
        raise UsageError(f"--out {args.out}: is a folder; name the HTML file to write")
    from lantern_jax.io.files import OutputFolderError
    from lantern_jax.report.page import check_report_target

    try:
        check_report_target(out, args.figures)
    except OutputFolderError as e:
        raise UsageError(f"--out {e}") from None
    try:
        sets = [read_result_set(r) for r in args.results]
    except ResultSetError as e:
        raise UsageError(str(e)) from None
    stage(args, f"report of {', '.join(str(rs.folder) for rs in sets)}")
    figures = _figure_maker(sets, args.quiet) if args.figures else None
    try:
        path = build_report(sets, out, figures=figures, title=args.title)
    except OSError as e:
        print(f"lantern-jax report: error: cannot write {out}: {e}", file=sys.stderr)
        return 1
    print(f"Wrote {path}" + (f" and {out.with_name(out.stem + '_files')}/" if figures else ""))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``report`` on the command line's sub-parsers."""
    rp = sub.add_parser(
        "report",
        allow_abbrev=False,
        help="one HTML page of result folders: plots, sortable tables, every failure",
        description="Write one self-contained HTML report of one or more result folders: the "
        "run's identity, per-family CUS with intervals, the decomposition and gate failures, "
        "paired differences between policies, and a gallery of every failing execution.",
    )
    rp.add_argument("results", nargs="+", metavar="RESULTS", help="result folders")
    rp.add_argument("--out", default="report.html", metavar="FILE.html",
                    help="the HTML file to write")  # fmt: skip
    rp.add_argument("--figures", action="store_true",
                    help="record every failing pair again and show its bird's-eye view and "
                    "timeline (kept in FILE_files/ for later reports)")  # fmt: skip
    rp.add_argument("--title", metavar="TEXT", help="the page's title")
    rp.add_argument("--quiet", action="store_true", help="no stage lines")
    rp.set_defaults(func=cmd_report)
