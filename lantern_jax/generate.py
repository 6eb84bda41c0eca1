"""Suite generation: sample candidates, validate them statically and with the expert, select.

Generation is deterministic from a seed:

1. for every (weather, family) slot, candidates are sampled in order from a generator seeded by
   ``(seed, weather index, family index)``;
2. **static validation** (:func:`lantern_jax.scenarios.suite.static_check`) rejects candidates
   whose parameters, markers, recovery stretch, junction or Route A/B agreement are wrong, or
   whose content hash repeats;
3. **dynamic validation** (:func:`dynamic_check`) runs the validator policy — the privileged
   ``expert`` — on Route A (warning condition) and Route B in one batched call and keeps a pair
   only when both routes are completed without any gate failure, the warning starts and ends
   exactly once and the physical event and its clearance are recorded on Route A;
4. the first four accepted candidates of each slot form the suite.

This is an evaluation-layer concern (it runs the simulator and a policy), so it lives above
:mod:`lantern_jax.scenarios`.  :func:`verify_regeneration` regenerates a shipped suite from its
seed and compares every hash.

The validator is part of what makes a suite: the manifest's generation report names it
(``validator``), and a suite regenerates only with the validator that filtered it.
``lantern-v1`` predates that record and was filtered by the first privileged reference, now
registered as ``expert-v1`` (:data:`LEGACY_VALIDATOR`); new suites use ``expert``.
"""

from __future__ import annotations

import jax
import numpy as np

from lantern_jax.constants import DT, FAMILIES, WEATHERS
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import sample_params
from lantern_jax.scenarios.suite import (
    SUITE_ID,
    PairSpec,
    load_suite,
    static_check,
    suite_hash,
)
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.rollout import rollout_batch
from lantern_jax.times import happened
from lantern_jax.world import Scenario, tree_stack

DEFAULT_SEED = 20260611
PAIRS_PER_SLOT = 4  # per family per weather profile
CANDIDATES_PER_SLOT = 8
EXPERT_MIN_PROGRESS = 0.99  # route completion the expert must reach on both routes
VALIDATOR = "expert"  # policy that filters newly generated suites
LEGACY_VALIDATOR = "expert-v1"  # the validator of manifests that do not name one (lantern-v1)


def dynamic_check(
    scenarios_a: list[Scenario],
    scenarios_b: list[Scenario],
    max_ticks: int | None = None,
    validator: str = VALIDATOR,
):
    """Run the validator on Route A (warning) and Route B of many pairs in one batched call.

    Returns:
        (accepted (N,) bool, reasons list[str] — "" for accepted pairs).
    """
    expert = get_policy(validator)
    params = expert.init(jax.random.PRNGKey(0))
    n = len(scenarios_a)
    batch = tree_stack(list(scenarios_a) + list(scenarios_b))
    if max_ticks is None:
        max_ticks = int(np.ceil(float(np.max(np.asarray(batch.config.timeout_s))) / DT))
    final = jax.jit(
        lambda sc: rollout_batch(sc, expert.act, params, max_ticks, privileged=expert.privileged)
    )(batch)
    m = jax.tree.map(np.asarray, finalize(final.telemetry))
    proto = jax.tree.map(np.asarray, final.protocol)
    gates = ("gate_collision", "gate_route_deviation", "gate_lane", "gate_rule", "gate_block")
    ok, reasons = np.ones(n, bool), [""] * n
    for i in range(n):
        why = []
        for j, tag in ((i, "A"), (n + i, "B")):
            if m.progress[j] < EXPERT_MIN_PROGRESS:
                why.append(f"{tag}: route not completed")
            for g in gates:
                if not bool(getattr(m, g)[j]):
                    why.append(f"{tag}: {g} failed")
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


def _candidates(seed: int, candidates_per_slot: int) -> tuple[list[tuple], dict[str, int]]:
    """Sample and statically check every slot's candidates, in slot order.

    Returns:
        (candidates ``(weather index, family index, k, params, scenario_a, scenario_b, meta)``,
        static rejects per family).
    """
    cands, seen = [], set()
    static_rejects: dict[str, int] = {f: 0 for f in FAMILIES}
    for wi, weather in enumerate(WEATHERS):
        for fi, fam in enumerate(FAMILIES):
            rng = _slot_rng(seed, wi, fi)
            for k in range(candidates_per_slot):
                params = sample_params(fam, rng, weather)
                try:
                    a, b, meta = static_check(params, seen)
                except ValueError:
                    static_rejects[fam] += 1
                    continue
                seen.add(meta["content_hash"])
                cands.append((wi, fi, k, params, a, b, meta))
    return cands, static_rejects


def _select(cands: list[tuple], ok, reasons, pairs_per_slot: int) -> tuple[list[dict], dict]:
    """The first ``pairs_per_slot`` accepted candidates of every slot, and counts per family.

    Raises:
        RuntimeError: naming the slots that could not be filled.
    """
    pairs, counters = [], {f: 0 for f in FAMILIES}
    tried = {f: 0 for f in FAMILIES}
    passed = {f: 0 for f in FAMILIES}
    filled: dict[tuple[int, int], int] = {}
    rejects: dict[str, list[str]] = {f: [] for f in FAMILIES}
    for c, good, why in zip(cands, ok, reasons, strict=True):
        wi, fi, _, params, _, _, meta = c
        fam = FAMILIES[fi]
        tried[fam] += 1
        passed[fam] += int(good)
        if not good:
            rejects[fam].append(why)
            continue
        if filled.get((wi, fi), 0) >= pairs_per_slot:
            continue
        filled[(wi, fi)] = filled.get((wi, fi), 0) + 1
        counters[fam] += 1
        pair_id = f"{fam.lower()}_{counters[fam]:04d}"
        pairs.append(dict(pair_id=pair_id, family=fam, weather=WEATHERS[wi],
                          sha256=meta["content_hash"], params=params))  # fmt: skip
    missing = [
        (WEATHERS[w], FAMILIES[f])
        for w in range(len(WEATHERS))
        for f in range(len(FAMILIES))
        if filled.get((w, f), 0) < pairs_per_slot
    ]
    if missing:
        short = {k: v for k, v in filled.items() if v < pairs_per_slot}
        raise RuntimeError(f"not enough valid candidates for slots {missing} ({short})")
    pairs.sort(key=lambda p: (FAMILIES.index(p["family"]), p["pair_id"]))
    stats = dict(
        dynamic_tried=tried,
        expert_pass_rate={f: passed[f] / max(tried[f], 1) for f in FAMILIES},
        dynamic_reject_reasons={f: sorted(set(r))[:10] for f, r in rejects.items()},
    )
    return pairs, stats


def generate_suite(
    seed: int = DEFAULT_SEED,
    pairs_per_slot: int = PAIRS_PER_SLOT,
    candidates_per_slot: int = CANDIDATES_PER_SLOT,
    progress: bool = True,
    validator: str = VALIDATOR,
) -> dict:
    """Generate, validate and select a suite; returns the manifest dict.

    Args:
        seed: generation seed.
        pairs_per_slot: accepted pairs per (weather, family) slot (4 for lantern-v1).
        candidates_per_slot: candidates sampled per slot before filtering.
        progress: print progress lines.
        validator: registered policy of the dynamic validation (recorded in the report).
    """
    cands, static_rejects = _candidates(seed, candidates_per_slot)
    if progress:
        print(f"[suite] {len(cands)} candidates passed static validation; running {validator}")
    ok, reasons = dynamic_check([c[4] for c in cands], [c[5] for c in cands],
                                validator=validator)  # fmt: skip
    pairs, stats = _select(cands, ok, reasons, pairs_per_slot)
    report = dict(candidates_per_slot=candidates_per_slot, static_rejected=static_rejects,
                  validator=validator, **stats)  # fmt: skip
    specs = [PairSpec(p["pair_id"], p["family"], p["weather"], p["params"], p["sha256"])
             for p in pairs]  # fmt: skip
    return dict(
        suite_id=SUITE_ID,
        format_version=1,
        seed=seed,
        pairs=pairs,
        suite_sha256=suite_hash(specs),
        generation_report=report,
    )


def suite_validator(report: dict | None) -> str:
    """The validator policy named by a generation report (:data:`LEGACY_VALIDATOR` if none)."""
    return (report or {}).get("validator", LEGACY_VALIDATOR)


def verify_regeneration(name: str = SUITE_ID) -> tuple[bool, str]:
    """Regenerate a shipped suite from its seed (with its own validator) and compare every pair
    hash and the suite hash."""
    shipped = load_suite(name)
    fresh = generate_suite(shipped.seed, progress=False, validator=suite_validator(shipped.report))
    got = [(p["pair_id"], p["sha256"]) for p in fresh["pairs"]]
    want = [(p.pair_id, p.sha256) for p in shipped.pairs]
    for g, w in zip(got, want, strict=False):
        if g != w:
            return (
                False,
                f"first mismatch at pair {w[0]}: shipped {w[1][:12]}, regenerated {g[1][:12]}",
            )
    if len(got) != len(want):
        return False, f"pair count differs: shipped {len(want)}, regenerated {len(got)}"
    return fresh["suite_sha256"] == shipped.suite_sha256, "suite hash " + fresh["suite_sha256"]


