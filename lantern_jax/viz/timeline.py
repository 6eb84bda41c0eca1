"""Speed and acceleration timelines of a warning / no-warning pair of executions."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from lantern_jax.core.constants import DT
from lantern_jax.viz.common import (
    COLLISION_COLOR,
    collision_index,
    happened,
    num_valid_ticks,
    to_numpy,
)

RUN_STYLES = (  # (key, label, colour, line style)
    ("warning", "warning", "#1d3557", "-"),
    ("nowarning", "no warning", "#ee9b00", "--"),
)
EVENT_LINES = (  # (protocol field, label, colour)
    ("t_event", "event onset", "#d62828"),
    ("t_warn_off", "warning termination", "#7b2cbf"),
    ("t_clear", "clearance", "#2a9d8f"),
)
SHADE_COLOR = "#ffd166"


def _ptime(protocol: Any, name: str) -> float:
    """A protocol time from a ``ProtocolState`` (or a mapping) as a float."""
    v = protocol[name] if isinstance(protocol, dict) else getattr(protocol, name)
    return float(np.asarray(v))


def warning_interval(record: Any, protocol: Any) -> tuple[float, float] | None:
    """Interval during which the warning was delivered in one execution.

    The protocol's times are used where they agree with the record to within one tick
    (``t_warn_on`` when written, else ``t_warn_point``; ``t_warn_off``); otherwise (late-onset or
    hold-extra ablations) the record's delivery is used.  ``warning_active[i]`` describes time
    ``record.t[i] - DT`` (the observation read during tick ``i``).

    Args:
        record: ``TickRecord`` with a leading time axis.
        protocol: the final ``ProtocolState`` of the execution.

    Returns:
        ``(start, end)`` in seconds, or None when no warning was delivered.
    """
    rec = to_numpy(record)
    n = num_valid_ticks(rec)
    active = np.asarray(rec.warning_active[:n], bool)
    if not active.any():
        return None
    t_obs = rec.t[:n] - DT
    idx = np.nonzero(active)[0]
    s_rec, e_rec = float(t_obs[idx[0]]), float(t_obs[idx[-1]] + DT)
    start = _ptime(protocol, "t_warn_on")
    if not happened(start):
        start = _ptime(protocol, "t_warn_point")
    if not happened(start) or abs(start - s_rec) > 1.5 * DT:
        start = s_rec
    end = _ptime(protocol, "t_warn_off")
    if not happened(end) or abs(end - e_rec) > 1.5 * DT:
        end = e_rec
    return start, end


#: The speed axis shows this share above the fastest speed plus ``SPEED_PAD_MPS`` (m/s), so a
#: constant-speed line is never drawn on the frame's edge.
SPEED_HEADROOM = 0.08
SPEED_PAD_MPS = 0.5
#: m/s^2: the acceleration axis spans at least +-this, so numerical ripple around zero is not
#: drawn as braking.
MIN_ACCEL_SPAN = 1.0
#: The colour of the legend's two transition-line styles (solid: warning run, dashed: not).
EVENT_KEY_COLOR = "#555555"


def _legend(ax_v: Any, shaded: bool, collided: bool) -> None:
    """The timeline's legend, right of the speed axes: the two runs, the warning's delivery
    (when ``shaded``), the protocol's transitions and (when ``collided``) the collision."""
    handles = [Line2D([], [], color=c, ls=ls, lw=1.6, label=lab) for _, lab, c, ls in RUN_STYLES]
    if shaded:
        handles.append(
            Line2D([], [], color=SHADE_COLOR, alpha=0.6, lw=8, label="warning delivered")
        )
    handles += [Line2D([], [], color=c, lw=1.1, label=lab) for _, lab, c in EVENT_LINES]
    handles += [Line2D([], [], color=EVENT_KEY_COLOR, lw=1.1, ls=ls, label=f"transition, {lab}")
                for _, lab, _, ls in RUN_STYLES]  # fmt: skip
    if collided:
        handles.append(
            Line2D([], [], color=COLLISION_COLOR, lw=2.0, marker="X", ms=8, label="collision")
        )
    ax_v.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
                frameon=False, borderaxespad=0.0)  # fmt: skip


def timeline_plot(
    rec_warning: Any,
    rec_nowarning: Any,
    protocol_warning: Any,
    protocol_nowarning: Any,
    title: str | None = None,
    collision_times: tuple[Any, Any] | None = None,
    axes: tuple[Any, Any] | None = None,
) -> Figure:
    """Speed and longitudinal acceleration over time of the two conditions of one scenario.

    Two stacked axes sharing the time axis: ego speed (m/s) and longitudinal acceleration
    (m/s^2) of the warning run (solid) and the no-warning run (dashed), each trimmed at the end
    of its execution.  The warning run's delivery interval is shaded (:func:`warning_interval`)
    and vertical lines mark event onset, warning termination and clearance of each run (solid:
    warning run, dashed: no-warning run; colour = transition).  The lines carry ``gid``
    ``"<field>:<run>"``, e.g. ``"t_event:warning"``, and sit at the protocol's times.  A run
    that collided gets a red vertical line at the collision on both axes and a red X on its
    speed curve (``gid="collision:<run>"``).

    Args:
        rec_warning: ``TickRecord`` (leading time axis) of the warning condition.
        rec_nowarning: ``TickRecord`` of the no-warning condition.
        protocol_warning: final ``ProtocolState`` (or mapping of its fields) of the warning run.
        protocol_nowarning: final ``ProtocolState`` of the no-warning run.
        title: figure title (the speed axes' title when drawing into ``axes``).
        collision_times: s, ``(warning run, no-warning run)`` first collision of each run
            (``telemetry.collision.t_collision``); None, NaN or a time that never happened: no
            collision.
        axes: ``(speed axes, acceleration axes)`` to draw into (sharing their x axis), e.g. next
            to a bird's-eye view; a new figure is made when None.

    Returns:
        The figure (two axes: speed on top, acceleration below).
    """
    recs = {"warning": to_numpy(rec_warning), "nowarning": to_numpy(rec_nowarning)}
    protos = {"warning": protocol_warning, "nowarning": protocol_nowarning}
    colls = dict(zip(("warning", "nowarning"), collision_times or (None, None), strict=True))
    if axes is None:
        fig = Figure(figsize=(8.0, 5.6))
        ax_v, ax_a = fig.subplots(2, 1, sharex=True)
    else:
        ax_v, ax_a = axes
        fig = ax_v.figure

    interval = warning_interval(recs["warning"], protocol_warning)
    if interval is not None:
        for ax in (ax_v, ax_a):
            ax.axvspan(*interval, color=SHADE_COLOR, alpha=0.35, lw=0, zorder=0, gid="warning_span")

    t_max = 0.0
    for key, label, color, ls in RUN_STYLES:
        rec = recs[key]
        n = num_valid_ticks(rec)
        t, v, a = rec.t[:n], rec.ego_speed[:n], rec.ego_accel[:n]
        t_max = max(t_max, float(t[-1]))
        ax_v.plot(t, v, color=color, ls=ls, lw=1.6, label=label, gid=f"speed:{key}")
        ax_a.plot(t, a, color=color, ls=ls, lw=1.4, label=label, gid=f"accel:{key}")
        for field, _, lcolor in EVENT_LINES:
            tm = _ptime(protos[key], field)
            if happened(tm):
                for ax in (ax_v, ax_a):
                    ax.axvline(tm, color=lcolor, ls=ls, lw=1.1, alpha=0.9, gid=f"{field}:{key}")
        i_coll = collision_index(rec, colls[key])
        if i_coll is not None:
            tc = float(colls[key])
            for ax in (ax_v, ax_a):
                ax.axvline(tc, color=COLLISION_COLOR, ls=ls, lw=2.0, gid=f"collision:{key}")
            ax_v.plot(tc, v[i_coll], marker="X", ms=12, color=COLLISION_COLOR, mec="white",
                      mew=1.0, ls="none", zorder=6, gid=f"collision:{key}")  # fmt: skip

    ax_a.axhline(0.0, color="#999999", lw=0.6, zorder=0.5)
    ax_v.set_ylabel("speed (m/s)")
    ax_a.set_ylabel("long. accel. (m/s$^2$)")
    ax_a.set_xlabel("time (s)")
    ax_a.set_xlim(0.0, max(t_max, DT))
    v_top = max(float(np.max(recs[k].ego_speed[: num_valid_ticks(recs[k])])) for k in recs)
    ax_v.set_ylim(min(0.0, ax_v.get_ylim()[0]), v_top * (1.0 + SPEED_HEADROOM) + SPEED_PAD_MPS)
    lo, hi = ax_a.get_ylim()
    ax_a.set_ylim(min(lo, -MIN_ACCEL_SPAN), max(hi, MIN_ACCEL_SPAN))
    for ax in (ax_v, ax_a):
        ax.grid(alpha=0.3, lw=0.5)
        ax.tick_params(labelsize=8)

    _legend(ax_v, interval is not None,
            any(collision_index(recs[k], colls[k]) is not None for k in recs))  # fmt: skip
    if axes is not None:
        if title:
            ax_v.set_title(title, fontsize=10)
        return fig
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig
