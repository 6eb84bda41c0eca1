"""One self-contained HTML report of one or more result folders: what ran, the tables as plots
and sortable tables, and a gallery of every failure.

:func:`build_report` reads result folders as evidence
(:func:`lantern_jax.report.evidence.read_result_set`: every file checked against its manifest)
and writes one HTML file that needs no network when it is viewed: plots are PNG images embedded
in the page, the tables are HTML with a few lines of script that sort a column on a click, and
the failure figures (only when a ``figures`` function is given: they need a re-simulation,
:func:`lantern_jax.viz.pair.plot_pair`) are PNG files in a folder beside it.  Sections:

* **the run** -- per result folder: suite and its hash, every policy with its parameters' hash
  and, for a policy from a file, the file and its SHA-256; ablation, the text bank's hash, the
  rule by which the actors find the ego ahead of them (``Settings.actors``), package versions,
  and when the manifest was written;
* **per-family CUS** -- warning, no-warning and the warning gain of every family and overall,
  every policy side by side, with the 95 % intervals, as a plot and as a table;
* **CUS decomposition and gate failures** -- the components and each gate's failure rate as a
  plot and a table; the premise (the hazard hidden from the front camera);
* **paired differences** -- with two or more policies (in one folder or across folders over the
  same pairs): every policy against the first, per family, with intervals (a forest plot,
  :func:`lantern_jax.scoring.paired.compare_runs`);
* **the failures** -- every Route A execution that fails a gate and every Route B false brake,
  grouped by family and by the first gate failed, with the pair, the condition, the time of the
  first failure and a one-line cause (and, with figures, the pair's bird's-eye view and
  timeline).
"""

from __future__ import annotations

import base64
import datetime as dt
import html
import io
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from lantern_jax.core.constants import FAMILIES, GATE_COLUMN_NAMES
from lantern_jax.dynamics.actors import DEFAULT_ACTORS
from lantern_jax.io.files import OutputFolderError, atomic_write
from lantern_jax.report.evidence import ResultSet, read_result_set
from lantern_jax.report.outputs import DECOMPOSITION_CSV, FAMILY_CSV
from lantern_jax.scoring.aggregate import premise_table
from lantern_jax.scoring.paired import compare_runs
from lantern_jax.sim.settings import actors_of_record

#: The gate columns of a Route A execution, in the order the gallery reads them.
A_GATES = tuple(g for g in GATE_COLUMN_NAMES if g != "no_false_brake")
#: What a failed gate means, for the gallery's one-line cause.
CAUSES = {
    "no_collision": "collided",
    "on_route": "left the route",
    "in_lane": "drove out of its lane",
    "no_red_light": "ran a red light",
    "not_blocked": "was blocked (stood still or timed out)",
    "no_false_brake": "braked on Route B with nothing there (false brake)",
}
#: A figure of one failing execution: ``(policy, pair id, condition, folder) -> PNG path``.
FigureMaker = Callable[[str, str, str, Path], Path]

#: The page's generator tag: an existing ``--out`` file without it is the user's, never replaced.
GENERATOR = "<meta name='generator' content='lantern_jax report'>"

_STYLE = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0 1.5em}
th,td{border:1px solid #ddd;padding:.25em .5em;text-align:right}
th{background:#f3f3f3;cursor:pointer}td:first-child,th:first-child{text-align:left}
.note{color:#555;font-size:.85em}.fail{border:1px solid #e5b8b8;margin:.5em 0;padding:.5em}
.gallery img{max-width:100%}dl{display:grid;grid-template-columns:14em auto}
dt{font-weight:bold}
"""
#: Sorting a table by the column clicked (numbers as numbers); nothing else runs in the page.
_SORT = """
document.querySelectorAll('table.sortable th').forEach(function (th, i) {
  th.addEventListener('click', function () {
    var body = th.closest('table').tBodies[0], up = th.dataset.up !== '1';
    var rows = Array.from(body.rows);
    rows.sort(function (a, b) {
      var x = a.cells[i].dataset.v || a.cells[i].textContent;
      var y = b.cells[i].dataset.v || b.cells[i].textContent;
      var nx = parseFloat(x), ny = parseFloat(y);
      var c = (isNaN(nx) || isNaN(ny)) ? x.localeCompare(y) : nx - ny;
      return up ? c : -c;
    });
    rows.forEach(function (r) { body.appendChild(r); });
    th.dataset.up = up ? '1' : '0';
  });
});
"""


def _esc(x: object) -> str:
    return html.escape(str(x))


def _png(fig) -> str:
    """A matplotlib figure as an ``<img>`` with the PNG embedded."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    data = base64.b64encode(buf.getvalue()).decode()
    return f'<img alt="plot" src="data:image/png;base64,{data}">'


def table_html(df: pd.DataFrame, caption: str = "", digits: int = 1) -> str:
    """A DataFrame as a sortable HTML table (numbers rounded to ``digits``; NaN as ``-``)."""
    head = "".join(f"<th>{_esc(c)}</th>" for c in df.columns)
    rows = []
    for rec in df.itertuples(index=False):
        cells = []
        for v in rec:
            if isinstance(v, float | np.floating):
                text = "-" if not np.isfinite(v) else f"{v:.{digits}f}"
                cells.append(f'<td data-v="{"" if not np.isfinite(v) else v}">{text}</td>')
            else:
                cells.append(f"<td>{_esc(v)}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{_esc(caption)}</caption>" if caption else ""
    return (f'<table class="sortable">{cap}<thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')  # fmt: skip


def interval_table_html(df: pd.DataFrame, caption: str = "") -> str:
    """A result table whose columns ``c`` come with ``c_lo``, ``c_hi`` (and ``c_n``) as one
    sortable HTML table, each cell ``value [lo, hi]`` (sorted by the value)."""
    values = [c for c in df.columns if f"{c}_lo" in df.columns and f"{c}_hi" in df.columns]
    keys = [c for c in df.columns if c not in values and not c.endswith(("_lo", "_hi", "_n"))]
    head = "".join(f"<th>{_esc(c)}</th>" for c in (*keys, *values))
    rows = []
    for rec in df.to_dict("records"):
        cells = [f"<td>{_esc(rec[k])}</td>" for k in keys]
        for c in values:
            v, lo, hi = (float(rec[c]), float(rec[f"{c}_lo"]), float(rec[f"{c}_hi"]))
            if not np.isfinite(v):
                cells.append('<td data-v="">-</td>')
                continue
            ci = f" [{lo:.1f}, {hi:.1f}]" if np.isfinite(lo) and np.isfinite(hi) else ""
            cells.append(f'<td data-v="{v}">{v:.1f}{ci}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{_esc(caption)}</caption>" if caption else ""
    return (f'<table class="sortable">{cap}<thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')  # fmt: skip


def _side_label(rs: ResultSet, model: str, many: bool) -> str:
    return f"{model} ({rs.folder.name})" if many else model


def _identity(rs: ResultSet) -> str:
    """The run's identity (definition list) of one result folder."""
    m = rs.manifest
    when = dt.datetime.fromtimestamp(rs.csv.stat().st_mtime, tz=dt.UTC)
    when = when.strftime("%Y-%m-%d %H:%M UTC")
    policies = []
    for p in m.get("policies", []):
        src = p.get("source") or {}
        where = (f", file {src.get('file')} (SHA-256 {str(src.get('source_sha256'))[:12]}...)"
                 if src.get("file") else "")  # fmt: skip
        policies.append(f"{_esc(p.get('name'))} (parameters {str(p.get('params_sha256'))[:12]}..."
                        f"{_esc(where)})")  # fmt: skip
    packages = m.get("packages") or {}
    versions = ", ".join(f"{k} {packages[k]}" for k in ("lantern-jax", "jax", "jaxlib", "numpy")
                         if k in packages)  # fmt: skip
    bank = ((m.get("settings") or {}).get("text_bank")) or {}
    # a record written before 2026-12-08 holds the actors only where not that day's default
    # (lantern_jax.sim.settings.actors_of_record)
    try:
        leader = actors_of_record(m.get("settings")).ego_leader
    except (TypeError, ValueError):  # a record this package never wrote: shown as it is
        leader = str(((m.get("settings") or {}).get("actors")) or "-")
    if leader == DEFAULT_ACTORS.ego_leader:
        leader = f"{leader} (the default)"
    items = [
        ("folder", _esc(rs.folder)),
        ("suite", f"{_esc(m.get('suite_id'))} ({m.get('num_pairs')} pairs, SHA-256 "
                  f"{str(m.get('suite_sha256'))[:12]}...)"),
        ("policies", "<br>".join(policies) or "-"),
        ("ablation", _esc(m.get("ablation", "-"))),
        ("warning texts", f"{bank.get('texts', '-')} (SHA-256 {str(bank.get('sha256'))[:12]}...)"),
        ("actors find the ego ahead by", _esc(leader)),
        ("packages", _esc(versions or "-")),
        ("written", when),
    ]  # fmt: skip
    return "<dl>" + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in items) + "</dl>"


def _family_plot(sets: Sequence[ResultSet]) -> str:
    """Per-family CUS with intervals, every policy side by side: warning and no-warning above,
    the warning gain below."""
    # deferred: matplotlib only when a figure is drawn
    from matplotlib.figure import Figure

    cols = [*FAMILIES, "Overall"]
    many = len(sets) > 1
    sides = []
    for rs in sets:
        fam = pd.read_csv(rs.folder / FAMILY_CSV)
        for model in dict.fromkeys(fam["model"]):
            sides.append((_side_label(rs, model, many), fam[fam["model"] == model]))
    fig = Figure(figsize=(11, 6.5))
    ax_cus, ax_gain = fig.subplots(2, 1, sharex=True)
    width = 0.8 / max(1, len(sides))
    x = np.arange(len(cols))
    for k, (label, rows) in enumerate(sides):
        off = -0.4 + width * (k + 0.5)
        for cond, ax, marker in (("warning", ax_cus, "o"), ("no-warning", ax_cus, "s"),
                                 ("warning gain", ax_gain, "D")):  # fmt: skip
            r = rows[rows["condition"] == cond]
            if r.empty:
                continue
            r = r.iloc[0]
            y = np.array([r[c] for c in cols], float)
            lo = np.array([r.get(f"{c}_lo", np.nan) for c in cols], float)
            hi = np.array([r.get(f"{c}_hi", np.nan) for c in cols], float)
            err = np.vstack([np.nan_to_num(y - lo), np.nan_to_num(hi - y)])
            ax.errorbar(x + off + (0.12 * width if cond == "no-warning" else 0.0), y, yerr=err,
                        fmt=marker, ms=5, capsize=2, color=f"C{k}",
                        mfc="white" if cond == "no-warning" else f"C{k}",
                        label=f"{label}, {cond}")  # fmt: skip
    ax_cus.set_ylabel("CUS")
    ax_cus.set_ylim(0, 100)
    ax_gain.axhline(0.0, color="#888", lw=0.8)
    ax_gain.set_ylabel("warning gain (CUS points)")
    ax_gain.set_xticks(x, cols)
    for ax in (ax_cus, ax_gain):
        ax.grid(alpha=0.3, lw=0.5)
        ax.legend(fontsize=7, ncol=2, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.suptitle("Per-family CUS with 95 % intervals (filled: warning; open: no-warning)")
    return _png(fig)


def _gate_plot(sets: Sequence[ResultSet]) -> str:
    """Each gate's failure rate (% of pairs) per policy and condition, with intervals."""
    # deferred: matplotlib only when a figure is drawn
    from matplotlib.figure import Figure

    gates = ["Coll.-A", "RD-A", "LC-A", "Rule-A", "Block-A", "False Brake-B"]
    many = len(sets) > 1
    bars = []
    for rs in sets:
        dec = pd.read_csv(rs.folder / DECOMPOSITION_CSV)
        for rec in dec.to_dict("records"):
            label = f"{_side_label(rs, rec['model'], many)} ({rec['condition']})"
            bars.append((label, rec))
    fig = Figure(figsize=(11, 4.5))
    ax = fig.subplots()
    width = 0.8 / max(1, len(bars))
    x = np.arange(len(gates))
    for k, (label, rec) in enumerate(bars):
        y = np.array([rec.get(g, np.nan) for g in gates], float)
        lo = np.array([rec.get(f"{g}_lo", np.nan) for g in gates], float)
        hi = np.array([rec.get(f"{g}_hi", np.nan) for g in gates], float)
        err = np.vstack([np.nan_to_num(y - lo), np.nan_to_num(hi - y)])
        ax.bar(x - 0.4 + width * (k + 0.5), np.nan_to_num(y), width, yerr=err, capsize=2,
               label=label, color=f"C{k % 10}")  # fmt: skip
    ax.set_xticks(x, gates)
    ax.set_ylabel("% of pairs failing")
    ax.grid(alpha=0.3, lw=0.5, axis="y")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.suptitle("Gate failures with 95 % intervals")
    return _png(fig)


def _sides(sets: Sequence[ResultSet]) -> list[tuple[str, pd.DataFrame]]:
    """Every (label, route rows) of every policy of every result set."""
    many = len(sets) > 1
    return [(_side_label(rs, model, many), rs.table[rs.table["model"] == model])
            for rs in sets for model in dict.fromkeys(rs.table["model"])]  # fmt: skip


def _forest(sets: Sequence[ResultSet]) -> str:
    """Every policy against the first, per family, the warning condition and the gain, with
    intervals; "" for fewer than two policies."""
    # deferred: matplotlib only when a figure is drawn
    from matplotlib.figure import Figure

    sides = _sides(sets)
    if len(sides) < 2:
        return ""
    (base_label, base), rows, notes = sides[0], [], []
    for label, other in sides[1:]:
        try:
            table = compare_runs(other, base)
        except ValueError as e:
            notes.append(f"{label} against {base_label}: not compared ({e})")
            continue
        table.insert(0, "comparison", f"{label} - {base_label}")
        rows.append(table)
    if not rows:
        return "".join(f'<p class="note">{_esc(n)}</p>' for n in notes)
    table = pd.concat(rows, ignore_index=True)
    shown = table[table["condition"].isin(["warning", "warning gain"])]
    fig = Figure(figsize=(9, 0.28 * len(shown) + 1.5))
    ax = fig.subplots()
    y = np.arange(len(shown))[::-1]
    err = np.vstack([shown["difference"] - shown["lo"], shown["hi"] - shown["difference"]])
    ax.errorbar(shown["difference"], y, xerr=np.nan_to_num(err), fmt="o", ms=4, capsize=2)
    ax.axvline(0.0, color="#888", lw=0.8)
    ax.set_yticks(y, [f"{r.comparison}, {r.condition}, {r.family}" for r in shown.itertuples()],
                  fontsize=7)  # fmt: skip
    ax.set_xlabel("paired difference of mean CUS (points), 95 % interval")
    ax.grid(alpha=0.3, lw=0.5, axis="x")
    return (_png(fig) + table_html(table, "paired differences (first minus second)", 3)
            + "".join(f'<p class="note">{_esc(n)}</p>' for n in notes))  # fmt: skip


def failures(table: pd.DataFrame) -> pd.DataFrame:
    """Every failing execution of a route table: a Route A execution failing a gate, or Route B
    braking falsely; one row each with the first failed gate, its time and a one-line cause,
    sorted by family and gate."""
    rows = []
    for rec in table.to_dict("records"):
        failed = [g for g in A_GATES if rec[g] == 0]
        if failed:
            first = failed[0]
            t = rec.get("t_first_failure_s")
            cause = f"Route A {CAUSES[first]}"
            if isinstance(t, float) and np.isfinite(t):
                cause += f" at {t:.2f} s"
            if failed[1:]:
                cause += f"; also {', '.join(failed[1:])}"
            rows.append(dict(family=rec["family"], gate=first, model=rec["model"],
                             condition=rec["condition"], route="A", pair_id=rec["pair_id"],
                             t_s=t, cause=cause))  # fmt: skip
        if rec["no_false_brake"] == 0 and rec["condition"] == "warning":  # Route B: once a pair
            stop = rec.get("B_false_brake_stop_s")
            cause = CAUSES["no_false_brake"]
            if isinstance(stop, float) and np.isfinite(stop):
                cause += f", stopped {stop:.1f} s"
            rows.append(dict(family=rec["family"], gate="no_false_brake", model=rec["model"],
                             condition="route-b", route="B", pair_id=rec["pair_id"],
                             t_s=np.nan, cause=cause))  # fmt: skip
    out = pd.DataFrame(rows, columns=["family", "gate", "model", "condition", "route",
                                      "pair_id", "t_s", "cause"])  # fmt: skip
    order = {f: i for i, f in enumerate(dict.fromkeys([*FAMILIES, *out["family"]]))}
    gate_order = {g: i for i, g in enumerate(GATE_COLUMN_NAMES)}
    return out.sort_values(
        ["family", "gate", "model", "pair_id", "condition"],
        key=lambda c: c.map(order) if c.name == "family" else
        c.map(gate_order) if c.name == "gate" else c,
    ).reset_index(drop=True)  # fmt: skip


def _gallery(sets: Sequence[ResultSet], figures: FigureMaker | None, files: Path) -> str:
    """The failures of every result set, grouped by family and first failed gate."""
    parts = []
    total = 0
    for rs in sets:
        fails = failures(rs.table)
        total += len(fails)
        if len(sets) > 1:
            parts.append(f"<h3>{_esc(rs.folder)}</h3>")
        for (family, gate), group in fails.groupby(["family", "gate"], sort=False):
            parts.append(f"<h4>{_esc(family)}: {_esc(gate)} ({len(group)})</h4>")
            for rec in group.to_dict("records"):
                img = ""
                if figures is not None:
                    png = figures(rec["model"], rec["pair_id"], rec["condition"], files)
                    img = f'<img alt="{_esc(rec["pair_id"])}" src="{_esc(_relative(png, files))}">'
                parts.append(
                    f'<div class="fail" data-pair="{_esc(rec["pair_id"])}">'
                    f'<b>{_esc(rec["pair_id"])}</b> {_esc(rec["model"])}, '
                    f'{_esc(rec["condition"])}: {_esc(rec["cause"])}{img}</div>'
                )  # fmt: skip
    head = (f'<p class="note">{total} failing executions'
            f'{"" if figures is not None else " (figures: lantern-jax report --figures)"}.</p>')
    return head + '<div class="gallery">' + "".join(parts) + "</div>"


def _relative(png: Path, files: Path) -> str:
    return f"{files.name}/{os.path.relpath(png, files)}"


def check_report_target(out: Path, figures: bool) -> Path:
    """Refuse a report target that would replace something this project did not write: an
    ``out`` that is a folder, a link or a file without the report's :data:`GENERATOR` tag (or,
    from before the tag, its sorting script); with ``figures``, a ``<stem>_files`` entry that
    is not a plain folder.  Returns the figures' folder.

    Raises:
        OutputFolderError: naming the entry.
    """
    files = out.with_name(out.stem + "_files")
    if os.path.lexists(out):
        if out.is_symlink() or not out.is_file():
            raise OutputFolderError(f"{out}: is not a file this project wrote (a folder, a link "
                                    "or a special file); choose another name")  # fmt: skip
        with open(out, "rb") as fh:
            head = fh.read(1 << 20).decode("utf-8", "replace")
        if GENERATOR not in head and _SORT not in head:
            raise OutputFolderError(f"{out}: exists and is not a report this project wrote; "
                                    "choose another name, or move it")  # fmt: skip
    if figures and os.path.lexists(files) and (files.is_symlink() or not files.is_dir()):
        raise OutputFolderError(f"{files}: the report's figure folder is a file or a link "
                                "here; move it, or choose another name")  # fmt: skip
    return files


def build_report(
    results: Sequence[str | os.PathLike | ResultSet],
    out: str | os.PathLike,
    figures: FigureMaker | None = None,
    title: str | None = None,
) -> Path:
    """Write the HTML report of one or more result folders (the module docstring).

    Args:
        results: result folders (or their route CSVs, or sets already read).
        out: the HTML file to write (figures go to ``<out stem>_files/`` beside it).
        figures: draws one failing execution's figure into a folder and returns its path (the
            command line's ``--figures``: a re-simulation of the pair); None: no figures.
        title: the page's title (default: the folders' names).

    Returns:
        The HTML file's path.

    Raises:
        lantern_jax.report.evidence.ResultSetError: for a folder that is not valid evidence.
        lantern_jax.io.files.OutputFolderError: when ``out`` (or its figure folder) is something
            this project did not write (:func:`check_report_target`), before anything runs.
    """
    out = Path(out)
    files = check_report_target(out, figures is not None)
    sets = [r if isinstance(r, ResultSet) else read_result_set(r) for r in results]
    title = title or "lantern_jax report: " + ", ".join(rs.folder.name for rs in sets)
    body = [f"<h1>{_esc(title)}</h1>", "<h2>The run</h2>"]
    body += [_identity(rs) for rs in sets]
    body += ["<h2>Per-family CUS</h2>", _family_plot(sets)]
    for rs in sets:
        fam = pd.read_csv(rs.folder / FAMILY_CSV)
        body.append(interval_table_html(fam, f"per-family CUS [95 % interval], "
                                             f"{rs.folder.name}"))  # fmt: skip
    body += ["<h2>CUS decomposition and gate failures</h2>", _gate_plot(sets)]
    for rs in sets:
        dec = pd.read_csv(rs.folder / DECOMPOSITION_CSV)
        body.append(interval_table_html(dec, f"decomposition [95 % interval], "
                                             f"{rs.folder.name}"))  # fmt: skip
        premise = premise_table(rs.table).reset_index()
        body.append(table_html(premise, f"the premise (% of Route A executions), "
                                        f"{rs.folder.name}"))  # fmt: skip
    forest = _forest(sets)
    if forest:
        body += ["<h2>Paired differences</h2>", forest]
    body += ["<h2>The failures</h2>", _gallery(sets, figures, files)]
    page = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>{GENERATOR}"
            f"<title>{_esc(title)}</title><style>{_STYLE}</style></head><body>"
            f"{''.join(body)}<script>{_SORT}</script></body></html>")  # fmt: skip
    atomic_write(out, page.encode())
    return out
