# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Train a warning-conditioned driving model and evaluate it in the closed loop
#
# The paper's headline result is about a *learned* model that reads the cooperative warning as
# language. This notebook builds the two language rows the paper's way, at a size that runs on a
# laptop CPU:
#
# 1. record an open-loop dataset: the privileged `expert` drives fresh scenes of every family
#    (Route A with the hazard and its warning, Route B without), kept at 4 Hz;
# 2. train **base** on ordinary driving only (its text channel carries the navigation
#    instruction, never a warning) — the SimLingo analogue;
# 3. fine-tune **coop** from base on every frame, warnings included — the Coop-SimLingo analogue;
# 4. evaluate both in the closed loop on suite pairs, with and without the warning.
#
# Set `LANTERN_NOTEBOOK_SMALL=1` for the tiny configuration the test runs (one pair per family,
# a narrow model, one epoch). The shipped `learned-*` policies were trained with
# `configs/train_*.toml` on the full default dataset (see the README).

# %%
# %matplotlib inline
import os
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

try:
    from IPython.display import display
except ImportError:  # run as a plain script (python notebooks/...py): print what a cell shows
    display = print

from lantern_jax.apps.dataset.generation import generate_dataset
from lantern_jax.apps.dataset.store import card_markdown
from lantern_jax.apps.evaluation import evaluate
from lantern_jax.apps.training.behaviour_cloning import train
from lantern_jax.apps.training.config import TrainConfig
from lantern_jax.policies.learned.checkpoint import checkpoint_policy
from lantern_jax.report import format_family_table, order_rows
from lantern_jax.scenarios.suite import load_suite

SMALL = os.environ.get("LANTERN_NOTEBOOK_SMALL") == "1"
print(f"SMALL = {SMALL}")
PAIRS_PER_FAMILY = 1 if SMALL else 24  # dataset scenes per family (each gives Route A and B)
WIDTH, EPOCHS = (16, 1) if SMALL else (64, 4)
work = Path("runs/notebook")

# %% [markdown]
# ## 1. The dataset
#
# Generation is resumable and deterministic from its seed; the card counts the accepted
# sequences per family and route and the rejections by reason (the paper's acceptance rules).

# %%
card = generate_dataset(work / "data", pairs_per_family=PAIRS_PER_FAMILY, seed=11,
                        chunk_pairs=6 if SMALL else 48, progress=not SMALL)  # fmt: skip
print(card_markdown(card))

# %% [markdown]
# ## 2. base: ordinary driving only
#
# The `base` recipe keeps the frames without an active warning. Validation holds out whole
# sequences; the checkpoint with the lowest validation L1 (metres over the 10 waypoints) is kept.

# %%
common = dict(dataset=str(work / "data"), width=WIDTH, heads=2 if SMALL else 4, epochs=EPOCHS,
              batch_size=64 if SMALL else 256, val_fraction=0.2, seed=0)  # fmt: skip
base_cfg = TrainConfig(name="nb-base", recipe="base", out=str(work / "base"), **common)
base = train(base_cfg, progress=not SMALL)
print({k: base[k] for k in ("best_val_l1_m", "best_epoch", "train_examples", "frames_per_s")})

# %% [markdown]
# ## 3. coop: base fine-tuned on the LANTERN frames

# %%
coop_cfg = TrainConfig(name="nb-coop", recipe="coop", out=str(work / "coop"),
                       init_from=str(work / "base" / "nb-base.msgpack"), lr=5e-4,
                       **common)  # fmt: skip
coop = train(coop_cfg, progress=not SMALL)
print({k: coop[k] for k in ("best_val_l1_m", "best_epoch", "train_examples", "frames_per_s")})

fig, ax = plt.subplots(figsize=(5, 3))
for name in ("base", "coop"):
    curve = pd.read_csv(work / name / "curve.csv")
    ax.plot(curve["epoch"], curve["val_l1_m"], marker="o", label=f"{name} validation")
    ax.plot(curve["epoch"], curve["train_l1_m"], ls="--", label=f"{name} training")
ax.set_xlabel("epoch")
ax.set_ylabel("L1 (m)")
ax.legend()
plt.close(fig)
display(fig)

# %% [markdown]
# ## 4. Closed loop: with and without the warning
#
# Each pair runs Route A with the warning, Route A without it and Route B. The warning gain is
# the paired difference; the paper expects coop's gain well above base's.

# %%
suite = load_suite()
per_family = 1 if SMALL else 5
ids = []
for family in ("PE", "VC", "OR", "LWW", "RWW", "RTY"):
    ids += [p.pair_id for p in suite.pairs if p.family == family][:per_family]
policies = [checkpoint_policy(work / "base" / "nb-base.msgpack"),
            checkpoint_policy(work / "coop" / "nb-coop.msgpack")]  # fmt: skip
result = evaluate(policies, suite=suite.select(ids), progress=False)
print(format_family_table(order_rows(result.family_table)))
