"""Fresh scenes for the open-loop dataset.

Every family gets the same number of pairs, spread over the suite's five weather profiles; each
sampled pair contributes a Route A sequence (hazard and warning) and a Route B sequence (the
same scene without them), which pass the acceptance rules independently (the paper: Route A and
Route B are complementary training sets, not one-to-one pairs).  Scenes are sampled from their
own seed, and a candidate is dropped when it repeats a pair of the frozen suite (same content
hash) or when its route is a **near duplicate** of a suite route of the same family by the
paper's rule (:mod:`lantern_jax.scenarios.duplicates`: in both directions at least 70 % of the
2-m route samples within 3 m of the other route, compared in the frame of their start pose; the
paper's scanner "also checks overlap with the existing closed-loop suite"), so training and
evaluation never share a route geometry.  The rule rejects most candidates of the families
whose geometry varies least (Obstacle Reveal, the turns: see :func:`plan_scenes`), so the
dataset leans toward the rest of each family's parameter ranges — the price of a disjoint
split, counted in the dataset card.

Open-loop collection uses the standard geometric event trigger (the paper: the anti-deadlock
rule is used solely for closed-loop evaluation), so ``force_event`` is off in every recorded
scene.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from lantern_jax.apps.dataset.store import DatasetError
from lantern_jax.core import family_codes
from lantern_jax.core.constants import (  # noqa: F401  (DATASET_SEED, PAIRS_PER_FAMILY re-exported)
    DATASET_SEED,
    FAMILIES,
    PAIRS_PER_FAMILY,
    WEATHERS,
)
from lantern_jax.core.progress import tqdm
from lantern_jax.io.files import atomic_write
from lantern_jax.scenarios.assemble import host_arrays
from lantern_jax.scenarios.duplicates import near_duplicate, route_samples
from lantern_jax.scenarios.families import build_pair, family, validate_params
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import Suite
from lantern_jax.types.world import Scenario

# DATASET_SEED and PAIRS_PER_FAMILY (the default plan) live in core/constants.py, so that the
# command line's options read them without importing JAX.  The scenes of a smaller plan are the
# first ones of every family in a larger plan of the same seed (:func:`plan_scenes`).
PLAN_JSON = "plan.json"  # the planned scenes, kept in the dataset folder for resuming


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """One candidate pair of the dataset."""

    index: int  # position in the generation order (deterministic from the seed)
    family: str
    weather: str
    params: dict
    sha256: str


#: m, how far a suite file's recorded ``route_2m`` may lie from the route its parameters build
#: (the file rounds it to ``generate.ROUTE_DECIMALS`` decimals: 5e-4 m).
ROUTE_2M_ATOL = 1e-3


def _suite_routes(suite: Suite | None) -> dict[str, list[np.ndarray]]:
    """Every suite pair's route samples (2 m, world frame) per family, built from the pair's
    parameters; a ``route_2m`` the suite file records is checked against them first.

    Raises:
        ValueError: naming the suite, the pair and the field when the recorded route is not the
            one its parameters build (the file was edited).
    """
    routes: dict[str, list[np.ndarray]] = {f: [] for f in family_codes.codes()}
    for p in suite.pairs if suite is not None else ():
        with host_arrays():
            built = route_samples(build_pair(p.params, validate=False)[0])
        if p.route_2m is not None:
            recorded = np.asarray(p.route_2m, np.float64)
            far = (recorded.shape != built.shape
                   or float(np.max(np.abs(recorded - built))) > ROUTE_2M_ATOL)  # fmt: skip
            if far:
                off = ("another number of points" if recorded.shape != built.shape else
                       f"{float(np.max(np.abs(recorded - built))):.3g} m off")  # fmt: skip
                raise ValueError(
                    f"suite {suite.suite_id}: pair {p.pair_id}: route_2m is not the route its "
                    f"params build ({off}; tolerance {ROUTE_2M_ATOL:g} m): the file was edited"
                )
        routes[p.family].append(built)
    return routes


def _route_or_error(params: dict) -> np.ndarray:
    """A sampled candidate's Route A route samples; an unbuildable candidate raises the
    validation error that names its field (what
    :func:`~lantern_jax.scenarios.families.sample_params` would have raised)."""
    try:
        with host_arrays():
            return route_samples(build_pair(params, validate=False)[0])
    except Exception:
        validate_params(params)
        raise


def plan_scenes(
    pairs_per_family: int,
    seed: int,
    suite: Suite | None = None,
    rejected: dict | None = None,
    progress: bool = False,
    families: Sequence[str] = FAMILIES,
) -> list[SceneSpec]:
    """The dataset's candidate pairs, in a deterministic order (family-major, weathers cycled).

    A sampled candidate is skipped when its content hash is a suite pair's or an earlier
    candidate's, and when its Route A route is a near duplicate of a suite route of its family
    (each candidate is built once, on the host, to get its route); the survivors are validated
    as :func:`~lantern_jax.scenarios.families.sample_params` validates, so the plan is the one
    that sampling validated parameters one by one would give.

    Args:
        pairs_per_family: candidate pairs per family.
        seed: generation seed.
        suite: a frozen suite to stay disjoint from (default: none).
        rejected: if given, filled with the candidates skipped as near duplicates of the suite,
            per family (``{family: count}``).
        progress: show a progress bar (the default plan samples and builds about 9,900
            candidates for its 2,280 pairs: about three minutes on two CPU cores).
        families: the families to plan (default: the six; a registered family is planned like
            them, :mod:`lantern_jax.scenarios.registry`).

    Each family draws from its own stream (``seed``, :func:`lantern_jax.core.family_codes.stream`:
    the family index for the six) and stops after
    ``pairs_per_family`` survivors, so the plan of a smaller ``pairs_per_family`` is, family by
    family, the first scenes of a larger one.
    """
    taken = {p.sha256 for p in suite.pairs} if suite is not None else set()
    suite_routes = _suite_routes(suite)
    out: list[SceneSpec] = []
    bar = None
    if progress:
        bar = tqdm(total=pairs_per_family * len(families), desc="scenes", unit="pair")
    for fam in families:
        rng = np.random.default_rng([seed, family_codes.stream(fam)])
        k = n_dup = 0
        while k < pairs_per_family:
            weather = WEATHERS[k % len(WEATHERS)]
            # the family's sampler draws exactly what sample_params draws; validation (a full
            # feasibility check) is left for the candidates that survive the duplicate tests
            params = family(fam).sample(rng, weather)
            h = content_hash(params)
            if h in taken:
                continue
            taken.add(h)
            if suite_routes[fam]:
                route = _route_or_error(params)
                if any(near_duplicate(route, r) for r in suite_routes[fam]):
                    n_dup += 1
                    continue
            validate_params(params)
            out.append(SceneSpec(len(out), fam, weather, params, h))
            k += 1
            if bar is not None:
                bar.set_postfix_str(f"{fam}, {n_dup} near duplicates skipped")
                bar.update(1)
        if rejected is not None:
            rejected[fam] = n_dup
    if bar is not None:
        bar.close()
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


def write_plan(folder: str | Path, key: dict, suite_sha256: str, specs: list[SceneSpec],
               info: dict | None = None) -> None:  # fmt: skip
    """Keep a plan in ``folder/plan.json`` (atomically), so that a resumed or repeated
    generation records from the same scenes without sampling and checking them again.

    Args:
        folder: the dataset folder.
        key: the plan's identity (seed, pairs per family, chunking, format version).
        suite_sha256: hash of the suite the plan is disjoint from.
        specs: the planned scenes.
        info: what the card reports about planning (skipped near duplicates, seconds), given
            back by :func:`read_plan`.
    """
    body = dict(key, suite_sha256=suite_sha256, info=info or {},
                specs=[dataclasses.asdict(s) for s in specs])  # fmt: skip
    atomic_write(Path(folder) / PLAN_JSON, json.dumps(body, sort_keys=True) + "\n")


def read_plan(folder: str | Path, key: dict, suite_sha256: str
              ) -> tuple[list[SceneSpec], dict] | None:  # fmt: skip
    """The plan kept in ``folder`` by :func:`write_plan` and its ``info``; None when there is
    none, or when it was made for another key or suite (it is then planned again).

    Raises:
        DatasetError: naming the file when it cannot be read or a scene's parameters do not
            match their recorded hash.
    """
    path = Path(folder) / PLAN_JSON
    if not path.exists():
        return None
    try:
        body = json.loads(path.read_text())
        same = all(body.get(k) == v for k, v in key.items())
        if not same or body.get("suite_sha256") != suite_sha256:
            return None
        specs = [SceneSpec(**d) for d in body["specs"]]
        info = dict(body.get("info", {}))
    except (OSError, ValueError, TypeError, KeyError) as e:
        raise DatasetError(f"{path}: not a readable scene plan ({e!r}); delete it to plan "
                           "again") from None  # fmt: skip
    for s in specs:
        if content_hash(s.params) != s.sha256:
            raise DatasetError(f"{path}: scene {s.index} ({s.family}) does not match its "
                               "sha256; delete the file to plan again")  # fmt: skip
    return specs, info
