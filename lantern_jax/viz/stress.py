"""Convergence plot of a stress test: best hard CUS found so far, per method."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

from lantern_jax.apps.diagnostics import run_recorded
from lantern_jax.apps.stress.verify import FAIL_BELOW_CUS
from lantern_jax.core.times import ticks
from lantern_jax.viz.plots import bev_plot

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

METHOD_STYLE = {
    "gradient": dict(color="#d62828", lw=2.0),
    "random": dict(color="#6c757d", lw=1.6, ls="--"),
    "cmaes": dict(color="#1d3557", lw=1.6, ls="-."),
    "hybrid": dict(color="#f4a261", lw=1.8, ls=":"),
    "king": dict(color="#2a9d8f", lw=1.8, ls=(0, (5, 1, 1, 1))),
}


def convergence_plot(traces: list[Any], title: str = "") -> Figure:
    """Best (lowest) hard CUS found so far against rollouts and against wall-clock seconds.

    Args:
        traces: :class:`lantern_jax.apps.stress.search.Trace` objects, one per method.
        title: figure title.

    Returns:
        A figure with two panels (rollouts per restart, seconds); a horizontal line marks the
        failure threshold of the verifier (CUS 50) and markers the first verified failures.
    """

    fig = Figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    for t in traces:
        style = METHOD_STYLE.get(t.method, {})
        cost = t.rollouts or t.evaluations
        for ax, x in zip(axes, (cost, t.seconds), strict=True):
            # markers as well: a trace of one iteration is a single point, which a line alone
            # would not draw
            ax.step(x, t.best_cus, where="post", label=t.method, marker="o", ms=3, **style)
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


MAX_PANELS = 12  # bird's-eye views drawn in the catalogue figure


def catalogue_figure(problem: Any, entries: list[dict], max_panels: int = MAX_PANELS) -> Figure:
    """Bird's-eye views of the first ``max_panels`` catalogue entries: the policy's recorded
    rollout at its first gate failure (else at its closest approach to a watched actor), with
    the path of every tracked actor drawn over the whole execution.

    Args:
        problem: the :class:`lantern_jax.apps.stress.objective.Problem` searched.
        entries: catalogue entries (:func:`lantern_jax.apps.stress.catalogue.catalogue_entries`).
        max_panels: at most this many panels.
    """

    shown = entries[:max_panels]
    cols = min(3, max(1, len(shown)))
    rows = max(1, -(-len(shown) // cols))
    fig = Figure(figsize=(6.0 * cols, 5.4 * rows))
    if not shown:
        fig.text(0.5, 0.5, "no failure found", ha="center")
        return fig
    space = problem.space
    scenarios = [
        space.apply(problem.scenario_a, problem.scenario_b, jnp.asarray(e["values"], jnp.float32))[
            0
        ]
        for e in shown
    ]
    _, rec, _ = run_recorded(problem.policy, problem.policy_params, scenarios, problem.settings)
    for k, e in enumerate(shown):
        ax = fig.add_subplot(rows, cols, k + 1)
        r = jax.tree.map(lambda x, k=k: x[k], rec)
        t_fail = e["t_fail_s"]
        if np.isfinite(t_fail):
            tick = ticks(t_fail) - 1
        else:
            d = np.min(
                [np.linalg.norm(r.actor_xy[:, s] - r.ego_xy, axis=1) for s in problem.watched],
                axis=0,
            )
            tick = int(np.argmin(np.where(np.asarray(r.done), np.inf, d)))
        bev_plot(scenarios[k], r, max(tick, 0), ax=ax, title=e["pair_id"], show_rays=False)
        for s in space.tracked:
            here = np.asarray(r.actor_present)[:, s]
            xy = np.asarray(r.actor_xy)[:, s][here]
            ax.plot(xy[:, 0], xy[:, 1], color="#d62828", lw=1.2, ls="--", zorder=6)
        if ax.get_legend() is not None:  # panels sit side by side: no room for legends
            ax.get_legend().remove()
        ax.text(
            0.01,
            0.01,
            e["description"],
            transform=ax.transAxes,
            fontsize=5.5,
            va="bottom",
            wrap=True,
            bbox=dict(facecolor="white", alpha=0.8, lw=0),
        )
    fig.tight_layout()
    return fig
