"""Bird's-eye views, condition timelines, animations and PNG output of recorded executions."""

from __future__ import annotations

import types
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import HORIZON, MODE_COOP, select
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon, Rectangle
from matplotlib.text import Text
from PIL import Image

from lantern_jax.scenarios.families import build_pair, sample_params
from lantern_jax.scenarios.warnings import render_warning
from lantern_jax.viz import (
    bev_plot,
    num_valid_ticks,
    save_animation,
    save_figure,
    timeline_plot,
    warning_interval,
)

NUM_TICKS = HORIZON  # ticks of every recorded run (the shared runner's)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def pe_runs(sim):
    """A PE pair rolled out with the cooperative policy in both conditions (the session's
    shared batch runner: no compile of its own)."""
    world, _, _ = build_pair(sample_params("PE", np.random.default_rng(0), "clear_day"))
    world_nw = world.replace(config=world.config.replace(warning_enabled=jnp.asarray(False)))
    final, rec = sim.batch([world, world_nw], MODE_COOP)
    return types.SimpleNamespace(
        world=world,
        world_nw=world_nw,
        rec_w=select(rec, 0),
        rec_nw=select(rec, 1),
        proto_w=select(final.protocol, 0),
        proto_nw=select(final.protocol, 1),
    )


def _assert_png(path, min_bytes=10_000):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > min_bytes
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.format == "PNG" and min(im.size) >= 300


def _actor_patches(ax):
    """Actor and ego patches (occluders of the map are drawn as patches too, gid occluder:k)."""
    return [
        p for p in ax.patches
        if isinstance(p, (Rectangle, Polygon)) and not str(p.get_gid()).startswith("occluder:")
    ]  # fmt: skip


def _occluder_patches(ax):
    return [p for p in ax.patches if str(p.get_gid()).startswith("occluder:")]


def _norm(s: str) -> str:
    return " ".join(s.split())


def test_bev_with_active_warning(pe_runs, tmp_path):
    rec, world = pe_runs.rec_w, pe_runs.world
    active = np.nonzero(np.asarray(rec.warning_active[: num_valid_ticks(rec)]))[0]
    assert active.size > 0, "the warning run never delivered a warning"
    t = int(active[active.size // 2])
    fig = bev_plot(world, rec, t)
    ax = fig.axes[0]

    expected = render_warning(int(world.config.text_id), rec.warning_pos[t])
    texts = [_norm(x.get_text()) for x in fig.findobj(Text)]
    assert expected in texts

    present = np.asarray(rec.actor_present[t]) & np.asarray(world.actors.valid)
    patches = _actor_patches(ax)
    assert len(patches) == int(present.sum()) + 1
    gids = sorted(p.get_gid() for p in patches)
    assert gids == sorted(["ego"] + [f"actor:{a}" for a in np.nonzero(present)[0]])
    # the map's occluders (the parked truck hiding the pedestrian, ...) are drawn, one each
    occ = np.nonzero(np.asarray(world.occluders.valid))[0]
    assert len(occ) >= 1
    assert sorted(p.get_gid() for p in _occluder_patches(ax)) == sorted(
        f"occluder:{k}" for k in occ
    )

    # equal aspect, ego-centred window, time and speed in the title
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert x1 - x0 == pytest.approx(70.0) and y1 - y0 == pytest.approx(70.0)
    assert 0.5 * (x0 + x1) == pytest.approx(float(rec.ego_xy[t, 0]), abs=1e-3)
    assert ax.get_aspect() == 1.0
    assert f"t = {float(rec.t[t]):.2f} s" in ax.get_title()

    out = save_figure(fig, tmp_path / "nested" / "bev.png")
    _assert_png(out)
    assert [p.name for p in out.parent.iterdir()] == ["bev.png"]  # no temporary left behind


def test_bev_redraw_on_given_axes(pe_runs):
    rec, world = pe_runs.rec_w, pe_runs.world
    fig = bev_plot(world, rec, 0)
    ax = fig.axes[0]
    fig2 = bev_plot(world, rec, NUM_TICKS - 1, ax=ax, show_rays=False, title="again")
    assert fig2 is fig and len(fig.axes) == 1
    present = np.asarray(rec.actor_present[NUM_TICKS - 1]) & np.asarray(world.actors.valid)
    assert len(_actor_patches(ax)) == int(present.sum()) + 1
    assert ax.get_title().startswith("again")
    # no warning at the end of the run: no warning text box
    assert not any(t.get_gid() == "warning" for t in ax.texts)
    with pytest.raises(IndexError):
        bev_plot(world, rec, NUM_TICKS)


def test_timeline(pe_runs, tmp_path):
    fig = timeline_plot(
        pe_runs.rec_w, pe_runs.rec_nw, pe_runs.proto_w, pe_runs.proto_nw, title="PE coop"
    )
    assert len(fig.axes) == 2
    ax_v, ax_a = fig.axes
    for ax, kind in ((ax_v, "speed"), (ax_a, "accel")):
        gids = {ln.get_gid() for ln in ax.lines}
        assert {f"{kind}:warning", f"{kind}:nowarning"} <= gids
        assert all(isinstance(ln, Line2D) for ln in ax.lines)
    speed_w = next(ln for ln in ax_v.lines if ln.get_gid() == "speed:warning")
    n = num_valid_ticks(pe_runs.rec_w)
    np.testing.assert_allclose(speed_w.get_ydata(), np.asarray(pe_runs.rec_w.ego_speed[:n]))

    for key, proto in (("warning", pe_runs.proto_w), ("nowarning", pe_runs.proto_nw)):
        line = next(ln for ln in ax_v.lines if ln.get_gid() == f"t_event:{key}")
        assert float(line.get_xdata()[0]) == pytest.approx(float(proto.t_event))
    start, end = warning_interval(pe_runs.rec_w, pe_runs.proto_w)
    assert start == pytest.approx(float(pe_runs.proto_w.t_warn_point))
    assert end == pytest.approx(float(pe_runs.proto_w.t_warn_off))
    assert warning_interval(pe_runs.rec_nw, pe_runs.proto_nw) is None
    assert any(p.get_gid() == "warning_span" for p in ax_v.patches)
    _assert_png(save_figure(fig, tmp_path / "timeline.png"))


def test_gif(pe_runs, tmp_path):
    out = save_animation(pe_runs.world, pe_runs.rec_w, tmp_path / "bev.gif", fps=10, stride=30)
    assert out.exists() and out.stat().st_size > 10_000
    with Image.open(out) as im:
        assert im.format == "GIF"
        assert im.n_frames >= 10
    assert [p.name for p in tmp_path.iterdir()] == ["bev.gif"]


def test_mp4_request(pe_runs, tmp_path):
    short = jax.tree.map(lambda x: x[:12], pe_runs.rec_w)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = save_animation(pe_runs.world, short, tmp_path / "clip.mp4", stride=6)
    assert out.exists() and out.suffix in (".mp4", ".gif")
    assert out.stat().st_size > 1000


def test_num_valid_ticks():
    rec = types.SimpleNamespace(done=np.array([False, False, True, True]))
    assert num_valid_ticks(rec) == 3
    rec = types.SimpleNamespace(done=np.zeros(5, bool))
    assert num_valid_ticks(rec) == 5


def test_timeline_axes_show_a_constant_speed_and_keep_ripple_small(pe_runs):
    """A run at one constant speed and a ripple of 1e-3 m/s^2: the speed line sits inside the
    frame (not on its edge), the acceleration axis spans at least +-1 m/s^2 (ripple is not drawn
    as braking), and every line style drawn has a legend entry."""
    n = num_valid_ticks(pe_runs.rec_w)
    flat = pe_runs.rec_w.replace(
        ego_speed=jnp.full_like(pe_runs.rec_w.ego_speed, 8.0),
        ego_accel=jnp.asarray(1e-3 * np.sin(np.arange(len(pe_runs.rec_w.ego_accel))),
                              jnp.float32),
    )  # fmt: skip
    fig = timeline_plot(flat, flat, pe_runs.proto_w, pe_runs.proto_nw)
    ax_v, ax_a = fig.axes
    lo, hi = ax_v.get_ylim()
    assert lo <= 0.0 and hi > 8.0 + 0.5, (lo, hi)
    lo, hi = ax_a.get_ylim()
    assert lo <= -1.0 and hi >= 1.0, (lo, hi)
    labels = [t.get_text() for t in ax_v.get_legend().get_texts()]
    styles = {ln.get_linestyle() for ln in ax_v.get_legend().get_lines()}
    assert {"-", "--"} <= styles and "transition, no warning" in labels
    assert n > 0
