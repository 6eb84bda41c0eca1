"""Bird's-eye views of recorded executions (:func:`bev_plot`).

This module also re-exports :func:`~lantern_jax.viz.timeline.timeline_plot`,
:func:`~lantern_jax.viz.timeline.warning_interval` and
:func:`~lantern_jax.viz.common.save_figure`; animations are in :mod:`lantern_jax.viz.animate`.

Everything here runs outside ``jit`` on concrete arrays: JAX inputs are converted to NumPy at
the start of every public function.  Frames follow :mod:`lantern_jax.core.constants` (world frame x
east / y north, yaw counter-clockwise; ego frame x forward / y right).

Record indexing: ``record`` is the :class:`~lantern_jax.sim.step.TickRecord` returned by
``rollout(..., record=True)`` with a leading time axis.  Entry ``i`` holds the state *after* tick
``i`` (time ``record.t[i]``), while ``warning_active``, ``warning_pos`` and ``waypoints`` are
what the policy read / produced *during* tick ``i``, i.e. relative to the ego pose of entry
``i - 1`` (the initial pose for ``i = 0``).  Entries after the first ``done`` are not part of the
execution and are trimmed (:func:`num_valid_ticks`).
"""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon, Wedge

from lantern_jax.core.constants import (
    CAMERA_BACK_OFFSET,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    FAMILIES,
    FRONT_CAMERA_FOV,
    KIND_PEDESTRIAN,
    KIND_STATIC,
    LIGHT_GREEN,
    LIGHT_RED,
    LIGHT_YELLOW,
    OCC_BUILDING,
    OCC_PARKED_VEHICLE,
    OCC_WALL,
    ROLE_NAMES,
)
from lantern_jax.dynamics.lights import light_states
from lantern_jax.scenarios.warnings import get_text, render_warning
from lantern_jax.viz.common import (
    COLLISION_COLOR,
    box_corners_np,
    collision_index,
    ego_frame_to_world,
    lane_polygon,
    num_valid_ticks,
    rot,
    route_point,
    save_figure,
    to_numpy,
)
from lantern_jax.viz.timeline import timeline_plot, warning_interval

__all__ = ["bev_figure", "bev_plot", "save_figure", "timeline_plot", "warning_interval"]

VIEW_HALF = 35.0  # m, half side of the BEV window centred on the ego
FRUSTUM_DRAW_RANGE = 60.0  # m, drawn length of the camera frustum (capped by sensing range)

EGO_COLOR = "#7b2cbf"
ROUTE_COLOR = "#2a9d8f"
ROLE_COLORS = ("#d62828", "#3d3d3d", "#f77f00", "#1f77b4")  # hazard, occluder, context, bg
VISIBLE_EDGE = "#00c853"
RAY_COLOR = "#606c38"
LIGHT_COLORS = {LIGHT_GREEN: "#2ecc40", LIGHT_YELLOW: "#ffdc00", LIGHT_RED: "#ff4136"}
LANE_FACE = ("#d4d4d4", "#ececec", "#e4e4e4")  # driving, shoulder, junction connector
OCCLUDER_STYLE = {  # kind -> (face, edge, hatch, label)
    OCC_BUILDING: ("#b5a48b", "#6b5d4a", "//", "building"),
    OCC_WALL: ("#8d99ae", "#4a5568", "", "wall / fence"),
    OCC_PARKED_VEHICLE: ("#5c5c5c", "#222222", "", "parked vehicle"),
}
MARKERS = (  # (params field, label, marker, colour)
    ("s_warn", "warning point", "v", "#e9c46a"),
    ("s_event", "event trigger", "D", "#f4a261"),
    ("s_conflict", "conflict point", "X", "#d62828"),
)


# ---------------------------------------------------------------------------------------------
# bird's-eye view
# ---------------------------------------------------------------------------------------------
def _draw_lanes(ax, lanes: Any) -> None:
    polys = {0: [], 1: [], 2: []}
    for i in np.nonzero(lanes.valid)[0]:
        c = lanes.center[i][lanes.point_valid[i]]
        if c.shape[0] < 2:
            continue
        k = int(lanes.kind[i]) if int(lanes.kind[i]) in polys else 0
        polys[k].append(lane_polygon(c, float(lanes.width[i])))
        if k == 2:  # junction connector: thin centre line
            ax.plot(c[:, 0], c[:, 1], color="#a0a0a0", lw=0.6, ls=":", zorder=1.2)
        elif k == 0:  # travel direction at the lane middle
            m = c.shape[0] // 2
            d = c[min(m + 1, c.shape[0] - 1)] - c[max(m - 1, 0)]
            d = 3.0 * d / max(np.linalg.norm(d), 1e-9)
            ax.quiver(
                *(c[m] - 0.5 * d),
                *d,
                color="#a8a8a8",
                angles="xy",
                scale_units="xy",
                scale=1.0,
                width=0.004,
                headwidth=4,
                zorder=1.3,
            )
    style = {
        0: dict(facecolor=LANE_FACE[0], edgecolor="#b0b0b0", linewidth=0.6, linestyle="-"),
        1: dict(facecolor=LANE_FACE[1], edgecolor="#8c8c8c", linewidth=0.9, linestyle="--"),
        2: dict(facecolor=LANE_FACE[2], edgecolor="none", linewidth=0.0, alpha=0.6),
    }
    for k, zo in ((1, 0.9), (0, 1.0), (2, 1.1)):
        if polys[k]:
            ax.add_collection(PolyCollection(polys[k], zorder=zo, **style[k]))


def _draw_occluders(ax, occluders: Any) -> None:
    """The map's static occluders (``gid="occluder:<slot>"``), styled by kind."""
    for k in np.nonzero(np.asarray(occluders.valid, bool))[0]:
        face, edge, hatch, _ = OCCLUDER_STYLE.get(int(occluders.kind[k]), OCCLUDER_STYLE[0])
        ax.add_patch(
            Polygon(
                box_corners_np(occluders.center[k], float(occluders.yaw[k]), occluders.extent[k]),
                closed=True, facecolor=face, edgecolor=edge, hatch=hatch, linewidth=0.8,
                alpha=0.95, gid=f"occluder:{k}", zorder=4,
            )
        )  # fmt: skip


def _draw_route(ax, scenario: Any) -> None:
    r, p = scenario.route, scenario.config
    v = np.asarray(r.valid, bool)
    ax.plot(r.xy[v, 0], r.xy[v, 1], color=ROUTE_COLOR, lw=2.0, alpha=0.8, zorder=2, label="route")
    for field, label, marker, color in MARKERS:
        pt = route_point(r, float(getattr(p, field)))
        if pt is not None:
            ax.plot(
                *pt,
                marker=marker,
                ms=9,
                color=color,
                mec="black",
                mew=0.8,
                ls="none",
                zorder=6,
                label=label,
            )


def _clear_axes(ax) -> None:
    """Remove the drawn artists but keep the axes' tick machinery (cheaper than ``cla``)."""
    for artist in [*ax.patches, *ax.lines, *ax.collections, *ax.texts, *ax.images]:
        artist.remove()
    if ax.get_legend() is not None:
        ax.get_legend().remove()


def bev_figure() -> tuple[Figure, Any]:
    """An empty figure laid out for :func:`bev_plot` (square axes, legend room on the right)."""
    fig = Figure(figsize=(8.2, 6.6))
    ax = fig.add_subplot()
    fig.subplots_adjust(left=0.08, right=0.76, bottom=0.08, top=0.94)
    return fig, ax


def _draw_box(ax, xy, yaw, extent, face, edge, lw, alpha, gid, zorder, heading=True) -> None:
    corners = box_corners_np(xy, yaw, extent)
    ax.add_patch(
        Polygon(
            corners,
            closed=True,
            facecolor=face,
            edgecolor=edge,
            linewidth=lw,
            alpha=alpha,
            gid=gid,
            zorder=zorder,
        )
    )
    if heading:  # front edge drawn thick to show the heading
        ax.plot(corners[[0, 3], 0], corners[[0, 3], 1], color="white", lw=1.6, zorder=zorder + 0.1)


def _draw_lights(ax, lights: Any, t: float) -> None:
    """Traffic lights at their stop lines, coloured by their state at ``t``."""
    lv = np.nonzero(lights.valid)[0]
    for n, (j, stv) in enumerate(zip(lv, np.asarray(light_states(lights, t))[lv], strict=True)):
        ax.plot(
            *lights.stop_xy[j],
            marker="o",
            ms=10,
            color=LIGHT_COLORS[int(stv)],
            mec="black",
            mew=1.0,
            ls="none",
            zorder=7,
            label="traffic light" if n == 0 else None,
        )


def _draw_frustum(ax, cam: np.ndarray, ego_yaw: float, sensing_range: float) -> None:
    """The front camera's 110-degree field of view (``gid="frustum"``)."""
    rng = min(sensing_range, FRUSTUM_DRAW_RANGE)
    half_fov = 0.5 * FRONT_CAMERA_FOV
    yaw_deg = np.degrees(ego_yaw)
    ax.add_patch(
        Wedge(
            cam,
            rng,
            yaw_deg - half_fov,
            yaw_deg + half_fov,
            facecolor="#fff3b0",
            alpha=0.35,
            edgecolor="#c9a227",
            linewidth=0.8,
            linestyle="--",
            gid="frustum",
            zorder=2.5,
        )
    )


def _draw_actors(ax, sc: Any, rec: Any, i: int, cam: np.ndarray, show_rays: bool) -> None:
    """Present actors coloured by role; visible ones outlined, with sight lines."""
    present, visible = rec.actor_present[i] & sc.actors.valid, rec.visible[i]
    axy, ayaw = rec.actor_xy[i], rec.actor_yaw[i]
    for a in np.nonzero(present)[0]:
        role = int(sc.actors.role[a])
        vis = bool(visible[a])
        _draw_box(
            ax,
            axy[a],
            float(ayaw[a]),
            sc.actors.extent[a],
            face=ROLE_COLORS[role],
            edge=VISIBLE_EDGE if vis else "black",
            lw=2.2 if vis else 0.7,
            alpha=0.9,
            gid=f"actor:{a}",
            zorder=5,
            heading=int(sc.actors.kind[a]) != KIND_STATIC and sc.actors.extent[a, 0] > 0.5,
        )
        if int(sc.actors.kind[a]) == KIND_PEDESTRIAN:  # tiny box: ring it so it can be seen
            ax.plot(
                *axy[a], marker="o", ms=11, mfc="none", mec=ROLE_COLORS[role], mew=1.5, zorder=5.4
            )
        if vis:
            if show_rays:
                ax.plot(
                    [cam[0], axy[a, 0]],
                    [cam[1], axy[a, 1]],
                    color=RAY_COLOR,
                    lw=0.9,
                    ls="--",
                    alpha=0.85,
                    zorder=5.3,
                )
            ax.plot(*axy[a], marker="o", ms=3, color=VISIBLE_EDGE, zorder=5.5)


def _draw_warning(ax, fig: Figure, text: str, grounded_xy: np.ndarray | None) -> None:
    """The active warning text (wrapped to the axes width, ``gid="warning"``) and its grounded
    position (none for a text that states no position)."""
    if grounded_xy is not None:
        ax.plot(
            *grounded_xy,
            marker="x",
            ms=10,
            mew=2.2,
            color="#ff006e",
            ls="none",
            zorder=8,
            label="grounded position",
        )
    pos = ax.get_position()  # square axes (equal aspect): the smaller side is the width
    side_in = min(pos.width * fig.get_figwidth(), pos.height * fig.get_figheight())
    chars = max(30, int(side_in * 72.0 / (8 * 0.62)))
    ax.text(
        0.015,
        0.985,
        textwrap.fill(text, chars),
        transform=ax.transAxes,
        ha="left",
        va="top",
        fontsize=8,
        zorder=10,
        gid="warning",
        bbox=dict(boxstyle="round,pad=0.4", fc="#fffbe6", ec="#e09f3e", alpha=0.95),
    )


def _draw_collision(ax, xy: np.ndarray) -> None:
    """A red X where the ego collided (``gid="collision"``)."""
    ax.plot(*xy, marker="X", ms=16, color=COLLISION_COLOR, mec="white", mew=1.2, ls="none",
            zorder=9, gid="collision", label="collision")  # fmt: skip


def _default_title(config: Any) -> str:
    fam = FAMILIES[int(config.family)] if 0 <= int(config.family) < len(FAMILIES) else "?"
    route = "A" if bool(config.is_route_a) else "B"
    cond = "warning" if bool(config.warning_enabled) else "no warning"
    return f"{fam} route {route}, {cond}"


def _frame_view(ax, centre: np.ndarray) -> None:
    ax.set_xlim(centre[0] - VIEW_HALF, centre[0] + VIEW_HALF)
    ax.set_ylim(centre[1] - VIEW_HALF, centre[1] + VIEW_HALF)
    ax.set_aspect("equal", adjustable="box")
    ax.set_facecolor("#f7f7f2")
    ax.set_xlabel("x (m, east)")
    ax.set_ylabel("y (m, north)")
    ax.tick_params(labelsize=7)


def bev_plot(
    scenario: Any,
    record: Any,
    tick_index: int,
    ax: Any = None,
    title: str | None = None,
    show_rays: bool = True,
    collision_time: float | None = None,
) -> Figure:
    """Bird's-eye view of one execution at one recorded tick.

    Draws the lanes (driving lanes as grey strips with their travel direction, shoulders dashed,
    junction connectors faint with a dotted centre line), the ego route with the warning point,
    event trigger and conflict point (route arcs ``s_warn``, ``s_event``, ``s_conflict``), the
    ego's past trajectory and planned waypoints, the map's static occluders (buildings hatched
    brown, walls slate, parked vehicles dark grey; ``gid="occluder:<slot>"``), the ego box and
    its 110-degree camera frustum,
    the present actors coloured by role (hazard red, occluder dark grey, context orange,
    background blue; a white front edge shows the heading), visible actors outlined in green
    with sight lines from the camera, the traffic lights at their stop lines (colour = state),
    and the active warning text (wrapped to the axes width; ``gid="warning"``) with its grounded
    position.  The view is centred on the ego (70 m window).  Patches: one ``Polygon`` per
    present actor (``gid="actor:<slot>"``) and one for the ego (``gid="ego"``); the frustum is a
    ``Wedge`` (``gid="frustum"``); lanes are collections.  With ``collision_time``, from the
    collision's tick on a red X (``gid="collision"``) marks where the ego was when it collided.

    Args:
        scenario: the :class:`~lantern_jax.types.world.Scenario` of the execution (static data:
            lanes, occluders, route, lights, extents, roles, markers, text id, initial ego
            pose).
        record: its ``TickRecord`` with a leading time axis (``rollout(..., record=True)``).
        tick_index: entry of ``record`` to draw (negative counts from the end); entries past the
            end of the execution show its last tick.
        ax: axes to draw into (cleared first); a new figure is made when None.  The legend is
            placed to the right of the axes.
        title: title prefix; defaults to the family, route and condition.
        show_rays: draw sight lines from the camera to every visible actor's centre.
        collision_time: s, the execution's first collision (``telemetry.collision.t_collision``
            of its final state); None, NaN or a time that never happened: no collision.

    Returns:
        The figure holding the axes.
    """
    sc, rec = to_numpy(scenario), to_numpy(record)
    n_all = int(rec.t.shape[0])
    if not -n_all <= tick_index < n_all:
        raise IndexError(f"tick_index: {tick_index} outside the record's {n_all} entries")
    i = min(tick_index % n_all, num_valid_ticks(rec) - 1)
    if ax is None:
        fig, ax = bev_figure()
    else:
        fig = ax.figure
        _clear_axes(ax)

    ego_xy, ego_yaw = rec.ego_xy[i], float(rec.ego_yaw[i])
    if i > 0:
        prev_xy, prev_yaw = rec.ego_xy[i - 1], float(rec.ego_yaw[i - 1])
    else:
        prev_xy, prev_yaw = sc.ego0.xy, float(sc.ego0.yaw)
    t = float(rec.t[i])
    _draw_lanes(ax, sc.lanes)
    _draw_occluders(ax, sc.occluders)
    _draw_route(ax, sc)
    _draw_lights(ax, sc.lights, t)
    # ego trail and planned waypoints (the plan was made at the previous tick's pose)
    ax.plot(
        rec.ego_xy[: i + 1, 0], rec.ego_xy[: i + 1, 1], color=EGO_COLOR, lw=1.0, alpha=0.5, zorder=3
    )
    wps = ego_frame_to_world(rec.waypoints[i], prev_xy, prev_yaw)
    ax.plot(wps[:, 0], wps[:, 1], ".", color=EGO_COLOR, ms=3.5, zorder=3.5, label="waypoints")
    fwd, _ = rot(ego_yaw)
    cam = np.asarray(ego_xy, float) - CAMERA_BACK_OFFSET * fwd
    _draw_frustum(ax, cam, ego_yaw, float(sc.config.sensing_range))
    _draw_actors(ax, sc, rec, i, cam, show_rays)
    ego_extent = (EGO_HALF_LENGTH, EGO_HALF_WIDTH)
    _draw_box(ax, ego_xy, ego_yaw, ego_extent, face=EGO_COLOR, edge="black", lw=1.0, alpha=0.95,
              gid="ego", zorder=5.2)  # fmt: skip
    ax.plot(*cam, marker="^", ms=4, color="black", zorder=5.6)
    if bool(rec.warning_active[i]):
        text_id = int(rec.warning_text_id[i])
        text = render_warning(text_id, rec.warning_pos[i])
        stated = get_text(text_id).has_position
        where = ego_frame_to_world(rec.warning_pos[i], prev_xy, prev_yaw)[0] if stated else None
        _draw_warning(ax, fig, text, where)
    i_coll = collision_index(rec, collision_time)
    if i_coll is not None and i >= i_coll:
        _draw_collision(ax, rec.ego_xy[i_coll])
    _frame_view(ax, ego_xy)
    title = _default_title(sc.config) if title is None else title
    ax.set_title(f"{title}  |  t = {t:.2f} s, v = {float(rec.ego_speed[i]):.1f} m/s", fontsize=10)
    _bev_legend(ax)
    return fig


def _bev_legend(ax) -> None:
    handles = [
        Line2D([], [], marker="s", ls="none", ms=8, color=EGO_COLOR, label="ego"),
        *(
            Line2D([], [], marker="s", ls="none", ms=8, color=face, mec=edge, label=label)
            for face, edge, _, label in OCCLUDER_STYLE.values()
        ),
        *(
            Line2D([], [], marker="s", ls="none", ms=8, color=c, label=n)
            for c, n in zip(ROLE_COLORS, ROLE_NAMES, strict=True)
        ),
        Line2D(
            [],
            [],
            marker="s",
            ls="none",
            ms=8,
            mfc="white",
            mec=VISIBLE_EDGE,
            mew=2,
            label="visible",
        ),
        Line2D([], [], color=RAY_COLOR, ls="--", label="sight line"),
    ]
    handles += ax.get_legend_handles_labels()[0]
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=7,
        frameon=False,
        borderaxespad=0.0,
    )
