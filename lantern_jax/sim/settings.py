"""Settings of a simulation: one frozen value, passed as an argument to every rollout.

:class:`Settings` gathers what may be changed without editing the package:

* ``scoring`` — the CUS thresholds, weights and the soft temperature
  (:class:`~lantern_jax.scoring.thresholds.ScoringSettings`);
* ``protocol`` — the temporal protocol's thresholds
  (:class:`~lantern_jax.sim.protocol.ProtocolSettings`);
* ``bank`` — the warning texts (:class:`~lantern_jax.scenarios.warnings.TextBank`; its token
  tables, padded to a multiple of 128 texts, are the program's arguments);
* ``actors`` — how the IDM-driven actors treat the ego
  (:class:`~lantern_jax.dynamics.actors.ActorSettings`; static).

A planner's constants are its policy's parameters (``PlannerConfig`` inside the reference
policies' params), the other thing a rollout takes as an argument.

Because settings are arguments, a changed setting is a different input: no cache — JAX's, the
evaluator's, the program store — can answer for it with the program of another value.  Float
fields and the texts of the bank are traced (a change runs the same compiled program; floats
can be batched with ``vmap``); tick windows, the user metrics and a bank grown past a multiple
of 128 texts are static (a change compiles again).  Defaults live in one place
each: the dataclasses' field defaults.

    from lantern_jax import Settings, evaluate
    from lantern_jax.scoring.thresholds import ScoringSettings
    evaluate(["coop"], settings=Settings(scoring=ScoringSettings(ttc_norm_s=2.0)))
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any

import numpy as np
from flax import struct

from lantern_jax.dynamics.actors import DEFAULT_ACTORS, EARLIER_ACTORS, ActorSettings
from lantern_jax.scenarios.warnings import DEFAULT_BANK, TextBank, registered_bank
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings
from lantern_jax.sim.protocol import DEFAULT_PROTOCOL, ProtocolSettings


@struct.dataclass
class Settings:
    """Everything a simulation reads besides the scenario, the state and the policy."""

    scoring: ScoringSettings = DEFAULT_SCORING
    protocol: ProtocolSettings = DEFAULT_PROTOCOL
    bank: TextBank = DEFAULT_BANK  # a pytree: its token tables (padded) are the leaves
    actors: ActorSettings = DEFAULT_ACTORS  # static: a change compiles again

    def validate(self) -> Settings:
        """Check the values outside ``jit``; returns self.

        Raises:
            ValueError: naming the field.
        """
        if not isinstance(self.scoring, ScoringSettings):
            raise ValueError(f"Settings.scoring: expected ScoringSettings, got {self.scoring!r}")
        if not isinstance(self.protocol, ProtocolSettings):
            raise ValueError(f"Settings.protocol: expected ProtocolSettings, got {self.protocol!r}")
        if not isinstance(self.bank, TextBank):
            raise ValueError(f"Settings.bank: expected a TextBank, got {type(self.bank).__name__}")
        if not isinstance(self.actors, ActorSettings):
            raise ValueError(f"Settings.actors: expected ActorSettings, got {self.actors!r}")
        self.scoring.validate()
        self.actors.validate()
        return self

    def check_texts(self, text_ids) -> Settings:
        """Check that the bank holds every text the executions may deliver (outside ``jit``; a
        text id beyond the bank would be delivered as no text at all); returns self.

        Args:
            text_ids: the executions' text ids (``config.text_id`` and
                ``config.override_text_id``; ``-1`` = none).

        Raises:
            ValueError: naming the ids beyond the bank.
        """
        ids = np.asarray(text_ids).reshape(-1)
        beyond = sorted({int(i) for i in ids if i >= len(self.bank)})
        if beyond:
            raise ValueError(
                f"Settings.bank: holds {len(self.bank)} texts; the executions read text id(s) "
                f"{beyond} beyond it (texts of a registered family: start from "
                "lantern_jax.sim.settings.default_settings())"
            )
        return self

    def with_temperature(self, temperature: float) -> Settings:
        """These settings with another soft-score temperature."""
        return self.replace(scoring=self.scoring.replace(temperature=temperature))


#: The paper's settings.
DEFAULT_SETTINGS = Settings()


def default_settings() -> Settings:
    """The paper's settings with every registered family's warning texts in the bank
    (:func:`~lantern_jax.scenarios.warnings.registered_bank`; :data:`DEFAULT_SETTINGS` itself
    when no family is registered)."""
    bank = registered_bank()
    return DEFAULT_SETTINGS if bank == DEFAULT_BANK else DEFAULT_SETTINGS.replace(bank=bank)


def settings_record(settings: Settings) -> dict:
    """The settings of an evaluation as the manifest records them (every value, the bank as
    its size and content hash, the user metrics by name, unit and description, the actors'
    settings).  Records written before 2026-12-08 hold the actors' settings only where they
    differed from that day's default, :data:`~lantern_jax.dynamics.actors.EARLIER_ACTORS`;
    :func:`actors_of_record` reads either."""
    bank = settings.bank
    digest = hashlib.sha256(repr(bank.entries).encode()).hexdigest()
    scoring = {f.name: getattr(settings.scoring, f.name)
               for f in dataclasses.fields(settings.scoring) if f.name != "metrics"}  # fmt: skip
    metrics = settings.scoring.metrics
    return dict(
        scoring={k: _plain(v) for k, v in scoring.items()},
        protocol={k: _plain(v) for k, v in dataclasses.asdict(settings.protocol).items()},
        text_bank=dict(texts=len(bank), sha256=digest),
        # the user metrics (scoring/user_metrics.py) the route table holds, when there are any
        **({"metrics": [m.record() for m in metrics]} if metrics else {}),
        actors=dataclasses.asdict(settings.actors),
    )


def actors_of_record(record: dict | None) -> ActorSettings:
    """The actors' settings a manifest's settings record (:func:`settings_record`) ran under:
    its ``actors`` entry, or :data:`~lantern_jax.dynamics.actors.EARLIER_ACTORS` for a record
    without one (written before 2026-12-08, when the record held them only where they were not
    the default of then).

    Raises:
        ValueError: naming ``ActorSettings.ego_leader`` when the record names an unknown rule.
    """
    recorded = (record or {}).get("actors") or {}
    return dataclasses.replace(EARLIER_ACTORS, **recorded).validate()


def normalised_record(record: dict | None) -> dict | None:
    """``record`` with its ``actors`` entry filled in where an older record has none
    (:func:`actors_of_record`), so that two records of the same settings compare equal whatever
    day they were written; ``None`` stays ``None``."""
    if not record:
        return record
    return {**record, "actors": dataclasses.asdict(actors_of_record(record))}


def _plain(v: Any) -> Any:
    """A JSON-friendly value (a traced float leaf becomes a float)."""
    return v if isinstance(v, int | str | bool) else float(np.asarray(v))
