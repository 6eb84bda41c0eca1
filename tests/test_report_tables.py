"""Tables as text: a value that does not exist reads as ``MISSING``, never ``nan`` or ``inf``,
in the terminal tables (tabulate) and the Markdown files alike; the tables a command prints go
through :func:`lantern_jax.report.missing_shown`."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from tabulate import tabulate

from lantern_jax.commands.common import print_and_write
from lantern_jax.report import MISSING, format_interval, missing_shown


def _table() -> pd.DataFrame:
    return pd.DataFrame({"Variant": ["a", "b", "c"], "PE": [1.25, np.nan, -np.inf],
                         "VC": [np.inf, 2.0, 3.0], "n": [1, 2, 3]})  # fmt: skip


def test_missing_values_print_as_missing():
    text = tabulate(missing_shown(_table()), headers="keys", floatfmt=".1f", missingval=MISSING)
    md = missing_shown(_table()).to_markdown(index=False, floatfmt=".1f", missingval=MISSING)
    for out in (text, md):
        assert "nan" not in out and "inf" not in out
        assert out.count(f" {MISSING} ") >= 3
        assert "1.2" in out and "2.0" in out  # finite values keep their format


def test_missing_shown_keeps_finite_values_and_the_original():
    df = _table()
    shown = missing_shown(df)
    assert shown.loc[0, "PE"] == 1.25 and shown.loc[1, "PE"] is None and shown.loc[2, "PE"] is None
    assert shown.loc[0, "VC"] is None and shown["n"].tolist() == [1, 2, 3]
    assert math.isnan(df.loc[1, "PE"])  # the caller's table is not changed


def test_printed_command_tables_show_missing(tmp_path, capsys):
    print_and_write({"t": ("title", _table())}, str(tmp_path), note="")
    out = capsys.readouterr().out
    assert "nan" not in out and "inf" not in out
    assert "nan" not in (tmp_path / "t.md").read_text()


def test_an_interval_of_nothing_is_missing():
    assert format_interval(float("nan"), None, None) == MISSING


def test_a_one_iteration_trace_is_visible_in_the_convergence_plot():
    from types import SimpleNamespace

    from lantern_jax.viz.stress import convergence_plot

    trace = SimpleNamespace(method="gradient", rollouts=[8], evaluations=[8], seconds=[1.5],
                            best_cus=[72.0], found=[])  # fmt: skip
    fig = convergence_plot([trace])
    lines = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "gradient"]
    assert len(lines) == 1 and lines[0].get_marker() == "o"
    assert list(lines[0].get_ydata()) == [72.0]


def test_format_family_table_of_a_result_renders_as_the_command_line():
    """Given the evaluation itself, the family table is the command line's: title, the policies
    in the order given, intervals with their pairs per column, and the legend."""
    import lantern_jax as lj
    from lantern_jax.report import format_family_table, format_tables

    result = lj.evaluate(["coop", "ego"], suite=lj.load_suite().select(["pe_0001", "vc_0001"]),
                         progress=False)  # fmt: skip
    text = format_family_table(result)
    lines = text.splitlines()
    assert lines[0].startswith("Per-family CUS  (suite lantern-v3, 2 pairs, ablation none")
    assert "n=1" in lines[1] and "[" in lines[3]
    rows = [ln.split("  ")[0] for ln in lines[3:9]]
    assert rows[0].startswith("coop (warning)") and rows[3].startswith("ego (warning)")
    table, legend = text.rsplit("\n", 1)
    assert table in format_tables(result) and format_tables(result).endswith(legend)
    # without the expert in the run, B-Time/Exp. is '-', and the title says why
    assert "B-Time/Exp. % of the expert's time, - without the expert in the run" in format_tables(
        result
    )
