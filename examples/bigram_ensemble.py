"""The bigram reader's three seeds as one policy: the mean of their plans.

Evaluate the checkpoints ``examples/train_bigram_ensemble.sh`` leaves (run from the project's
folder)::

    .venv/bin/lantern-jax evaluate --policy examples/bigram_ensemble.py:bigram_ensemble

The ensemble declares its members' sensors (the six-camera rig and the warning text) and sees
nothing more; ``lantern_jax.policies.learned.ensemble`` says how the plans are averaged, and
``docs/learned.md`` what the three seeds score alone and together.
"""

from __future__ import annotations

from pathlib import Path

from lantern_jax.policies.base import Policy
from lantern_jax.policies.learned.ensemble import ensemble_policy

#: Where ``examples/train_bigram_ensemble.sh`` writes the chains by default.
RUNS = Path("runs/train/bigram_ensemble")
SEEDS = (0, 1, 2)
MODEL = "closed/learned-closed-loop-rig-bigram.msgpack"  # each chain's last stage


#: The variant whose counterfactual positions are drawn where true warnings state theirs
#: (``CLOSED_CONFIG=configs/train_closed_loop_rig_bigram_stated.toml``, ``docs/learned.md``).
STATED_RUNS = Path("runs/train/bigram_stated")
STATED_MODEL = "closed/learned-closed-loop-rig-bigram-stated.msgpack"
#: The variant with half of those positions drawn so, half in the near box
#: (``CLOSED_CONFIG=configs/train_closed_loop_rig_bigram_stated_half.toml``).
STATED_HALF_RUNS = Path("runs/train/bigram_stated_half")
STATED_HALF_MODEL = "closed/learned-closed-loop-rig-bigram-stated-half.msgpack"


def member_paths(runs: str | Path = RUNS, model: str = MODEL) -> list[Path]:
    """The three chains' closed-loop checkpoints ``model`` under ``runs``, seeds 0, 1, 2."""
    return [Path(runs) / f"bigram_s{seed}" / model for seed in SEEDS]


def bigram_ensemble(runs: str | Path = RUNS) -> Policy:
    """The ``bigram-ensemble`` policy of the chains under ``runs``.

    Raises:
        lantern_jax.policies.learned.checkpoint.CheckpointError: naming a member's checkpoint
            that is missing or not valid (a chain not run, or not finished).
    """
    return ensemble_policy("bigram-ensemble", member_paths(runs),
                           "mean plan of the bigram reader's three seeds")  # fmt: skip


def bigram_stated_ensemble(runs: str | Path = STATED_RUNS) -> Policy:
    """The three chains of the stated-positions variant as one policy (not shipped)."""
    return ensemble_policy("bigram-stated-ensemble", member_paths(runs, STATED_MODEL),
                           "mean plan of the stated-positions variant's three seeds")  # fmt: skip


def bigram_stated_half_ensemble(runs: str | Path = STATED_HALF_RUNS) -> Policy:
    """The three chains of the half-stated-positions variant as one policy (not shipped)."""
    paths = member_paths(runs, STATED_HALF_MODEL)
    what = "mean plan of the half-stated-positions variant's three seeds"
    return ensemble_policy("bigram-stated-half-ensemble", paths, what)
