"""Animated bird's-eye views of a recorded execution (GIF, or MP4 where ffmpeg exists)."""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path
from typing import Any

from matplotlib import animation

from lantern_jax.io.files import file_mode
from lantern_jax.viz.common import collision_index, num_valid_ticks, to_numpy
from lantern_jax.viz.plots import bev_figure, bev_plot


def save_animation(
    scenario: Any,
    record: Any,
    path: str | os.PathLike,
    fps: int = 10,
    stride: int = 2,
    dpi: int = 80,
    show_rays: bool = True,
    title: str | None = None,
    collision_time: float | None = None,
) -> Path:
    """Write an animation of the bird's-eye view (:func:`~lantern_jax.viz.plots.bev_plot`).

    One frame every ``stride`` record entries, from the first entry to the end of the execution
    (the tick that ended it is always the last frame).  A single figure is reused and redrawn
    per frame at a small ``dpi``.  The file is written to a temporary name in the same folder
    and moved into place when complete, with the mode a plain ``open`` would give it (0o666
    minus the umask, e.g. 0o644).

    Args:
        scenario: the :class:`~lantern_jax.types.world.Scenario` of the execution.
        record: its ``TickRecord`` with a leading time axis.
        path: destination; ``.mp4`` is written with ffmpeg when available, otherwise (with a
            warning) a GIF is written next to it with the suffix ``.gif``; every other suffix
            gives an animated GIF (Pillow).
        fps: frames per second of the output.
        stride: record entries per frame (20 entries = 1 s of simulated time).
        dpi: resolution of the frames.
        show_rays: draw the camera sight lines.
        title: title prefix of every frame (see ``bev_plot``).
        collision_time: s, the execution's first collision: from its frame on a red X marks
            where the ego collided (see ``bev_plot``); None: no collision.

    Returns:
        The path actually written.
    """
    if stride < 1 or fps < 1:
        raise ValueError(f"stride and fps must be >= 1, got stride={stride}, fps={fps}")
    w, rec = to_numpy(scenario), to_numpy(record)
    n = num_valid_ticks(rec)
    frames = list(range(0, n, stride))
    if frames[-1] != n - 1:
        frames.append(n - 1)
    i_coll = collision_index(rec, collision_time)
    if i_coll is not None and i_coll not in frames:  # the collision always gets its frame
        frames = sorted([*frames, i_coll])

    path = Path(path)
    if path.suffix.lower() == ".mp4":
        if animation.writers.is_available("ffmpeg"):
            writer = animation.FFMpegWriter(fps=fps)
        else:
            path = path.with_suffix(".gif")
            warnings.warn(f"ffmpeg is not available; writing a GIF to {path}", stacklevel=2)
            writer = animation.PillowWriter(fps=fps)
    else:
        writer = animation.PillowWriter(fps=fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The temporary name keeps the real suffix: the writers pick the format from it.
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.tmp.", suffix=path.suffix, dir=path.parent)
    os.close(fd)

    fig, ax = bev_figure()
    try:
        with writer.saving(fig, tmp, dpi):
            for i in frames:
                bev_plot(w, rec, i, ax=ax, title=title, show_rays=show_rays,
                         collision_time=collision_time)  # fmt: skip
                writer.grab_frame()
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
