"""A bank of pre-built scenes for the environment: resets draw from it by an index.

Scenes are built with NumPy (:mod:`lantern_jax.scenarios`), which cannot run inside ``jit``.
The bank builds many of them once, stacks them along a leading axis together with their initial
simulator state, and a reset becomes a jittable gather: ``index = randint(rng, 0, size)``.

Training scenes are drawn from the family generators with their own seed (default
:data:`TRAIN_SEED`, not the seed of the evaluation suite ``lantern-v3``) and pass the suite's
static validation (:func:`lantern_jax.scenarios.suite.static_check`); the expert's dynamic
validation is not run (a scene the expert fails is still a legitimate training scene).  Every
pair contributes its three executions: Route A with the warning, Route A without it, Route B.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import FAMILIES, WEATHERS
from lantern_jax.scenarios.families import sample_params
from lantern_jax.scenarios.suite import static_check
from lantern_jax.sim.state import State, init_state
from lantern_jax.types.world import Scenario, tree_stack

TRAIN_SEED = 7_000_001  # seed of the training scenes (the suite lantern-v3 uses another one)
ROUTES = ("A warning", "A no-warning", "B")


@dataclasses.dataclass(frozen=True)
class ScenarioBank:
    """Stacked scenes (leading axis ``size``) and their initial states."""

    scenarios: Scenario  # (N, ...) leaves
    states: State  # (N, ...) leaves, ``init_state`` of each scene
    family: np.ndarray  # (N,) int32, family index (``constants.FAMILIES`` order)
    route: np.ndarray  # (N,) int32, index into :data:`ROUTES`

    @property
    def size(self) -> int:
        return int(self.family.shape[0])

    def take(self, index: jax.Array) -> tuple[Scenario, State]:
        """Scene and initial state number ``index`` (jittable gather).

        Args:
            index: () int32 in [0, size).
        """
        pick = lambda x: x[index]  # noqa: E731
        return jax.tree.map(pick, self.scenarios), jax.tree.map(pick, self.states)


def _pairs(family: str, count: int, rng: np.random.Generator, seen: set) -> list[tuple]:
    out, tries = [], 0
    while len(out) < count:
        tries += 1
        if tries > 20 * count:
            raise RuntimeError(f"{family}: only {len(out)} of {count} scenes pass the checks")
        params = sample_params(family, rng, WEATHERS[len(out) % len(WEATHERS)])
        try:
            a, b, meta = static_check(params, seen)
        except ValueError:
            continue
        seen.add(meta["content_hash"])
        out.append((a, b))
    return out


def build_bank(
    pairs_per_family: int = 16,
    seed: int = TRAIN_SEED,
    families: tuple[str, ...] | list[str] = FAMILIES,
) -> ScenarioBank:
    """Build ``pairs_per_family`` statically valid pairs per family (three executions each).

    Args:
        pairs_per_family: pairs drawn per family.
        seed: generator seed; the same seed gives the same bank.
        families: family codes to draw from.

    Returns:
        A :class:`ScenarioBank` of ``3 * pairs_per_family * len(families)`` scenes.
    """
    if pairs_per_family < 1 or not families:
        raise ValueError("build_bank: need at least one family and one pair per family")
    scenes, fam_ids, route_ids, seen = [], [], [], set()
    for code in families:
        rng = np.random.default_rng([seed, FAMILIES.index(code)])
        for a, b in _pairs(code, pairs_per_family, rng, seen):
            on = jnp.ones_like(a.config.warning_enabled)
            a_warn = a.replace(config=a.config.replace(warning_enabled=on))
            a_none = a.replace(config=a.config.replace(warning_enabled=~on))
            scenes += [a_warn, a_none, b]
            fam_ids += [FAMILIES.index(code)] * 3
            route_ids += [0, 1, 2]
    stacked = tree_stack(scenes)
    states = jax.jit(jax.vmap(init_state))(stacked)
    return ScenarioBank(
        scenarios=stacked,
        states=states,
        family=np.asarray(fam_ids, np.int32),
        route=np.asarray(route_ids, np.int32),
    )
