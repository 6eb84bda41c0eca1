"""The fragility figure: every pair's predicted radius, and where its verified failure lay."""

from __future__ import annotations

import matplotlib
import numpy as np
import pandas as pd

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

#: How a pair is drawn, by what the hard probes found along its predicted direction.
OUTCOME_STYLE = {
    "fails at the radius": dict(color="#d62828", marker="o"),
    "fails farther along": dict(color="#f4a261", marker="s"),
    "no failure on the line": dict(color="#6c757d", marker="o", facecolors="none"),
    "fails in its own scene": dict(color="#000000", marker="x"),
}
FLOOR = 1e-3  # normalised units: radii below this are drawn at it (log axis)
CEIL = 10.0  # radii above this (inf: no direction) are drawn at it


def outcome(row: pd.Series) -> str:
    """Which :data:`OUTCOME_STYLE` entry a pair of the fragility table falls in."""
    if bool(row["nominal_failed"]):
        return "fails in its own scene"
    if bool(row["fails_within"]):
        return "fails at the radius"
    if bool(row["fails_on_line"]):
        return "fails farther along"
    return "no failure on the line"


def fragility_figure(table: pd.DataFrame, title: str = "") -> Figure:
    """Two panels from :attr:`lantern_jax.apps.stress.fragility.Fragility.table`.

    Left: each pair's radius (normalised knob units, log scale), by family, coloured by what the
    hard probes found (:data:`OUTCOME_STYLE`). Right: the radius against the distance of the
    nearest verified failure along the predicted direction, with the lines ``t = r`` and
    ``t = 2 r`` (a pair below ``2 r`` counts as predicted).
    """
    fig = Figure(figsize=(11, 4.2))
    ax, ax2 = fig.subplots(1, 2, gridspec_kw=dict(width_ratios=[1.3, 1]))
    families = list(dict.fromkeys(table["family"]))
    radius = np.clip(table["radius"].to_numpy(float), FLOOR, CEIL)
    kinds = table.apply(outcome, axis=1).to_numpy()
    rng = np.random.default_rng(0)
    x = np.array([families.index(f) for f in table["family"]], float)
    x = x + rng.uniform(-0.25, 0.25, len(x))
    for kind, style in OUTCOME_STYLE.items():
        on = kinds == kind
        if not on.any():
            continue
        label = f"{kind} ({int(on.sum())})"
        if style["marker"] == "x":  # an unfilled marker takes one colour
            ax.scatter(x[on], radius[on], s=22, marker="x", color=style["color"], label=label)
        else:
            ax.scatter(x[on], radius[on], s=22, marker=style["marker"], edgecolors=style["color"],
                       facecolors=style.get("facecolors", style["color"]), label=label)  # fmt: skip
    ax.set_yscale("log")
    ax.set_xticks(range(len(families)), families)
    ax.set_ylabel("fragility radius (share of a knob's range)")
    ax.axhline(1.0, color="#adb5bd", lw=0.8, ls=":")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)
    t = table["first_failure_t"].to_numpy(float)
    found = np.isfinite(t) & ~table["nominal_failed"].to_numpy(bool)
    if found.any():
        ax2.scatter(radius[found], np.clip(t[found], FLOOR, CEIL), s=22, color="#d62828")
    lims = np.array([FLOOR, CEIL])
    ax2.plot(lims, lims, color="#495057", lw=0.9, label="t = r")
    ax2.plot(lims, 2 * lims, color="#495057", lw=0.9, ls="--", label="t = 2 r")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("predicted radius r")
    ax2.set_ylabel("nearest verified failure t (same units)")
    ax2.legend(fontsize=7, loc="upper left")
    if not found.any():
        ax2.text(0.5, 0.5, "no verified failure along any line", ha="center", va="center",
                 transform=ax2.transAxes)  # fmt: skip
    fig.suptitle(title or "fragility radius")
    fig.tight_layout()
    return fig
