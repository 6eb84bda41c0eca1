"""Fresh scenes for the open-loop dataset.

Every family gets the same number of pairs, spread over the suite's five weather profiles; each
sampled pair contributes a Route A sequence (hazard and warning) and a Route B sequence (the
same scene without them), which pass the acceptance rules independently (the paper: Route A and
Route B are complementary training sets, not one-to-one pairs).  Scenes are sampled from their
own seed and a candidate is dropped when it repeats a pair of the frozen suite (same content
hash), so the dataset is disjoint from the suite.

Open-loop collection uses the standard geometric event trigger (the paper: the anti-deadlock
rule is used solely for closed-loop evaluation), so ``force_event`` is off in every recorded
scene.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from lantern_jax.constants import FAMILIES, WEATHERS
from lantern_jax.scenarios.families import build_pair, sample_params
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import Suite
from lantern_jax.world import Scenario

DATASET_SEED = 3272  # default generation seed
PAPER_ROUTE_A = 1631  # sequences in the paper's release
PAPER_ROUTE_B = 1641
PAIRS_PER_FAMILY = 280  # default: 1680 pairs -> up to 1680 Route A + 1680 Route B sequences


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """One candidate pair of the dataset."""

    index: int  # position in the generation order (deterministic from the seed)
    family: str
    weather: str
    params: dict
    sha256: str


def plan_scenes(pairs_per_family: int, seed: int, suite: Suite | None = None) -> list[SceneSpec]:
    """The dataset's candidate pairs, in a deterministic order (family-major, weathers cycled).

    Args:
        pairs_per_family: candidate pairs per family.
        seed: generation seed.
        suite: a frozen suite to stay disjoint from (default: none).
    """
    taken = {p.sha256 for p in suite.pairs} if suite is not None else set()
    out: list[SceneSpec] = []
    for fi, fam in enumerate(FAMILIES):
        rng = np.random.default_rng([seed, fi])
        k = 0
        while k < pairs_per_family:
            weather = WEATHERS[k % len(WEATHERS)]
            params = sample_params(fam, rng, weather)
            h = content_hash(params)
            if h in taken:
                continue
            taken.add(h)
            out.append(SceneSpec(len(out), fam, weather, params, h))
            k += 1
    return out


def open_loop(scenario: Scenario) -> Scenario:
    """The scenario with the geometric event trigger only (no anti-deadlock countdown)."""
    return scenario.replace(config=scenario.config.replace(force_event=jnp.asarray(False)))


def build_scenes(specs: list[SceneSpec]) -> tuple[list[Scenario], list[Scenario]]:
    """Route A (warning condition) and Route B scenarios of the given candidates, open loop."""
    a_list, b_list = [], []
    for spec in specs:
        a, b, _ = build_pair(spec.params)
        a_list.append(open_loop(a))
        b_list.append(open_loop(b))
    return a_list, b_list
