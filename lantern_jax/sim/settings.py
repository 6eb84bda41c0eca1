"""Settings of a simulation: one frozen value, passed as an argument to every rollout.

:class:`Settings` gathers what may be changed without editing the package:

* ``scoring`` — the CUS thresholds, weights and the soft temperature
  (:class:`~lantern_jax.scoring.thresholds.ScoringSettings`);
* ``protocol`` — the temporal protocol's thresholds
  (:class:`~lantern_jax.scenarios.protocol.ProtocolSettings`);
* ``bank`` — the warning texts (:class:`~lantern_jax.scenarios.warnings.TextBank`, static).

A planner's constants are its policy's parameters (``PlannerConfig`` inside the reference
policies' params), the other thing a rollout takes as an argument.

Because settings are arguments, a changed setting is a different input: no cache — JAX's, the
evaluator's, the program store — can answer for it with the program of another value.  Float
fields are traced (a change runs the same compiled program and can be batched with ``vmap``);
tick windows and the bank are static (a change compiles again).  Defaults live in one place
each: the dataclasses' field defaults.

    from lantern_jax import Settings, evaluate
    from lantern_jax.scoring.thresholds import ScoringSettings
    evaluate(["coop"], settings=Settings(scoring=ScoringSettings(ttc_norm_s=2.0)))
"""

from __future__ import annotations

from flax import struct

from lantern_jax.scenarios.protocol import DEFAULT_PROTOCOL, ProtocolSettings
from lantern_jax.scenarios.warnings import DEFAULT_BANK, TextBank
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings


@struct.dataclass
class Settings:
    """Everything a simulation reads besides the scenario, the state and the policy."""

    scoring: ScoringSettings = DEFAULT_SCORING
    protocol: ProtocolSettings = DEFAULT_PROTOCOL
    bank: TextBank = struct.field(pytree_node=False, default=DEFAULT_BANK)

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
        self.scoring.validate()
        return self

    def with_temperature(self, temperature: float) -> Settings:
        """These settings with another soft-score temperature."""
        return self.replace(scoring=self.scoring.replace(temperature=temperature))


#: The paper's settings.
DEFAULT_SETTINGS = Settings()
