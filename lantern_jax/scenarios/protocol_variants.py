"""The protocol ablations (paper §"Ablations and Robustness", Table "Sensitivity to warning
timing, event activation, localization, and wording"), one record each.

An :class:`Ablation` changes only protocol data of a batch of executions (its
:class:`~lantern_jax.types.world.ExecutionConfig`): every variant runs the same compiled program as
the full protocol.  :data:`ABLATIONS` lists them in the paper's order; :func:`get_ablation`
looks one up by name.  The table that evaluates them is :mod:`lantern_jax.apps.ablation_table`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp

from lantern_jax.scenarios.warnings import paraphrase_text_ids
from lantern_jax.types.world import ExecutionConfig

ConfigFn = Callable[[ExecutionConfig], ExecutionConfig]


@dataclasses.dataclass(frozen=True)
class Ablation:
    """One protocol variant.

    Attributes:
        name: the name commands and result files use (``late_onset``).
        label: its row label in the paper's table.
        description: one line, what it changes.
        apply: ``config -> config`` for a batch of Route A configs (``None``: the standard
            protocol).
    """

    name: str
    label: str
    description: str
    apply: ConfigFn | None = None


def _set(field: str, value) -> ConfigFn:
    """A config transform setting one field of every execution to ``value``."""

    def apply(config: ExecutionConfig) -> ExecutionConfig:
        return config.replace(**{field: jnp.full_like(getattr(config, field), value)})

    return apply


def _paraphrase(config: ExecutionConfig) -> ExecutionConfig:
    """Held-out paraphrases by ambiguity tier (``warnings.paraphrase_text_ids``): the pairs
    fall into three disjoint subsets (low / medium / high ambiguity) and each pair reads a
    paraphrase of its family and tier; the paper's ablation aggregates the three tiers."""
    return config.replace(text_id=jnp.asarray(paraphrase_text_ids(config), jnp.int32))


#: Every ablation, the full protocol first, in the paper's order.
ABLATIONS: tuple[Ablation, ...] = (
    Ablation("none", "Full temporal protocol", "the standard protocol"),
    Ablation(
        "late_onset",
        "Late warning onset",
        "warning delivered from the physical event on, not from the warning point",
        _set("late_onset", True),
    ),
    Ablation(
        "warning_beyond_termination",
        "Warning beyond termination",
        "warning held 10 s beyond its termination",
        _set("warn_hold_extra", 10.0),
    ),
    Ablation(
        "no_anti_deadlock",
        "No anti-deadlock rule",
        "no anti-deadlock countdown: the event waits for the ego indefinitely",
        _set("force_event", False),
    ),
    Ablation(
        "noisy_position",
        "Noisy warning position",
        "the reported hazard position displaced once per execution by exactly 2 m in a seeded "
        "random direction",
        _set("pos_noise_m", 2.0),
    ),
    Ablation(
        "held_out_paraphrase",
        "Held-out warning paraphrase",
        "every warning text replaced by a held-out paraphrase of its pair's ambiguity tier "
        "(low / medium / high, three disjoint thirds of the suite)",
        _paraphrase,
    ),
)


def ablation_names() -> list[str]:
    """Valid ablation names, in the paper's order."""
    return [a.name for a in ABLATIONS]


def get_ablation(name: str) -> Ablation:
    """The ablation called ``name``.

    Raises:
        ValueError: listing the valid names for an unknown one.
    """
    for a in ABLATIONS:
        if a.name == name:
            return a
    raise ValueError(f"unknown ablation {name!r}; valid: {', '.join(ablation_names())}")
