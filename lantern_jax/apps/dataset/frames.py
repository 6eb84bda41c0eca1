"""From a recorded execution to training frames: waypoints, flags, timeline, acceptance.

Per sequence (one recorded execution, host side, NumPy):

* **frames** — every live frame whose ten future frames are live too (the expert's actual
  positions 0.25 ... 2.5 s later exist): the ten waypoints are those positions in the frame's
  ego frame (x forward, y right, metres);
* **horizon crossing** — a frame whose waypoint horizon ``(t, t + 2.5 s]`` contains the warning
  onset or the warning termination is flagged (training excludes it by default, the paper's
  rule: its labels mix two warning states; see ``EXCLUDE_CROSSING`` in
  :mod:`lantern_jax.apps.dataset.store` for the alternatives);
* **acceptance** (the paper's open-loop rules, appendix "Data Collection Details"): at least 95 %
  route completion, no collision, no low-speed tail longer than 40 retained frames; Route A also
  needs at least three retained frames before warning onset, the ordered timeline
  ``t_warn_on <= t_event < t_warn_off`` (equality of onset and event only for Right-Turn Yield),
  a completed physical event (clearance recorded) and a recovery segment (frames after the
  release); Route B must show no active warning and hold no hazard actor.  A rejected sequence is
  counted by its first failed rule.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lantern_jax.core.constants import NUM_WAYPOINTS, ROLE_HAZARD, WAYPOINT_DT
from lantern_jax.core.times import happened
from lantern_jax.types.language import PAD_ID

MIN_COMPLETION = 0.95  # route completion of an accepted sequence
MIN_FRAMES_BEFORE_WARNING = 3
MIN_RECOVERY_FRAMES = 4  # retained frames (1 s) after the release
LOW_SPEED_MPS = 0.5  # m/s, a retained frame this slow belongs to a low-speed tail
MAX_LOW_SPEED_FRAMES = 40  # a longer run of slow frames rejects the sequence
HORIZON_S = NUM_WAYPOINTS * WAYPOINT_DT  # 2.5 s

REASONS = (
    "route completion below 95 %",
    "collision",
    "low-speed tail longer than 40 frames",
    "fewer than 3 frames before warning onset",
    "timeline out of order",
    "physical event not completed",
    "no recovery segment",
    "Route B shows a warning or a hazard",
    "no frame with a full waypoint horizon",
)


def future_waypoints(ego_xy: np.ndarray, ego_yaw: np.ndarray, f: int) -> np.ndarray:
    """(10, 2) positions of frames ``f + 1 .. f + 10`` in the ego frame of frame ``f``."""
    rel = ego_xy[f + 1 : f + 1 + NUM_WAYPOINTS] - ego_xy[f]
    c, s = np.cos(ego_yaw[f]), np.sin(ego_yaw[f])
    return np.stack([rel[:, 0] * c + rel[:, 1] * s, rel[:, 0] * s - rel[:, 1] * c], axis=-1)


def _longest_run(mask: np.ndarray) -> int:
    best = run = 0
    for m in mask:
        run = run + 1 if m else 0
        best = max(best, run)
    return best


def rejection(
    route_a: bool, frames: Any, protocol: Any, metrics: Any, roles: np.ndarray, valid: np.ndarray,
    coincident: bool,
) -> str | None:  # fmt: skip
    """The first acceptance rule a recorded sequence fails (:data:`REASONS`), or None.

    Args:
        route_a: the sequence is a Route A execution.
        frames: its :class:`~lantern_jax.apps.dataset.record.FrameRecord` (NumPy, frame axis first).
        protocol: its final :class:`~lantern_jax.types.world.ProtocolState` (NumPy).
        metrics: its :class:`~lantern_jax.scoring.metrics.ExecutionMetrics` (NumPy).
        roles, valid: (A,) actor roles and validity of its scenario.
        coincident: warning and event points coincide (Right-Turn Yield).
    """
    live = np.asarray(frames.live, bool)
    speed = np.asarray(frames.obs.ego_speed)[live]
    if float(metrics.progress) < MIN_COMPLETION:
        return REASONS[0]
    if not bool(metrics.gate_collision):
        return REASONS[1]
    if _longest_run(speed < LOW_SPEED_MPS) > MAX_LOW_SPEED_FRAMES:
        return REASONS[2]
    t = np.asarray(frames.t)[live]
    if route_a:
        on, ev, off, clear = (float(getattr(protocol, k)) for k in
                              ("t_warn_on", "t_event", "t_warn_off", "t_clear"))  # fmt: skip
        if not happened(on) or int(np.sum(t < on)) < MIN_FRAMES_BEFORE_WARNING:
            return REASONS[3]
        ordered = happened(ev) and happened(off) and (on < ev or (coincident and on == ev))
        if not (ordered and ev < off):
            return REASONS[4]
        if not happened(clear):
            return REASONS[5]
        if int(np.sum(t > max(off, clear))) < MIN_RECOVERY_FRAMES:
            return REASONS[6]
    elif bool(np.any(np.asarray(frames.obs.warning_tokens)[live] != PAD_ID)) or bool(
        np.any(valid & (roles == ROLE_HAZARD))
    ):
        return REASONS[7]
    if int(live.sum()) <= NUM_WAYPOINTS:
        return REASONS[8]
    return None


def frame_indices(frames: Any) -> np.ndarray:
    """Indices of the frames with a full live waypoint horizon."""
    n_live = int(np.sum(np.asarray(frames.live, bool)))
    return np.arange(max(n_live - NUM_WAYPOINTS, 0))


def horizon_crossing(t: np.ndarray, *marks: Any) -> np.ndarray:
    """(F,) bool: the waypoint horizon ``(t, t + 2.5 s]`` contains one of the ``marks``.

    Args:
        t: (F,) float32, s, frame times.
        marks: times (s), each a scalar or an (F,) array (one per frame, e.g. its sequence's
            warning onset); a mark that did not happen (``NEVER`` or NaN) crosses nothing.
            Marks are compared in ``t``'s dtype, so a recorded float32 time compares exactly.

    Returns:
        (F,) bool.
    """
    t = np.asarray(t)
    crosses = np.zeros(t.shape, bool)
    for mark in marks:
        m = np.asarray(mark, dtype=t.dtype)
        crosses |= happened(m) & (t < m) & (m <= t + HORIZON_S)
    return crosses
