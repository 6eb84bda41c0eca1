"""Helpers shared by the figure modules: NumPy conversion, record trimming, frames, PNG output."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import jax
import numpy as np
from matplotlib.figure import Figure

from lantern_jax.core import times
from lantern_jax.core.constants import DT
from lantern_jax.io.files import file_mode, temporary_beside

COLLISION_COLOR = "#e00000"  # collision markers (bird's-eye view and timeline)


def to_numpy(tree: Any) -> Any:
    """Convert every leaf of a pytree (JAX or NumPy arrays, scalars) to a NumPy array.

    Args:
        tree: any pytree, e.g. a :class:`~lantern_jax.types.world.Scenario` or a ``TickRecord``.

    Returns:
        The same structure with ``np.ndarray`` leaves.
    """
    return jax.tree.map(np.asarray, tree)


def num_valid_ticks(record: Any) -> int:
    """Number of record entries that belong to the execution.

    Args:
        record: a ``TickRecord`` with a leading time axis (``done`` of shape ``(N,)``).

    Returns:
        Index of the first ``done`` entry plus one (the tick that ended the execution is kept),
        or ``N`` when the execution never ended inside the horizon.
    """
    done = np.asarray(record.done, bool).reshape(-1)
    return int(np.argmax(done)) + 1 if done.any() else int(done.shape[0])


def happened(t: Any) -> bool:
    """Host-side :func:`lantern_jax.core.times.happened` of one concrete time (NaN: not
    happened)."""
    return bool(np.isfinite(float(t)) and times.happened(float(t)))


def collision_index(record: Any, collision_time: Any) -> int | None:
    """Record entry of a collision: the first entry at or after ``collision_time``.

    Args:
        record: a ``TickRecord`` with a leading time axis (``t`` of shape ``(N,)``, s).
        collision_time: s, the first collision (``telemetry.collision.t_collision``); None, NaN
            or a time that never happened: no collision.

    Returns:
        The entry index (within the execution's valid entries), or None without a collision.
    """
    if collision_time is None or not happened(collision_time):
        return None
    t = np.asarray(record.t, float).reshape(-1)[: num_valid_ticks(record)]
    i = int(np.searchsorted(t, float(collision_time) - 0.5 * DT))
    return min(i, t.shape[0] - 1)


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Write a figure as PNG atomically (temporary file in the same folder + ``os.replace``).

    The file gets the mode a plain ``open`` would give it (0o666 minus the umask, e.g. 0o644),
    so others can read it.

    Args:
        fig: the matplotlib figure.
        path: destination file; parent folders are created.
        dpi: resolution.

    Returns:
        The destination path.
    """
    path = Path(path)
    fd, tmp = temporary_beside(path, ".png.tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fig.savefig(fh, format="png", dpi=dpi, bbox_inches="tight")
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def rot(yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit heading and unit left normal of a yaw."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c, s]), np.array([-s, c])


def box_corners_np(xy: np.ndarray, yaw: float, extent: np.ndarray) -> np.ndarray:
    """(4, 2) corners (front-left, rear-left, rear-right, front-right) of one oriented box."""
    fwd, left = rot(float(yaw))
    hl, hw = float(extent[0]), float(extent[1])
    sx = np.array([1.0, -1.0, -1.0, 1.0])[:, None]
    sy = np.array([1.0, 1.0, -1.0, -1.0])[:, None]
    return np.asarray(xy, float)[None] + sx * hl * fwd + sy * hw * left


def ego_frame_to_world(pts: np.ndarray, xy: np.ndarray, yaw: float) -> np.ndarray:
    """Ego-frame points (x forward, y right) -> world frame, for an ego pose."""
    fwd, left = rot(float(yaw))
    pts = np.asarray(pts, float).reshape(-1, 2)
    return np.asarray(xy, float)[None] + pts[:, :1] * fwd - pts[:, 1:2] * left


def lane_polygon(center: np.ndarray, width: float) -> np.ndarray:
    """Outline of a lane strip of ``width`` around a centre polyline (left edge, right edge)."""
    d = np.gradient(center, axis=0)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    d = d / np.maximum(n, 1e-9)
    left = np.stack([-d[:, 1], d[:, 0]], axis=1)
    return np.concatenate([center + 0.5 * width * left, (center - 0.5 * width * left)[::-1]])


def route_point(route: Any, s: float) -> np.ndarray | None:
    """World point at route arc ``s`` (None when outside the route)."""
    v = np.asarray(route.valid, bool)
    rs, rxy = route.s[v], route.xy[v]
    if not (rs[0] - 1e-6 <= s <= rs[-1] + 1e-6):
        return None
    return np.array([np.interp(s, rs, rxy[:, 0]), np.interp(s, rs, rxy[:, 1])])
