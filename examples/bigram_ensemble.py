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


#: The variants whose counterfactual positions are drawn where true warnings state theirs,
#: all of them or a share (``docs/learned.md``, "Counterfactual positions where true warnings
#: state theirs"): variant -> the share drawn so, in words.  Each trains with
#: ``CLOSED_CONFIG=configs/train_closed_loop_rig_bigram_<variant>.toml`` into
#: ``runs/train/bigram_<variant>``.
STATED_VARIANTS = {"stated": "all", "stated_half": "half", "stated_quarter": "a quarter",
                   "stated_half_short": "half", "stated_half_short_hard": "half",
                   "stated_half_short_max": "half", "stated_half_short_modes": "half",
                   "stated_half_short_box": "half"}
#: What else a variant's closed-loop stage changes, in words (its config says it in full).
VARIANT_ROUNDS = {
    "stated_half_short": "fourteen closed-loop rounds of one epoch",
    "stated_half_short_hard": "fourteen closed-loop rounds of one epoch, each round's pairs "
                              "weighted to LWW, RWW and RTY",
    "stated_half_short_max": "fourteen closed-loop rounds of one epoch, the actors pooled by "
                             "their mean and largest values (every stage)",
    "stated_half_short_modes": "fourteen closed-loop rounds of one epoch, a head of three "
                               "scored plans (every stage)",
    "stated_half_short_box": "fourteen closed-loop rounds of one epoch driven under the "
                             "benchmark's default actors' rule",
}


def member_paths(runs: str | Path = RUNS, model: str = MODEL,
                 seeds: tuple[int, ...] = SEEDS) -> list[Path]:  # fmt: skip
    """The chains' closed-loop checkpoints ``model`` under ``runs``, one per seed (0, 1, 2
    unless ``seeds`` names others)."""
    return [Path(runs) / f"bigram_s{seed}" / model for seed in seeds]


def bigram_ensemble(runs: str | Path = RUNS) -> Policy:
    """The ``bigram-ensemble`` policy of the chains under ``runs``.

    Raises:
        lantern_jax.policies.learned.checkpoint.CheckpointError: naming a member's checkpoint
            that is missing or not valid (a chain not run, or not finished).
    """
    return ensemble_policy("bigram-ensemble", member_paths(runs),
                           "mean plan of the bigram reader's three seeds")  # fmt: skip


def _seed_tail(seeds: tuple[int, ...]) -> str:
    """``""`` for the default seeds, else ``_s`` and the seeds' digits (``_s345``)."""
    return "" if seeds == SEEDS else "_s" + "".join(str(seed) for seed in seeds)


def variant_members(variant: str, seeds: tuple[int, ...] = SEEDS,
                    runs: str | Path | None = None) -> list[Path]:  # fmt: skip
    """The closed-loop checkpoints of a :data:`STATED_VARIANTS` variant's chains, one per seed:
    under ``runs/train/bigram_<variant>`` (another seed set's folder ends in its
    :func:`_seed_tail`, e.g. ``_s345``) unless ``runs`` is given."""
    tag = variant.replace("_", "-")
    runs = Path(f"runs/train/bigram_{variant}{_seed_tail(seeds)}") if runs is None else runs
    return member_paths(runs, f"closed/learned-closed-loop-rig-bigram-{tag}.msgpack", seeds)


def stated_variant_ensemble(variant: str, runs: str | Path | None = None, combine: str = "mean",
                            seeds: tuple[int, ...] = SEEDS) -> Policy:  # fmt: skip
    """The three chains of a :data:`STATED_VARIANTS` variant as one policy (not shipped),
    named ``bigram-<variant>-ensemble`` (underscores as hyphens), or
    ``bigram-<variant>-median-ensemble`` with ``combine="median"`` (the element-wise median of
    the three plans, :func:`~lantern_jax.policies.learned.ensemble.ensemble_median_act`).
    Another set of ``seeds``, e.g. ``(3, 4, 5)`` (trained with ``SEEDS="3 4 5"``), is read
    from ``runs/train/bigram_<variant>_s345`` unless ``runs`` is given, and its name ends in
    ``-s345`` (the seeds' digits).

    Raises:
        KeyError: for a variant not in :data:`STATED_VARIANTS`.
        lantern_jax.policies.learned.checkpoint.CheckpointError: as :func:`bigram_ensemble`.
    """
    share = STATED_VARIANTS[variant]
    tag = variant.replace("_", "-")
    tail = _seed_tail(seeds)
    what = f"{combine} plan of the three seeds with {share} of the counterfactual positions stated"
    if variant in VARIANT_ROUNDS:
        what += f", {VARIANT_ROUNDS[variant]}"
    name = f"bigram-{tag}-ensemble" if combine == "mean" else f"bigram-{tag}-{combine}-ensemble"
    if tail:
        name += tail.replace("_", "-")
        what += f" (seeds {', '.join(str(seed) for seed in seeds)})"
    return ensemble_policy(name, variant_members(variant, seeds, runs), what, combine=combine)


def bigram_stated_ensemble() -> Policy:
    """Every counterfactual position drawn where true warnings state theirs."""
    return stated_variant_ensemble("stated")


def bigram_stated_half_ensemble() -> Policy:
    """Half of them drawn so, half in the near box."""
    return stated_variant_ensemble("stated_half")


def bigram_stated_quarter_ensemble() -> Policy:
    """A quarter of them drawn so, three quarters in the near box."""
    return stated_variant_ensemble("stated_quarter")


def bigram_stated_half_median_ensemble() -> Policy:
    """The half variant's three seeds joined by the median of their plans."""
    return stated_variant_ensemble("stated_half", combine="median")


def bigram_stated_quarter_median_ensemble() -> Policy:
    """The quarter variant's three seeds joined by the median of their plans."""
    return stated_variant_ensemble("stated_quarter", combine="median")


def bigram_stated_half_short_ensemble() -> Policy:
    """The half variant trained in fourteen closed-loop rounds of one epoch each."""
    return stated_variant_ensemble("stated_half_short")


def bigram_stated_half_short_median_ensemble() -> Policy:
    """Those three seeds joined by the median of their plans."""
    return stated_variant_ensemble("stated_half_short", combine="median")


def bigram_stated_half_short_hard_ensemble() -> Policy:
    """As :func:`bigram_stated_half_short_ensemble`, each round driving 11 pairs of LWW, RWW
    and RTY and 5 of the other families (``family_weights``)."""
    return stated_variant_ensemble("stated_half_short_hard")


def bigram_stated_half_short_hard_s345_ensemble() -> Policy:
    """:func:`bigram_stated_half_short_hard_ensemble` of the second seed set (3, 4, 5)."""
    return stated_variant_ensemble("stated_half_short_hard", seeds=(3, 4, 5))


def bigram_stated_half_short_max_ensemble() -> Policy:
    """As :func:`bigram_stated_half_short_ensemble`, every stage's model pooling the seen
    actors by their mean and each feature's largest value (``object_pool = "mean_max"``;
    trained with the three ``*_max.toml`` configs, ``examples/train_bigram_ensemble.sh``)."""
    return stated_variant_ensemble("stated_half_short_max")


def bigram_stated_half_short_max_median_ensemble() -> Policy:
    """Those three seeds joined by the median of their plans."""
    return stated_variant_ensemble("stated_half_short_max", combine="median")


def bigram_stated_half_short_max_medoid_ensemble() -> Policy:
    """Those three seeds driving the plan of the member nearest the others (``"medoid"``)."""
    return stated_variant_ensemble("stated_half_short_max", combine="medoid")


def bigram_stated_half_short_modes_ensemble() -> Policy:
    """As :func:`bigram_stated_half_short_ensemble`, every stage's model proposing three plans
    and driving the one it scores highest (``modes = 3``; trained with the three
    ``*_modes.toml`` configs, ``examples/train_bigram_ensemble.sh``)."""
    return stated_variant_ensemble("stated_half_short_modes")


def bigram_stated_half_short_modes_s345_ensemble() -> Policy:
    """:func:`bigram_stated_half_short_modes_ensemble` of the second seed set (3, 4, 5)."""
    return stated_variant_ensemble("stated_half_short_modes", seeds=(3, 4, 5))


def bigram_stated_half_short_modes_medoid_ensemble() -> Policy:
    """Those three seeds driving the plan of the member nearest the others (``"medoid"``):
    always one member's own plan, where the mean of plans chosen among modes is none."""
    return stated_variant_ensemble("stated_half_short_modes", combine="medoid")


def bigram_stated_half_short_medoid_ensemble() -> Policy:
    """:func:`bigram_stated_half_short_ensemble`'s seeds driving their medoid plan."""
    return stated_variant_ensemble("stated_half_short", combine="medoid")


def bigram_stated_half_short_slowest_ensemble() -> Policy:
    """:func:`bigram_stated_half_short_ensemble`'s seeds driving the plan of the member that
    would travel least (``"slowest"``)."""
    return stated_variant_ensemble("stated_half_short", combine="slowest")


def bigram_stated_half_short_s345_ensemble() -> Policy:
    """The same recipe's second, independent set of seeds (3, 4, 5)."""
    return stated_variant_ensemble("stated_half_short", seeds=(3, 4, 5))


def bigram_stated_half_short_s345_median_ensemble() -> Policy:
    """That set joined by the median of its plans."""
    return stated_variant_ensemble("stated_half_short", combine="median", seeds=(3, 4, 5))


#: The generation seed of the validation suite the members are chosen on
#: (``lantern-jax suite --regenerate runs/eval/validation/lantern-v3-seed20261206.json --seed
#: 20261206``): a suite used to choose, never to report.
VALIDATION_SEED = 20261206
#: The seeds :func:`choose_on_validation` kept of the stated-half-short recipe's six (0-5) on
#: that suite (``docs/learned.md``, "Three of six, chosen on a validation suite").
VALIDATION_CHOSEN = (0, 1, 3)


def choose_on_validation(members: dict[int, Path], validation_suite, keep: int = 3,
                         evaluate=None) -> list[int]:  # fmt: skip
    """The ``keep`` seeds of ``members`` (seed -> checkpoint) whose models score the highest
    overall warning CUS on ``validation_suite`` (a :class:`~lantern_jax.scenarios.suite.Suite`
    or a manifest path), best first; ties keep the lower seed first.  ``evaluate`` (default
    :func:`lantern_jax.evaluate`) evaluates one policy on the suite.

    Raises:
        ValueError: when ``keep`` is not between 1 and the number of members.
    """
    from lantern_jax.policies.learned.checkpoint import checkpoint_policy

    if not 1 <= keep <= len(members):
        raise ValueError(f"keep: expected 1 to {len(members)} members, got {keep}")
    if evaluate is None:
        import lantern_jax

        evaluate = lantern_jax.evaluate
    score = {}
    for seed, path in sorted(members.items()):
        result = evaluate([checkpoint_policy(path, name=f"seed-{seed}")],
                          suite=validation_suite, progress=False)  # fmt: skip
        table = result.family_table.set_index("condition")
        score[seed] = float(table.loc["warning", "Overall"])
    return sorted(score, key=lambda seed: (-score[seed], seed))[:keep]


def stated_half_short_six_members() -> dict[int, Path]:
    """The stated-half-short recipe's six closed-loop checkpoints: seeds 0-2 (the default
    set's folder) and 3-5 (``SEEDS="3 4 5"``)."""
    paths = variant_members("stated_half_short") + variant_members("stated_half_short", (3, 4, 5))
    return dict(zip(range(6), paths, strict=True))


def bigram_stated_half_short_chosen_ensemble() -> Policy:
    """The mean plan of the three of the six seeds chosen on the validation suite
    (:data:`VALIDATION_CHOSEN`; :func:`choose_on_validation` computes the choice again)."""
    members = stated_half_short_six_members()
    seeds = ", ".join(str(seed) for seed in VALIDATION_CHOSEN)
    what = (f"mean plan of seeds {seeds}, the three of six with the highest warning CUS on "
            f"the validation suite (seed {VALIDATION_SEED})")
    return ensemble_policy("bigram-stated-half-short-chosen-ensemble",
                           [members[seed] for seed in VALIDATION_CHOSEN], what)  # fmt: skip


def bigram_stated_half_short_box_ensemble() -> Policy:
    """As :func:`bigram_stated_half_short_ensemble`, its closed-loop rounds driven under the
    benchmark's default actors' rule (``ego_leader = "heading_line_or_box"``: a car also brakes
    for the ego's box on its path), the rule the evaluations run under."""
    return stated_variant_ensemble("stated_half_short_box")
