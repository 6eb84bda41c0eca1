"""What the horizon-crossing rule costs the fine-tuned model: ``learned-coop`` trained with the
paper's rule (frames whose 2.5-s horizon crosses warning onset or termination left out) and with
onset-only exclusion, over several seeds, each evaluated on the suite.

The paper leaves out every frame whose waypoint horizon crosses warning onset or termination.
Under this protocol a warning lasts from the warning point to the moment the hazard is first
seen after the event (about 1.25 s median with the expert), so that rule leaves no
warning-active frame at all in PE, VC, LWW and RWW.  This script measures whether keeping the
termination-crossing frames (``exclude_crossing = "onset"``) is what lets the fine-tuned model
use the warning::

    lantern-jax dataset --out data/lantern
    python docs/investigations/crossing_rule_seeds.py --dataset data/lantern --seeds 0 1 2

Both variants start from the same base model (``--base``, default: the shipped
``learned-base``) and use ``configs/train_coop.toml`` otherwise; ``--config
configs/train_distance.toml`` runs the same comparison for the distance-conditioned recipe (its
far counterexamples come on top of the dataset's warning-active frames counted here).  It
prints, per rule and seed, the number of training frames with an active warning, the per-family
warning gain and the overall CUS in both conditions, then the mean and spread per rule, and
writes them as CSV.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pandas as pd

from lantern_jax.apps.dataset.store import load_frames
from lantern_jax.apps.evaluation import evaluate
from lantern_jax.apps.training.behaviour_cloning import train
from lantern_jax.apps.training.config import load_config
from lantern_jax.policies.learned.checkpoint import checkpoint_policy, shipped_path

ROOT = Path(__file__).resolve().parents[2]  # the repository
RULES = ("both", "onset")


def run(dataset: str, seeds: list[int], base: str, out: Path, progress: bool,
        config: Path = ROOT / "configs" / "train_coop.toml") -> pd.DataFrame:  # fmt: skip
    """Train and evaluate every (rule, seed) with a training config; one row each."""
    rows = []
    for rule in RULES:
        active = int(
            load_frames(dataset, exclude_crossing=rule, columns=["obs.warning_active"])[
                "obs.warning_active"
            ].sum()
        )
        for seed in seeds:
            name = f"{config.stem.removeprefix('train_')}-{rule}-s{seed}"
            cfg = load_config(
                config, name=name, dataset=dataset,
                out=str(out / name), init_from=base, seed=seed, exclude_crossing=rule,
            )  # fmt: skip
            summary = train(cfg, progress=progress)
            pol = checkpoint_policy(summary["model"], name)
            fam = evaluate([pol], progress=progress).family_table
            fam = fam.drop(columns="model").set_index("condition")
            row = {"rule": rule, "seed": seed, "warning_frames": active,
                   "val_l1_m": summary["best_val_l1_m"]}  # fmt: skip
            gain = fam.loc["warning gain"]
            row.update({f"gain {c}": float(gain[c]) for c in gain.index})
            row["CUS warning"] = float(fam.loc["warning", "Overall"])
            row["CUS no-warning"] = float(fam.loc["no-warning", "Overall"])
            rows.append(row)
            print(pd.DataFrame([row]).to_string(index=False, float_format=lambda x: f"{x:.1f}"))
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", default="data/lantern")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--base", default=str(shipped_path("learned-base")))
    ap.add_argument(
        "--config",
        type=Path,
        default=ROOT / "configs" / "train_coop.toml",
        help="training config of both variants (default: configs/train_coop.toml)",
    )
    ap.add_argument("--csv", default="crossing_rule_seeds.csv")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        df = run(a.dataset, a.seeds, a.base, Path(tmp), not a.quiet, a.config)
    df.to_csv(a.csv, index=False)
    num = df.drop(columns=["seed"]).groupby("rule", sort=False)
    print("\nmean over seeds")
    print(num.mean().to_string(float_format=lambda x: f"{x:.1f}"))
    print("\nstandard deviation over seeds")
    print(num.std().to_string(float_format=lambda x: f"{x:.1f}"))


if __name__ == "__main__":
    main()
