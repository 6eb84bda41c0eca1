"""Why gradient descent does or does not reach a failure: the descent of one stress cell traced
step by step.

Runs the stress search's gradient method (Adam on the surrogate from the benchmark's own scene,
the adversary space of :mod:`bench_stress_dims`) on one policy and family and records, per
restart and step, what the search itself does not keep:

* the surrogate's two parts (the policy's soft collision margin, the expert's plausibility
  hinge) and the norm of each part's pathwise gradient, and the cosine between the two
  gradients (a descent that moves the expert as it moves the policy shows as a cosine near -1:
  the parts cancel);
* where the policy part's gradient lies: per actor slot, per channel (acceleration, lateral
  rate) and per second of the track (a gradient that lives only in the last knots, or only in
  the channel that cannot bring the hazard into the ego's path, carries nothing toward a
  collision);
* the share of the iterate's normalised actions at their bound (``|value| > 0.99``: the squashing
  to ``[-1, 1]`` leaves them no gradient);
* the hard verification of the iterate: the pair CUS, the policy's least margin to the watched
  actors, the expert's least distance and the gates it failed, the adversary's plausibility
  (its longest stop in the ego's path, its time off the road), whether it is a plausible
  failure.

With ``--draws N`` it also verifies ``N`` uniform draws of the space (``draws.csv``): the
failures sampling finds, their gates and margins, beside the ones descent is steered toward.

Writes ``trace.csv`` (one row per restart and step), ``knots.csv`` (the policy gradient's mass
per knot, at the first and last step) and ``trace.png`` into ``--out``::

    python benchmarks/trace_descent.py --policy coop --family RTY --space 128 --restarts 8 \\
        --steps 16 --out benchmarks/results/trace_descent_coop_rty
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import optax
import pandas as pd
from bench_stress import pick_pair
from bench_stress_dims import SPACES

from lantern_jax.apps.stress import report
from lantern_jax.apps.stress.objective import EXPERT, POLICY, part_samples, parts_of
from lantern_jax.apps.stress.search import initial_points
from lantern_jax.apps.stress.verify import Verifier
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite

AT_BOUND = 0.99  # normalised action beyond which the squashing leaves it (almost) no gradient


def _norm(x: np.ndarray) -> np.ndarray:
    return np.linalg.norm(x.reshape(len(x), -1), axis=1)


def _cosine(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cosine in float64; NaN where either gradient is (numerically) zero."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    na, nb = _norm(a), _norm(b)
    ok = (na > 1e-12) & (nb > 1e-12)
    return np.where(ok, np.sum(a * b, axis=1) / np.where(ok, na * nb, 1.0), np.nan)


def trace(problem, verifier: Verifier, restarts: int, steps: int, seed: int, lr: float,
          init_z: float) -> tuple[pd.DataFrame, np.ndarray]:  # fmt: skip
    """Adam on the surrogate (the pathwise gradient, both parts summed, as the gradient search
    runs it) with every part recorded.  Returns the per-(restart, step) table and the policy
    gradient per (step, restart, slot, channel, knot)."""
    space = problem.space
    shape = (len(space.slots), 2, space.knots)
    samples = part_samples(problem)
    parts = parts_of(problem)
    z = initial_points(problem, restarts, seed, init_z)
    opt = optax.adam(lr)
    state = opt.init(z)
    rows, grads = [], []
    for step in range(steps):
        t0 = time.perf_counter()
        pts = jnp.asarray(z, jnp.float32)[:, None, :]
        part = {p: samples(p, pts) for p in parts}
        v_pol, g_pol = (np.asarray(x)[:, 0] for x in part[POLICY])
        if EXPERT in part:
            v_exp, g_exp = (np.asarray(x)[:, 0] for x in part[EXPERT])
        else:
            v_exp, g_exp = np.zeros_like(v_pol), np.zeros_like(g_pol)
        g = np.nan_to_num(g_pol + g_exp, nan=0.0, posinf=0.0, neginf=0.0)
        values = np.asarray(space.values(z))
        verdict = verifier(values)
        gp = g_pol.reshape(restarts, *shape)
        grads.append(gp)
        by_slot = np.sqrt(np.sum(gp**2, axis=(2, 3)))  # (R, slots)
        by_channel = np.sqrt(np.sum(gp**2, axis=(1, 3)))  # (R, 2)
        for r in range(restarts):
            rows.append(dict(
                step=step, restart=r,
                surrogate=float(v_pol[r] + v_exp[r]), policy_part=float(v_pol[r]),
                expert_part=float(v_exp[r]),
                grad_norm=float(np.linalg.norm(g[r])),
                policy_grad_norm=float(np.linalg.norm(g_pol[r])),
                expert_grad_norm=float(np.linalg.norm(g_exp[r])),
                cos_policy_expert=float(_cosine(g_pol[r:r + 1], g_exp[r:r + 1])[0]),
                accel_share=float(by_channel[r, 0] ** 2 / max(np.sum(by_channel[r] ** 2), 1e-30)),
                hazard_share=float(by_slot[r, 0] ** 2 / max(np.sum(by_slot[r] ** 2), 1e-30)),
                at_bound=float(np.mean(np.abs(values[r]) > AT_BOUND)),
                hard_cus=float(verdict.cus[r]),
                policy_failed=bool(verdict.policy_failed[r]),
                plausible_failure=bool(verdict.failed[r]),
                expert_ok=bool(verdict.expert_ok[r]),
                expert_failed_gates=" ".join(verdict.expert_failed_gates[r]),
                adversary_plausible=bool(verdict.plausible[r]),
                adversary_stop_s=float(verdict.stop_s[r]),
                adversary_off_road_s=float(verdict.off_road_s[r]),
                policy_margin_m=float(verdict.margin_m[r]),
                expert_dist_m=float(verdict.expert_dist_m[r]),
                step_s=time.perf_counter() - t0,
            ))  # fmt: skip
        updates, state = opt.update(g, state, z)
        z = np.asarray(optax.apply_updates(z, updates), np.float32)
        med = pd.DataFrame(rows[-restarts:]).median(numeric_only=True)
        found = sum(r["plausible_failure"] for r in rows[-restarts:])
        print(f"step {step:2d}: surrogate {med.surrogate:7.3f}  |g_policy| "
              f"{med.policy_grad_norm:9.3g}  |g_expert| {med.expert_grad_norm:9.3g}  cos "
              f"{med.cos_policy_expert:+.2f}  margin {med.policy_margin_m:5.2f} m  expert "
              f"{med.expert_dist_m:5.2f} m  CUS {med.hard_cus:5.1f}  failures {found}  "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)  # fmt: skip
    return pd.DataFrame(rows), np.stack(grads)


def draws(problem, verifier: Verifier, n: int, seed: int) -> pd.DataFrame:
    """``n`` uniform draws of the space, verified: what the failures that sampling finds look
    like (the gates the policy failed, its margin to the watched actors, the expert's)."""
    rng = np.random.default_rng(seed + 1000)
    values = problem.space.uniform(rng, n)
    v = verifier(values)
    return pd.DataFrame(dict(
        draw=np.arange(n), hard_cus=v.cus, policy_failed=v.policy_failed,
        policy_failed_gates=[" ".join(g) for g in v.failed_gates],
        policy_margin_m=v.margin_m, expert_dist_m=v.expert_dist_m, expert_ok=v.expert_ok,
        expert_failed_gates=[" ".join(g) for g in v.expert_failed_gates],
        adversary_plausible=v.plausible, plausible_failure=v.failed,
    ))  # fmt: skip


def knot_profile(grads: np.ndarray, knot_s: float) -> pd.DataFrame:
    """The policy gradient's squared norm per knot (all slots and channels), as a share of its
    total, median over restarts, at the first and the last step."""
    mass = np.sum(grads**2, axis=(2, 3))  # (steps, R, knots)
    share = mass / np.maximum(np.sum(mass, axis=2, keepdims=True), 1e-30)
    k = grads.shape[-1]
    return pd.DataFrame(dict(
        knot=np.arange(k), t_s=np.arange(k) * knot_s,
        first_step=np.median(share[0], axis=0), last_step=np.median(share[-1], axis=0),
    ))  # fmt: skip


def figure(df: pd.DataFrame, knots: pd.DataFrame, title: str, path: Path) -> None:
    """Medians over restarts per step (quartiles shaded): the two parts' gradient norms, their
    cosine, the hard margins and CUS; and the policy gradient's mass over the track's seconds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = df.groupby("step")
    fig, ax = plt.subplots(1, 5, figsize=(20, 3.8))

    def band(a, col, label, color):
        q = g[col].quantile([0.25, 0.5, 0.75]).unstack()
        a.plot(q.index, q[0.5], color=color, label=label, marker=".")
        a.fill_between(q.index, q[0.25], q[0.75], color=color, alpha=0.15)

    band(ax[0], "policy_grad_norm", "policy part", "C0")
    band(ax[0], "expert_grad_norm", "expert part", "C1")
    ax[0].set_yscale("symlog", linthresh=1e-6)
    ax[0].set_ylabel("|gradient| of the surrogate part")
    if df["cos_policy_expert"].notna().any():
        band(ax[1], "cos_policy_expert", "cos(policy, expert)", "C2")
    else:
        ax[1].text(0.5, 0.5, "the expert part's gradient is 0\n(its hinge is inactive)",
                   ha="center", va="center", transform=ax[1].transAxes)  # fmt: skip
    ax[1].set_ylim(-1.05, 1.05)
    ax[1].set_ylabel("cosine of the two parts' gradients")
    band(ax[2], "policy_margin_m", "policy's least margin", "C0")
    band(ax[2], "expert_dist_m", "expert's least distance", "C1")
    ax[2].set_ylabel("m (hard rollout, watched actors)")
    band(ax[3], "hard_cus", "pair CUS", "C3")
    ax[3].set_ylabel("hard CUS of the iterate")
    for a in ax[:4]:
        a.set_xlabel("Adam step")
        a.legend(fontsize=8)
    width = float(knots["t_s"].iloc[1]) if len(knots) > 1 else 0.5
    ax[4].bar(knots["t_s"], knots["first_step"], width=width, color="C0", alpha=0.6,
              label="first step")  # fmt: skip
    ax[4].step(knots["t_s"], knots["last_step"], where="mid", color="C3", label="last step")
    ax[4].set_xlabel("s of the adversary's track")
    ax[4].set_ylabel("share of the policy part's |gradient|²")
    ax[4].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="coop")
    ap.add_argument("--family", default="RTY")
    ap.add_argument("--space", default="128", help=f"of {', '.join(SPACES)}")
    ap.add_argument("--restarts", type=int, default=8)
    ap.add_argument("--steps", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--horizon-s", type=float, default=20.0)
    ap.add_argument("--draws", type=int, default=0,
                    help="also verify this many uniform draws (draws.csv): what sampling finds")
    ap.add_argument("--out", default="runs/trace_descent")
    ap.add_argument("--pair", default=None, help="the pair (default: the family's first the "
                    "expert drives with margin)")
    ap.add_argument("--watch", default="hazard", choices=("hazard", "all"),
                    help="the actors the surrogate's margin and the verification watch: the "
                    "hazard and the tracked ones, or every actor of the scene")
    ap.add_argument("--plot-only", action="store_true",
                    help="draw trace.png again from the CSV files in --out, run nothing")
    args = ap.parse_args()
    if args.plot_only:
        out = Path(args.out)
        df = pd.read_csv(out / "trace.csv")
        title = (f"{args.policy} {args.family} ({df.pair.iloc[0]}), {args.space} dimensions, "
                 f"{df.restart.nunique()} restarts: gradient descent from the nominal scene")
        figure(df, pd.read_csv(out / "knots.csv"), title, out / "trace.png")
        return
    if args.space not in SPACES:
        ap.error(f"--space: {args.space} not of {', '.join(SPACES)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    actors, knots, knot_s, background = SPACES[args.space]
    cfg = report.StressConfig(
        space="adversary", actors=actors, knots=knots, knot_s=knot_s, background=background,
        restarts=args.restarts, horizon_s=args.horizon_s, methods=("gradient",), watch=args.watch,
    ).resolved()  # fmt: skip
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f} (1 min); {args.policy} {args.family}, space {args.space}, "
          f"{args.restarts} restarts, {args.steps} steps, lr {cfg.lr}", flush=True)  # fmt: skip
    suite = load_suite()
    policy = get_policy(args.policy)
    pair = pick_pair(suite, args.family, cfg, policy, args.pair)
    if pair is None:
        raise SystemExit(f"{args.family}: no pair the expert drives with margin")
    problem = report.make_problem(pair, policy, None, cfg, suite)
    print(f"watched slots {problem.watched}", flush=True)
    verifier = Verifier(problem, batch=args.restarts)
    t0 = time.perf_counter()
    df, grads = trace(problem, verifier, args.restarts, args.steps, args.seed, cfg.lr, cfg.init_z)
    print(f"{time.perf_counter() - t0:.0f} s in all (compiles included)")
    if args.draws:
        d = draws(problem, verifier, args.draws, args.seed)
        d.insert(0, "pair", pair.pair_id)
        d.to_csv(out / "draws.csv", index=False, float_format="%.6g")
        fail = d[d.plausible_failure]
        print(f"uniform draws: {len(d)}, policy failed {int(d.policy_failed.sum())}, plausible "
              f"failures {len(fail)}; their failed gates "
              f"{fail.policy_failed_gates.value_counts().to_dict()}; their margin to the watched "
              f"actors (median, min, max) {fail.policy_margin_m.median():.2f} / "
              f"{fail.policy_margin_m.min():.2f} / {fail.policy_margin_m.max():.2f} m; draws the "
              f"expert fails: {int((~d.expert_ok).sum())} "
              f"({d.expert_failed_gates.value_counts().to_dict()})")  # fmt: skip
    df.insert(0, "pair", pair.pair_id)
    df.to_csv(out / "trace.csv", index=False, float_format="%.6g")
    prof = knot_profile(grads, knot_s)
    prof.to_csv(out / "knots.csv", index=False, float_format="%.6g")
    title = (f"{args.policy} {args.family} ({pair.pair_id}), {problem.space.dim} dimensions, "
             f"{args.restarts} restarts: gradient descent from the nominal scene")  # fmt: skip
    figure(df, prof, title, out / "trace.png")
    first, last = df[df.step == 0], df[df.step == df.step.max()]
    for name, d in (("first step", first), ("last step", last)):
        print(f"{name}: median |g_policy| {d.policy_grad_norm.median():.3g}, |g_expert| "
              f"{d.expert_grad_norm.median():.3g}, cos {d.cos_policy_expert.median():+.2f}, "
              f"accel share {d.accel_share.median():.2f}, at bound {d.at_bound.median():.2f}, "
              f"margin {d.policy_margin_m.median():.2f} m, expert "
              f"{d.expert_dist_m.median():.2f} m, CUS {d.hard_cus.median():.1f}")  # fmt: skip
    restarts = df.groupby("restart").plausible_failure.any().sum()
    gates = df.expert_failed_gates.fillna("").value_counts().to_dict()
    print(f"plausible failures: {int(df.plausible_failure.sum())} of {len(df)} iterates; "
          f"restarts with one: {restarts}/{args.restarts}; policy failed "
          f"{int(df.policy_failed.sum())}, expert without margin {int((~df.expert_ok).sum())} "
          f"(its failed gates: {gates}), adversary implausible "
          f"{int((~df.adversary_plausible).sum())}")


if __name__ == "__main__":
    main()
