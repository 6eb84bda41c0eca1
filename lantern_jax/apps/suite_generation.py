"""Suite generation: sample candidates, validate them statically and with the expert, select.

Generation is deterministic from a seed.  Every (weather, family) slot draws its candidates in
order from its own generator seeded by ``(seed, weather index, family index)``, and the slots
are filled in rounds of ``ROUND_SIZE`` candidates per unfilled slot:

1. **static validation** (:func:`lantern_jax.scenarios.suite.static_check`) rejects candidates
   whose parameters, occluders, markers, recovery stretch, junction or Route A/B agreement are
   wrong, whose hazard the front camera sees at the warning point (the premise), or whose
   content hash repeats; a candidate that is a **near duplicate** (paper rule, start-pose
   frame, :mod:`lantern_jax.scenarios.duplicates`) of a pair already selected for its family is
   rejected too;
2. **dynamic validation** (:func:`dynamic_check`) runs the privileged ``expert`` on Route A
   (warning condition) and Route B of the round's candidates in one batched call and keeps a
   pair only when both routes are completed without any gate failure, the warning starts and
   ends exactly once, and the physical event and its clearance are recorded on Route A (not by
   a safety limit);
3. **selection**: candidate ``k`` of every slot in turn (``k`` by ``k``, weathers in order),
   each accepted when it passed both validations, its slot still needs pairs and it is not a
   near duplicate of a pair selected before it.

Rounds stop when every slot holds ``pairs_per_slot`` pairs.  ``generate_suite(families=...)``
generates a suite of other families, registered ones included
(:mod:`lantern_jax.scenarios.registry`); a registered family's slots draw from generators
seeded by a number derived from its code (:func:`lantern_jax.core.family_codes.stream`), so its
pairs do not depend on what else is registered.  The batch of every expert call is
padded to one size with executions that are never stepped, so one compilation serves all
rounds and a round of a few candidates costs only their own ticks.  This is an
evaluation-layer concern (it runs the simulator and a policy), so it lives above
:mod:`lantern_jax.scenarios`.
:func:`verify_regeneration` regenerates a shipped suite from its seed and compares every hash
and every recorded route.

The validator is part of what makes a suite: the manifest's generation report names it
(``validator``), and a suite regenerates only with the validator that filtered it.
``lantern-v2`` was filtered by the first privileged reference, registered as ``expert-v1``
(its report names it; a manifest that names none is taken to mean the same,
:data:`LEGACY_VALIDATOR`).  ``lantern-v3`` (Obstacle Reveal on a straight approach) was
generated from the same seed with the same validator, so that its pairs of the five other
families are exactly those of ``lantern-v2``; new suites use ``expert`` by default.
"""

from __future__ import annotations

import collections
from collections.abc import Sequence

import jax
import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES, ROUTE_A_GATE_NAMES, WEATHERS
from lantern_jax.core.times import happened, ticks_covering
from lantern_jax.dynamics.actors import EARLIER_ACTORS
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.assemble import host_arrays
from lantern_jax.scenarios.duplicates import near_duplicate, route_samples
from lantern_jax.scenarios.families import sample_params
from lantern_jax.scenarios.spec import PARAM_RANGES, param_ranges, route_timeout_s
from lantern_jax.scenarios.suite import (
    SUITE_ID,
    PairSpec,
    load_suite,
    shipped_suite_hash,
    static_check,
    suite_hash,
)
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.engine import run_executions
from lantern_jax.sim.settings import default_settings
from lantern_jax.types.world import Scenario, tree_stack

DEFAULT_SEED = 20260611
PAIRS_PER_SLOT = 4  # per family per weather profile
CANDIDATES_PER_SLOT = 160  # at most, per slot (lantern-v3: OR needs up to ~100)
ROUND_SIZE = 8  # candidates per unfilled slot and round
EXPERT_MIN_PROGRESS = 0.99  # route completion the expert must reach on both routes
ROUTE_DECIMALS = 3  # the manifest's route samples are rounded to 1 mm


def _timeout_ticks(route_length_m: float) -> int:
    """Ticks that cover the route timeout of a route this long."""
    return ticks_covering(route_timeout_s(route_length_m))


#: Ticks of every expert call: the longest route timeout of any family.
MAX_TICKS = _timeout_ticks(max(r["route_length"].hi for r in PARAM_RANGES.values()))


def max_ticks(families: Sequence[str]) -> int:
    """Ticks of the expert calls of a suite of ``families``: :data:`MAX_TICKS` for the six,
    longer when a registered family's routes are longer."""
    longest = max(param_ranges(f)["route_length"].hi for f in families)
    return max(MAX_TICKS, _timeout_ticks(longest))


VALIDATOR = "expert"  # policy that filters newly generated suites
LEGACY_VALIDATOR = "expert-v1"  # the validator of manifests that do not name one
#: How the IDM actors treat the ego while a validator drives: the rule ``lantern-v3`` and every
#: suite of its design were filtered under (:data:`~lantern_jax.dynamics.actors.EARLIER_ACTORS`,
#: the default until 2026-12-08), kept so that each regenerates from its seed bit for bit.  The
#: suites are evaluated under the default rule, under which the flow's cars also brake for an
#: ego on their path: the validator then meets at most the same cars.
VALIDATION_ACTORS = EARLIER_ACTORS

_VALIDATOR_PARAMS = {}


def _validator(validator: str):
    """A validator policy and its parameters (initialised once per validator)."""
    if validator not in _VALIDATOR_PARAMS:
        pol = get_policy(validator)
        _VALIDATOR_PARAMS[validator] = (pol, pol.init(jax.random.PRNGKey(0)))
    return _VALIDATOR_PARAMS[validator]


def dynamic_check(
    scenarios_a: list[Scenario],
    scenarios_b: list[Scenario],
    batch_size: int | None = None,
    validator: str = VALIDATOR,
    ticks: int = MAX_TICKS,
) -> tuple[np.ndarray, list[str]]:
    """Run the validator (a privileged expert) on Route A (warning) and Route B of many pairs
    in one batched call.

    The executions are stepped as an evaluation steps them
    (:func:`lantern_jax.apps.evaluation.run_executions`: refilled slots on every device), the batch
    padded with executions that are never stepped.

    Args:
        scenarios_a, scenarios_b: the pairs' Route A and Route B scenarios.
        batch_size: pad the batch of ``2 n`` executions to this many (never stepped) so that
            calls of different sizes share one compilation; None = no padding.
        validator: the registered policy that validates.
        ticks: horizon of the rollouts (:func:`max_ticks` of the suite's families).

    Returns:
        (accepted (n,) bool, reasons list[str] — "" for accepted pairs).
    """
    n = len(scenarios_a)
    execs = list(scenarios_a) + list(scenarios_b)
    if batch_size is not None and batch_size < len(execs):
        raise ValueError(f"dynamic_check: {len(execs)} executions exceed batch {batch_size}")
    pol, params = _validator(validator)
    settings = default_settings().replace(actors=VALIDATION_ACTORS)
    final, _ = run_executions(
        pol, tree_stack(execs), params, ticks, settings, compact=True, pad_to=batch_size
    )
    m = jax.tree.map(np.asarray, finalize(final.telemetry))
    proto = jax.tree.map(np.asarray, final.protocol)
    ok, reasons = np.ones(n, bool), [""] * n
    for i in range(n):
        why = []
        for j, tag in ((i, "A"), (n + i, "B")):
            if m.progress[j] < EXPERT_MIN_PROGRESS:
                why.append(f"{tag}: route not completed")
            why += [f"{tag}: {g} failed" for g in ROUTE_A_GATE_NAMES if not bool(getattr(m, g)[j])]
        if not bool(m.gate_false_brake[n + i]):
            why.append("B: false brake")
        for f in ("t_warn_point", "t_event", "t_warn_off", "t_clear"):
            if not happened(getattr(proto, f)[i]):
                why.append(f"A: {f} not recorded")
        if bool(proto.clear_by_limit[i]):
            why.append("A: clearance by safety limit")
        ok[i] = not why
        reasons[i] = "; ".join(why)
    return ok, reasons


# ---------------------------------------------------------------------------------------------
# generation
# ---------------------------------------------------------------------------------------------
def _slot_rng(seed: int, w: int, f: int) -> np.random.Generator:
    return np.random.default_rng([seed, w, f])


class _Generation:
    """The state of one generation run: slot generators, selected pairs, statistics."""

    def __init__(self, seed: int, pairs_per_slot: int, candidates_per_slot: int,
                 families: Sequence[str] = FAMILIES) -> None:  # fmt: skip
        self.seed, self.need, self.max_k = seed, pairs_per_slot, candidates_per_slot
        self.families = tuple(families)
        self.rngs = {(w, f): _slot_rng(seed, w, family_codes.stream(code))
                     for w in range(len(WEATHERS))
                     for f, code in enumerate(self.families)}  # fmt: skip
        self.drawn = collections.Counter()  # candidates drawn per slot
        self.filled = collections.Counter()  # pairs selected per slot
        self.selected: dict[str, list[dict]] = {f: [] for f in self.families}
        self.seen: set[str] = set()
        zero = dict.fromkeys(self.families, 0)
        self.stats = dict(candidates=dict(zero), static_rejected=dict(zero),
                          premise_rejected=dict(zero), near_duplicate_rejected=dict(zero),
                          dynamic_tried=dict(zero), dynamic_passed=dict(zero))  # fmt: skip
        self.reasons: dict[str, set[str]] = {f: set() for f in self.families}

    def open_slots(self) -> list[tuple[int, int]]:
        return [s for s in self.rngs if self.filled[s] < self.need and self.drawn[s] < self.max_k]

    def _is_duplicate(self, fam: str, route: np.ndarray) -> bool:
        return any(near_duplicate(route, q["route"]) for q in self.selected[fam])

    def draw_round(self) -> list[dict]:
        """Draw and statically check the next ``ROUND_SIZE`` candidates of every open slot."""
        out = []
        for w, f in self.open_slots():
            fam = self.families[f]
            for _ in range(min(ROUND_SIZE, self.max_k - self.drawn[(w, f)])):
                k = self.drawn[(w, f)]
                self.drawn[(w, f)] += 1
                self.stats["candidates"][fam] += 1
                try:  # a sampler may draw an infeasible dict: a static rejection
                    params = sample_params(fam, self.rngs[(w, f)], WEATHERS[w])
                    # built with NumPy leaves: the checks read them on the host, and only the
                    # dynamic check's batch goes to the device
                    with host_arrays():
                        a, b, meta = static_check(params, self.seen)
                except ValueError as e:
                    key = "premise_rejected" if "premise" in str(e) else "static_rejected"
                    self.stats[key][fam] += 1
                    continue
                self.seen.add(meta["content_hash"])
                route = route_samples(a)
                if self._is_duplicate(fam, route):
                    self.stats["near_duplicate_rejected"][fam] += 1
                    continue
                out.append(dict(w=w, f=f, k=k, params=params, a=a, b=b, meta=meta, route=route))
        return out

    def select(self, cands: list[dict], ok: np.ndarray, reasons: list[str]) -> None:
        """Accept the round's candidates k by k, weathers in order (see the module docstring)."""
        for c, good, why in zip(cands, ok, reasons, strict=True):
            fam = self.families[c["f"]]
            self.stats["dynamic_tried"][fam] += 1
            self.stats["dynamic_passed"][fam] += int(good)
            c["ok"] = bool(good)
            if not good:
                self.reasons[fam].add(why)
        for c in sorted(cands, key=lambda c: (c["k"], c["w"], c["f"])):
            fam, slot = self.families[c["f"]], (c["w"], c["f"])
            if not c["ok"] or self.filled[slot] >= self.need:
                continue
            if self._is_duplicate(fam, c["route"]):
                self.stats["near_duplicate_rejected"][fam] += 1
                continue
            self.filled[slot] += 1
            self.selected[fam].append(c)


def _manifest_pairs(gen: _Generation) -> list[dict]:
    pairs = []
    for fam in gen.families:
        chosen = sorted(gen.selected[fam], key=lambda c: (c["w"], c["k"]))
        for i, c in enumerate(chosen, start=1):
            route = np.round(c["route"], ROUTE_DECIMALS) + 0.0
            pairs.append(dict(pair_id=f"{fam.lower()}_{i:04d}", family=fam,
                              weather=WEATHERS[c["w"]], sha256=c["meta"]["content_hash"],
                              params=c["params"], route_2m=route.tolist()))  # fmt: skip
    return pairs


def generate_suite(
    seed: int = DEFAULT_SEED,
    pairs_per_slot: int = PAIRS_PER_SLOT,
    candidates_per_slot: int = CANDIDATES_PER_SLOT,
    progress: bool = True,
    validator: str = VALIDATOR,
    families: Sequence[str] = FAMILIES,
    suite_id: str | None = None,
) -> dict:
    """Generate, validate and select a suite; returns the manifest dict.

    Args:
        seed: generation seed.
        pairs_per_slot: accepted pairs per (weather, family) slot (4 for lantern-v3).
        candidates_per_slot: most candidates drawn per slot.
        progress: print one line per round.
        validator: registered policy of the dynamic validation (recorded in the report).
        families: the families of the suite (default: the six; registered families may be
            named, :mod:`lantern_jax.scenarios.registry`).
        suite_id: the manifest's suite id (default: :func:`regenerated_suite_id`).

    Raises:
        RuntimeError: naming the slots that could not be filled.
        ValueError: for an unknown family or one named twice.
    """
    families = tuple(families)
    for code in families:
        param_ranges(code)  # raises for an unknown family
    if len(set(families)) != len(families):
        raise ValueError(f"families: named more than once in {families}")
    gen = _Generation(seed, pairs_per_slot, candidates_per_slot, families)
    ticks = max_ticks(families)
    batch = 2 * len(gen.rngs) * ROUND_SIZE
    rounds = 0
    while gen.open_slots():
        cands = gen.draw_round()
        rounds += 1
        if cands:
            ok, reasons = dynamic_check(
                [c["a"] for c in cands], [c["b"] for c in cands], batch, validator, ticks
            )
            gen.select(cands, ok, reasons)
        if progress:
            done = sum(min(v, pairs_per_slot) for v in gen.filled.values())
            print(f"[suite] round {rounds}: {len(cands)} candidates to {validator}, "
                  f"{done}/{pairs_per_slot * len(gen.rngs)} pairs selected")  # fmt: skip
    missing = [(WEATHERS[w], families[f]) for (w, f) in gen.rngs if gen.filled[(w, f)] < gen.need]
    if missing:
        raise RuntimeError(f"not enough valid candidates for slots {missing}; statistics per "
                           f"family: {gen.stats}")  # fmt: skip
    pairs = _manifest_pairs(gen)
    st = gen.stats
    report = dict(
        candidates_per_slot_max=candidates_per_slot,
        round_size=ROUND_SIZE,
        validator=validator,
        rounds=rounds,
        **st,
        expert_pass_rate={
            f: st["dynamic_passed"][f] / max(st["dynamic_tried"][f], 1) for f in families
        },  # fmt: skip
        dynamic_reject_reasons={f: sorted(r)[:10] for f, r in gen.reasons.items()},
    )
    specs = [PairSpec(p["pair_id"], p["family"], p["weather"], p["params"], p["sha256"])
             for p in pairs]  # fmt: skip
    digest = suite_hash(specs)
    return dict(
        suite_id=suite_id or regenerated_suite_id(seed, digest),
        format_version=1,
        seed=seed,
        pairs=pairs,
        suite_sha256=digest,
        generation_report=report,
    )


def regenerated_suite_id(seed: int, digest: str) -> str:
    """The id of a generated suite: the shipped suite's when it is that suite (same hash), else
    one naming the seed and the hash, so that a file never claims an id whose pairs it lacks."""
    if digest == shipped_suite_hash(SUITE_ID):
        return SUITE_ID
    return f"{SUITE_ID}-seed{seed}-{digest[:8]}"


def suite_validator(report: dict | None) -> str:
    """The validator policy named by a generation report (:data:`LEGACY_VALIDATOR` if none)."""
    return (report or {}).get("validator", LEGACY_VALIDATOR)


def regenerates_suite(name: str, seed: int, validator: str) -> bool:
    """Whether a generation from ``seed`` with ``validator`` (the six families) is what
    :func:`verify_regeneration` of suite ``name`` would generate, so that its manifest can be
    compared instead of generating the suite a second time."""
    shipped = load_suite(name)
    return seed == shipped.seed and validator == suite_validator(shipped.report)


def verify_regeneration(name: str = SUITE_ID, fresh: dict | None = None) -> tuple[bool, str]:
    """Regenerate a shipped suite from its seed (with its own validator) and compare every pair
    hash, every recorded route and the suite hash.

    Args:
        name: the suite id or manifest path.
        fresh: a manifest already generated from the suite's seed with its validator
            (:func:`regenerates_suite` says whether one was); compared instead of generating
            the suite again.
    """
    shipped = load_suite(name)
    if fresh is None:
        fresh = generate_suite(shipped.seed, progress=False,
                               validator=suite_validator(shipped.report))  # fmt: skip
    got = [(p["pair_id"], p["sha256"], p["route_2m"]) for p in fresh["pairs"]]
    want = [(p.pair_id, p.sha256, p.route_2m) for p in shipped.pairs]
    for g, w in zip(got, want, strict=False):
        if g[:2] != w[:2]:
            return (
                False,
                f"first mismatch at pair {w[0]}: shipped {w[1][:12]}, regenerated {g[1][:12]}",
            )
        if w[2] is not None and g[2] != w[2]:
            return False, f"pair {w[0]}: recorded route_2m differs from the regenerated route"
    if len(got) != len(want):
        return False, f"pair count differs: shipped {len(want)}, regenerated {len(got)}"
    return fresh["suite_sha256"] == shipped.suite_sha256, "suite hash " + fresh["suite_sha256"]
