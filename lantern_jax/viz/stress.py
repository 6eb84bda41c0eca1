"""Convergence plot of a stress test: best hard CUS found so far, per method."""

from __future__ import annotations

from typing import Any

import matplotlib

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

METHOD_STYLE = {
    "gradient": dict(color="#d62828", lw=2.0),
    "random": dict(color="#6c757d", lw=1.6, ls="--"),
    "cmaes": dict(color="#1d3557", lw=1.6, ls="-."),
}


def convergence_plot(traces: list[Any], title: str = "") -> Figure:
    """Best (lowest) hard CUS found so far against rollouts and against wall-clock seconds.

    Args:
        traces: :class:`lantern_jax.stress.search.Trace` objects, one per method.
        title: figure title.

    Returns:
        A figure with two panels (rollouts per restart, seconds); a horizontal line marks the
        failure threshold of the verifier (CUS 50) and markers the first verified failures.
    """
    from lantern_jax.stress.verify import FAIL_BELOW_CUS

    fig = Figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    for t in traces:
        style = METHOD_STYLE.get(t.method, {})
        cost = t.rollouts or t.evaluations
        for ax, x in zip(axes, (cost, t.seconds), strict=True):
            ax.step(x, t.best_cus, where="post", label=t.method, **style)
        for f in t.found[:1]:
            axes[0].plot(f["rollouts"], f["cus"], "o", color=style.get("color"))
            axes[1].plot(f["seconds"], f["cus"], "o", color=style.get("color"))
    for ax, label in zip(axes, ("rollouts per restart (every kind)", "seconds"), strict=True):
        ax.axhline(FAIL_BELOW_CUS, color="black", lw=0.8, ls=":")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("best hard CUS found")
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig
