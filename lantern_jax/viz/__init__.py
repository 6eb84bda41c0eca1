"""Figures of recorded executions: bird's-eye views, condition timelines, animations.

* :func:`bev_plot` — bird's-eye view of one execution at one recorded tick;
* :func:`timeline_plot` — speed and acceleration of the warning vs no-warning runs with the
  protocol's transitions;
* :func:`save_animation` — animated bird's-eye view (GIF; MP4 where ffmpeg exists);
* :func:`save_figure` — atomic PNG output;
* :func:`plot_pair` — one pair under one policy in one figure: the bird's-eye view at its most
  telling tick (first collision, else minimum clearance) and the timeline of both conditions,
  collisions and the first failed gate marked; :func:`record_pair` records the pair's three
  executions it draws.

Figures are built with :class:`matplotlib.figure.Figure` directly (no ``pyplot``), so they
render headless with any backend and are not kept alive by a global figure registry.
"""

from lantern_jax.viz.animate import save_animation
from lantern_jax.viz.common import num_valid_ticks, save_figure, to_numpy
from lantern_jax.viz.pair import PairRecording, RecordedExecution, plot_pair, record_pair
from lantern_jax.viz.plots import bev_plot
from lantern_jax.viz.timeline import timeline_plot, warning_interval

__all__ = [
    "PairRecording",
    "RecordedExecution",
    "bev_plot",
    "num_valid_ticks",
    "plot_pair",
    "record_pair",
    "save_animation",
    "save_figure",
    "timeline_plot",
    "to_numpy",
    "warning_interval",
]
