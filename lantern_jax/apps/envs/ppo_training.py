"""Train the ``ppo`` policy with brax's PPO on the benchmark environment.

::

    lantern-jax train --config configs/train_ppo.toml      # the [ppo] table: this module's train
    python -m lantern_jax.apps.envs.ppo_training --minutes 28 --out runs/ppo \
        --checkpoint runs/ppo/ppo_lantern.msgpack         # the same, with options

``brax.training.agents.ppo.train`` runs unchanged on :class:`~lantern_jax.apps.envs.LanternEnv`,
wrapped by :func:`~lantern_jax.apps.envs.wrap_for_training` (new scenes at every reset).  After
every evaluation the current policy is written to the checkpoint (so a run cut short keeps its
latest policy) and a row is appended to the learning curve ``<out>/learning_curve.csv``; training
stops at the last evaluation before the wall-clock budget ``--minutes``.  The curve is plotted to
``<out>/learning_curve.png``.  Evaluate the result like any policy::

    LANTERN_JAX_PPO_CHECKPOINT=<checkpoint> lantern-jax evaluate --policy ppo,ego
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import jax
import numpy as np
from brax.training.agents.ppo import train as ppo

from lantern_jax.apps.dataset.record import data_settings
from lantern_jax.apps.envs import LanternEnv, build_bank, wrap_for_training
from lantern_jax.apps.envs.bank import TRAIN_SEED
from lantern_jax.policies.learned_ppo import save_checkpoint

CURVE_COLUMNS = ("env_steps", "seconds", "eval_return", "eval_return_std", "eval_progress",
                 "eval_gate_failure", "eval_completed", "eval_length")  # fmt: skip

#: PPO settings of the shipped policy (brax's names).
PPO_SETTINGS = dict(
    num_envs=256,
    batch_size=256,
    num_minibatches=8,
    unroll_length=20,
    num_updates_per_batch=4,
    discounting=0.99,
    learning_rate=3e-4,
    entropy_cost=1e-3,
    reward_scaling=10.0,
    normalize_observations=True,
    episode_length=1000,
    num_eval_envs=128,
    deterministic_eval=True,
    clipping_epsilon=0.2,
    gae_lambda=0.95,
    max_grad_norm=1.0,
)


class _OutOfTime(Exception):
    """Raised from the progress callback once the wall-clock budget is spent."""


def _plot(curve: list[dict], path: Path) -> None:
    # deferred: matplotlib only when a curve is drawn
    import matplotlib

    matplotlib.use("Agg")
    # deferred: matplotlib only when a curve is drawn
    import matplotlib.pyplot as plt

    steps = np.asarray([r["env_steps"] for r in curve]) / 1e6
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ret = np.asarray([r["eval_return"] for r in curve])
    std = np.asarray([r["eval_return_std"] for r in curve])
    ax[0].plot(steps, ret, marker="o")
    ax[0].fill_between(steps, ret - std, ret + std, alpha=0.2)
    ax[0].set_xlabel("environment steps (millions)")
    ax[0].set_ylabel("evaluation return (route score; -1 = gate failed)")
    ax[1].plot(steps, [r["eval_progress"] for r in curve], label="route completion P")
    ax[1].plot(steps, [r["eval_gate_failure"] for r in curve], label="gate failure rate")
    ax[1].plot(steps, [r["eval_completed"] for r in curve], label="completed cleanly")
    ax[1].set_xlabel("environment steps (millions)")
    ax[1].legend()
    fig.suptitle("PPO on the lantern environment (deterministic evaluation episodes)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def train(
    out: str | Path,
    checkpoint: str | Path,
    minutes: float = 28.0,
    num_timesteps: int = 200_000_000,
    num_evals: int = 40,
    pairs_per_family: int = 16,
    seed: int = 0,
    bank_seed: int = TRAIN_SEED,
    **overrides,
) -> list[dict]:
    """Run PPO until ``num_timesteps`` or the wall-clock budget; returns the learning curve.

    Args:
        out: folder for the learning curve (CSV and PNG).
        checkpoint: file the policy is written to after every evaluation.
        minutes: wall-clock budget, compile included.
        num_timesteps: PPO's step budget (the clock usually stops it first).
        num_evals: evaluations spread over ``num_timesteps``.
        pairs_per_family: training scenes per family (three executions each).
        seed: PPO seed.
        bank_seed: seed of the training scenes.
        **overrides: replace entries of :data:`PPO_SETTINGS`.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    settings = {**PPO_SETTINGS, **overrides}
    # the actors' rule the shipped policy was trained under (apps.dataset.record.DATA_ACTORS)
    env = LanternEnv(build_bank(pairs_per_family, bank_seed), data_settings())
    curve: list[dict] = []
    meta = dict(settings=settings, pairs_per_family=pairs_per_family, bank_seed=bank_seed,
                seed=seed)  # fmt: skip

    def on_eval(step: int, metrics) -> None:
        m = {k: float(np.asarray(v)) for k, v in metrics.items()}
        length = max(m.get("eval/avg_episode_length", 1.0), 1.0)
        row = dict(
            env_steps=int(step),
            seconds=round(time.perf_counter() - t0, 1),
            eval_return=m.get("eval/episode_reward", np.nan),
            eval_return_std=m.get("eval/episode_reward_std", np.nan),
            eval_progress=m.get("eval/episode_progress", np.nan),
            eval_gate_failure=m.get("eval/episode_gate_failure", np.nan),
            eval_completed=m.get("eval/episode_completed", np.nan),
            eval_length=length,
        )
        curve.append(row)
        last = curve[-1]["seconds"] - (curve[-2]["seconds"] if len(curve) > 1 else 0.0)
        with open(out / "learning_curve.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=CURVE_COLUMNS)
            w.writeheader()
            w.writerows(curve)
        print(f"[ppo] {row}", flush=True)
        if row["seconds"] + last > 60.0 * minutes:  # the next evaluation would be too late
            raise _OutOfTime

    def on_params(step: int, make_policy, params) -> None:
        normalizer, policy = params[0], params[1]
        save_checkpoint(checkpoint, normalizer.mean, normalizer.std, policy["params"],
                        {**meta, "env_steps": int(step),
                         "seconds": round(time.perf_counter() - t0, 1)})  # fmt: skip

    try:
        ppo.train(
            env,
            num_timesteps=num_timesteps,
            num_evals=num_evals,
            seed=seed,
            wrap_env_fn=wrap_for_training,
            progress_fn=on_eval,
            policy_params_fn=on_params,
            **settings,
        )
    except _OutOfTime:
        pass
    if curve:
        _plot(curve, out / "learning_curve.png")
    return curve


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m lantern_jax.apps.envs.ppo_training",
        allow_abbrev=False,
        description="Train the ppo policy on the lantern environment.",
    )
    p.add_argument("--out", default="runs/ppo", help="folder for the learning curve")
    p.add_argument(
        "--checkpoint",
        default="runs/ppo/ppo_lantern.msgpack",
        help="checkpoint file (rewritten after every evaluation)",
    )
    p.add_argument("--minutes", type=float, default=28.0, help="wall-clock budget")
    p.add_argument("--num-timesteps", type=int, default=200_000_000)
    p.add_argument("--num-evals", type=int, default=40)
    p.add_argument("--pairs-per-family", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)  # fmt: skip
    print(f"[ppo] devices: {jax.devices()}", flush=True)
    train(args.out, args.checkpoint, args.minutes, args.num_timesteps, args.num_evals,
          args.pairs_per_family, args.seed)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
