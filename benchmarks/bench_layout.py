"""Batch-major against batch-minor layout for the tick's per-actor and per-ray geometry.

The evaluation vmaps one-scenario functions over the batch with the batch as the **leading**
axis, so a per-actor array of a batch is ``(B, A)``: the contiguous (minor) axis is the 10-16
actor slots.  This script measures what putting the batch on the **minor** axis would give,
on the simulator's own geometry kernels, before anyone rewrites the tick for it:

* ``distance_to_boxes`` — one box against the actor slots (the collision and clearance
  measure; 10 slots);
* ``segments_hit_boxes`` — 9 sight lines against the actors and occluders (the visibility
  test's inner step; 18 boxes);
* ``visible_actors`` — the whole front-camera visibility of 10 actors behind 8 occluders.

Each kernel runs as ``jit(vmap(f))`` on ``(B, ...)`` inputs (batch-major, as the evaluation
does) and as ``jit(vmap(f, in_axes=-1, out_axes=-1))`` on ``(..., B)`` inputs (batch-minor as
``vmap`` spells it); the segment test also as a hand-written batch-minor function
(:func:`segments_hit_boxes_minor`: every array ``(..., B)``, the box headings' cosines and
sines given, no ``vmap``).  Each runs ``--steps`` times inside one compiled ``scan`` (the ego
nudged every step, so nothing is hoisted out of the loop), on one CPU device; every variant
computes the same values (checked).

Usage::

    python benchmarks/bench_layout.py [--batches 180 2048] [--steps 200] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("LANTERN_JAX_CPU_DEVICES", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

Array = jax.Array

from lantern_jax.maths import geometry  # noqa: E402
from lantern_jax.sensors import visibility  # noqa: E402
from lantern_jax.types.world import Occluders  # noqa: E402

A, K, P = 10, 8, 9  # actor slots, static occluders, sample points per target


def scene_inputs(rng: np.random.Generator, b: int) -> dict[str, np.ndarray]:
    """(B, ...) float32 inputs of one kernel call per scenario: an ego box, ``A`` actor boxes
    and ``K`` occluder boxes within 60 m of it, ``P`` sight-line ends."""
    f = np.float32
    return dict(
        ego_c=rng.uniform(-5, 5, (b, 2)).astype(f),
        ego_yaw=rng.uniform(-0.3, 0.3, (b,)).astype(f),
        ego_e=np.broadcast_to(np.asarray([2.4, 1.0], f), (b, 2)).copy(),
        c=rng.uniform(-60, 60, (b, A + K, 2)).astype(f),
        yaw=rng.uniform(-np.pi, np.pi, (b, A + K)).astype(f),
        e=rng.uniform(0.3, 2.5, (b, A + K, 2)).astype(f),
        ends=rng.uniform(-60, 60, (b, P, 2)).astype(f),
        present=rng.uniform(size=(b, A)) < 0.7,
    )


def kernels() -> dict[str, callable]:
    """One-scenario functions ``(inputs dict, nudge) -> output`` of the three kernels."""

    def dist(x, d):
        return geometry.distance_to_boxes(
            x["ego_c"] + d, x["ego_yaw"], x["ego_e"], x["c"][:A], x["yaw"][:A], x["e"][:A]
        )

    def segments(x, d):
        return geometry.segments_hit_boxes(x["ego_c"] + d, x["ends"], x["c"], x["yaw"], x["e"])

    def visible(x, d):
        occ = Occluders(
            center=x["c"][A:],
            yaw=x["yaw"][A:],
            extent=x["e"][A:],
            kind=jnp.zeros((K,), jnp.int32),
            valid=jnp.ones((K,), bool),
        )
        return visibility.visible_actors(
            x["ego_c"] + d, x["ego_yaw"], x["c"][:A], x["yaw"][:A], x["e"][:A], x["present"],
            90.0, 80.0, occ,
        )  # fmt: skip

    return {"distance_to_boxes": dist, "segments_hit_boxes": segments, "visible_actors": visible}


def segments_hit_boxes_minor(x: dict[str, Array], d: Array) -> Array:
    """:func:`lantern_jax.maths.geometry.segments_hit_boxes` of the ego's centre to the ``P`` ends
    against all ``N = A + K`` boxes, written for the batch on the minor axis.

    Args:
        x: the inputs of :func:`scene_inputs` with the batch moved last: ``ego_c`` (2, B),
            ``ends`` (P, 2, B), ``c`` (N, 2, B), ``e`` (N, 2, B), and ``cos``/``sin`` (N, B) of
            the box headings.
        d: () float32, m, the nudge added to the ego's position.

    Returns:
        (P, N, B) bool, segment p touches box n in scenario b.
    """
    ca, sa = x["cos"], x["sin"]
    ex, ey = x["e"][:, 0], x["e"][:, 1]  # (N, B)
    px, py = x["ego_c"][0] + d - x["c"][:, 0], x["ego_c"][1] + d - x["c"][:, 1]
    ax, ay = (px * ca + py * sa)[None], (-px * sa + py * ca)[None]  # (1, N, B)
    qx = x["ends"][:, 0, None] - x["c"][None, :, 0]  # (P, N, B)
    qy = x["ends"][:, 1, None] - x["c"][None, :, 1]
    bx, by = qx * ca + qy * sa, -qx * sa + qy * ca
    return ~geometry.segment_separated_from_box(ax, ay, bx, by, ex, ey)


def program(fn, steps: int, minor: bool):
    """``jit`` of ``steps`` calls of ``vmap(fn)`` in one scan, batch-major or batch-minor."""
    axis = -1 if minor else 0
    batched = jax.vmap(fn, in_axes=(axis, None), out_axes=axis)

    def run(x):
        def body(acc, i):
            out = batched(x, 1e-4 * i.astype(jnp.float32))
            return acc + jnp.sum(out.astype(jnp.float32)), None

        return jax.lax.scan(body, jnp.float32(0), jnp.arange(steps))[0]

    return jax.jit(run), jax.jit(batched)


def hand_program(fn, steps: int):
    """``jit`` of ``steps`` calls of the already batched ``fn`` in one scan."""

    def run(x):
        def body(acc, i):
            return acc + jnp.sum(fn(x, 1e-4 * i.astype(jnp.float32)).astype(jnp.float32)), None

        return jax.lax.scan(body, jnp.float32(0), jnp.arange(steps))[0]

    return jax.jit(run)


def timed(fn, x, repeats: int) -> float:
    """Best wall seconds of ``repeats`` calls (after one warm call)."""
    jax.block_until_ready(fn(x))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(x))
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, nargs="+", default=[180, 2048])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(
        f"device: {jax.devices()[0].device_kind} x {jax.device_count()}, {os.cpu_count()} "
        f"cores, {platform.machine()}; jax {jax.__version__}; {args.steps} calls per program"
    )
    print(f"{'kernel':<20} {'batch':>6} {'major ns/scen':>14} {'minor ns/scen':>14} "
          f"{'minor/major':>12}  minor written as")  # fmt: skip
    rng = np.random.default_rng(0)
    for b in args.batches:
        major_x = jax.tree.map(jnp.asarray, scene_inputs(rng, b))
        minor_x = jax.tree.map(lambda a: jnp.asarray(np.moveaxis(np.asarray(a), 0, -1)), major_x)
        per = 1e9 / (args.steps * b)

        def row(name, t_major, t_minor, how, b=b, per=per):
            print(
                f"{name:<20} {b:>6} {t_major * per:>14.1f} {t_minor * per:>14.1f} "
                f"{t_minor / t_major:>12.2f}  {how}",
                flush=True,
            )

        major_s = {}
        for name, fn in kernels().items():
            (maj, maj1), (mnr, mnr1) = (program(fn, args.steps, m) for m in (False, True))
            want = np.asarray(maj1(major_x, jnp.float32(0)))
            got = np.moveaxis(np.asarray(mnr1(minor_x, jnp.float32(0))), -1, 0)
            np.testing.assert_array_equal(got, want)  # the same values in either layout
            major_s[name] = timed(maj, major_x, args.repeats)
            row(name, major_s[name], timed(mnr, minor_x, args.repeats), "vmap(in_axes=-1)")
        hand_x = dict(minor_x, cos=jnp.cos(minor_x["yaw"]), sin=jnp.sin(minor_x["yaw"]))
        want = np.asarray(jax.jit(jax.vmap(kernels()["segments_hit_boxes"], (0, None)))(
            major_x, jnp.float32(0)))  # fmt: skip
        got = np.moveaxis(np.asarray(jax.jit(segments_hit_boxes_minor)(hand_x, 0.0)), -1, 0)
        np.testing.assert_array_equal(got, want)
        hand = hand_program(segments_hit_boxes_minor, args.steps)
        t = timed(hand, hand_x, args.repeats)
        row("segments_hit_boxes", major_s["segments_hit_boxes"], t, "by hand, (..., B) arrays")


if __name__ == "__main__":
    main()
