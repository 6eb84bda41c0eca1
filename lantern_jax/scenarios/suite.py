"""The frozen closed-loop suite ``lantern-v1``: generation, validation, manifest, loading.

120 matched Route A/B pairs: 20 per family, five weather profiles x 24 pairs (4 per family per
profile), as in the paper's appendix A.  Generation is deterministic from a seed:

1. for every (weather, family) slot, candidates are sampled in order from a generator seeded by
   ``(seed, weather index, family index)``;
2. **static validation** (:func:`static_check`) rejects a candidate whose parameters are out of
   range or infeasible, whose markers are out of order or off the route, whose recovery stretch
   is shorter than 29 m, whose junction has fewer than three arms or turns the wrong way, whose
   Route A and Route B disagree on anything they must share, or whose content hash repeats;
3. **dynamic validation** (:func:`dynamic_check`) runs the privileged ``expert`` on Route A
   (warning condition) and Route B in one batched call and keeps a pair only when both routes
   are completed without any gate failure, the warning starts and ends exactly once and the
   physical event and its clearance are recorded on Route A;
4. the first four accepted candidates of each slot form the suite.

The manifest (``lantern_jax/data/lantern-v1.json``) stores every pair's parameter dict and its
SHA-256 content hash, the suite hash, and the generation report (candidate counts and the
expert's pass rate before filtering).  :func:`load_suite` checks every hash and names the first
mismatching pair; :func:`verify_regeneration` regenerates from the seed and compares.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from importlib import resources
from pathlib import Path

import jax
import numpy as np

from lantern_jax.constants import BIG, FAMILIES, WEATHERS
from lantern_jax.files import atomic_write
from lantern_jax.scenarios.families import build_pair, check_feasible, sample_params
from lantern_jax.scenarios.spec import content_hash, validate_params
from lantern_jax.world import World, tree_stack

SUITE_ID = "lantern-v1"
DEFAULT_SEED = 20260611
PAIRS_PER_SLOT = 4  # per family per weather profile
CANDIDATES_PER_SLOT = 8
MIN_RECOVERY = 29.0  # m of route after the conflict point
TURN_FAMILIES = {"LWW": 1.0, "RWW": -1.0, "RTY": -1.0}  # sign of the heading change


@dataclasses.dataclass(frozen=True)
class PairSpec:
    """One pair of a suite: its id, family, weather, parameter dict and content hash."""

    pair_id: str
    family: str
    weather: str
    params: dict
    sha256: str


@dataclasses.dataclass(frozen=True)
class Suite:
    """A loaded, hash-checked suite."""

    suite_id: str
    pairs: tuple[PairSpec, ...]
    suite_sha256: str
    seed: int
    report: dict

    def __len__(self) -> int:
        return len(self.pairs)

    def subset(self, n_per_family: int) -> Suite:
        """The first ``n_per_family`` pairs of every family (for quick runs and tests)."""
        keep, count = [], {f: 0 for f in FAMILIES}
        for p in self.pairs:
            if count[p.family] < n_per_family:
                keep.append(p)
                count[p.family] += 1
        return dataclasses.replace(
            self, pairs=tuple(keep), suite_sha256=suite_hash(keep), suite_id=self.suite_id + "-sub"
        )

    def select(self, pair_ids: list[str]) -> Suite:
        """The pairs with the given ids, in the given order."""
        by_id = {p.pair_id: p for p in self.pairs}
        missing = [i for i in pair_ids if i not in by_id]
        if missing:
            raise KeyError(f"pairs not in suite {self.suite_id}: {missing}")
        keep = [by_id[i] for i in pair_ids]
        return dataclasses.replace(self, pairs=tuple(keep), suite_sha256=suite_hash(keep))


def suite_hash(pairs) -> str:
    """SHA-256 over the ordered (pair id, pair hash) list."""
    body = json.dumps([[p.pair_id, p.sha256] for p in pairs], separators=(",", ":"))
    return hashlib.sha256(body.encode()).hexdigest()


# ---------------------------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------------------------
def _tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(
        np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb, strict=True)
    )


def _heading_change(world: World) -> float:
    r = np.asarray(world.route.xy)[np.asarray(world.route.valid)]
    d = np.diff(r, axis=0)
    h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return float(h[-1] - h[0])


def static_check(params: dict, seen_hashes: set[str]) -> tuple[World, World, dict]:
    """Static validation of one candidate; returns the built pair.

    Raises:
        ValueError: naming the failed check.
    """
    validate_params(params)
    check_feasible(params)
    a, b, meta = build_pair(params)
    a.validate()
    b.validate()
    fam = meta["family"]
    pa = a.params
    s_warn, s_event, s_conflict = float(pa.s_warn), float(pa.s_event), float(pa.s_conflict)
    if fam == "RTY":
        if not (s_warn == s_event < s_conflict or s_warn == s_event == s_conflict):
            raise ValueError(f"{fam}: warning and event points must coincide")
    elif not s_warn < s_event < s_conflict:
        raise ValueError(f"{fam}: markers out of order ({s_warn}, {s_event}, {s_conflict})")
    length = float(a.route.length)
    if length - s_conflict < MIN_RECOVERY - 1e-3:
        raise ValueError(f"{fam}: recovery {length - s_conflict:.1f} m < {MIN_RECOVERY} m")
    if fam in TURN_FAMILIES:
        turn = _heading_change(a)
        if np.sign(turn) != TURN_FAMILIES[fam] or abs(turn) < np.pi / 3:
            raise ValueError(f"{fam}: route turns {np.degrees(turn):.0f} deg, wrong direction")
        arms = len(
            {ch for name in meta["lanes"] if ">" not in name for ch in name.split("_")[0]}
            & set("NSEW")
        )
        if arms < 3:
            raise ValueError(f"{fam}: junction with {arms} arms (need >= 3)")
    # Route A and Route B share everything but the hazard behaviour.
    for name in ("route", "lanes", "lights"):
        if not _tree_equal(getattr(a, name), getattr(b, name)):
            raise ValueError(f"{fam}: Route A and Route B differ in {name}")
    for f in ("s_warn", "s_event", "s_conflict", "friction", "sensing_range", "v_ref",
              "timeout_s", "ego_light", "ego_stop_s", "family"):  # fmt: skip
        if float(getattr(a.params, f)) != float(getattr(b.params, f)):
            raise ValueError(f"{fam}: Route A and Route B differ in {f}")
    if not _tree_equal(a.ego, b.ego):
        raise ValueError(f"{fam}: Route A and Route B differ in the ego start")
    shared = [i for i in range(a.actors.num) if i not in meta["scenario_slots"]]
    for i in shared:
        if not _tree_equal(jax.tree.map(lambda x, i=i: x[i], (a.actors, a.script)),
                           jax.tree.map(lambda x, i=i: x[i], (b.actors, b.script))):  # fmt: skip
            raise ValueError(f"{fam}: Route A and Route B differ in actor slot {i}")
    h = content_hash(params)
    if h in seen_hashes:
        raise ValueError(f"{fam}: duplicate content hash {h[:12]}")
    return a, b, meta


def dynamic_check(worlds_a: list[World], worlds_b: list[World], max_ticks: int | None = None):
    """Run the expert on Route A (warning) and Route B of many pairs in one batched call.

    Returns:
        (accepted (N,) bool, reasons list[str] — "" for accepted pairs).
    """
    from lantern_jax.policies.base import get_policy
    from lantern_jax.scoring.metrics import finalize
    from lantern_jax.sim.rollout import rollout_batch

    expert = get_policy("expert")
    params = expert.init(jax.random.PRNGKey(0))
    n = len(worlds_a)
    batch = tree_stack(list(worlds_a) + list(worlds_b))
    if max_ticks is None:
        max_ticks = int(np.ceil(float(np.max(np.asarray(batch.params.timeout_s))) / 0.05))
    final = jax.jit(lambda w: rollout_batch(w, expert.act, params, max_ticks))(batch)
    m = jax.tree.map(np.asarray, finalize(final.telemetry))
    proto = jax.tree.map(np.asarray, final.world.protocol)
    gates = ("gate_collision", "gate_route_deviation", "gate_lane", "gate_rule", "gate_block")
    ok, reasons = np.ones(n, bool), [""] * n
    for i in range(n):
        why = []
        for j, tag in ((i, "A"), (n + i, "B")):
            if m.progress[j] < 0.99:
                why.append(f"{tag}: route not completed")
            for g in gates:
                if not bool(getattr(m, g)[j]):
                    why.append(f"{tag}: {g} failed")
        if not bool(m.gate_false_brake[n + i]):
            why.append("B: false brake")
        for f in ("t_warn_point", "t_event", "t_warn_off", "t_clear"):
            if not getattr(proto, f)[i] < BIG:
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


def generate_suite(
    seed: int = DEFAULT_SEED,
    pairs_per_slot: int = PAIRS_PER_SLOT,
    candidates_per_slot: int = CANDIDATES_PER_SLOT,
    progress: bool = True,
) -> dict:
    """Generate, validate and select a suite; returns the manifest dict.

    Args:
        seed: generation seed.
        pairs_per_slot: accepted pairs per (weather, family) slot (4 for lantern-v1).
        candidates_per_slot: candidates sampled per slot before filtering.
        progress: print progress lines.
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
    if progress:
        print(f"[suite] {len(cands)} candidates passed static validation; running the expert")
    ok, reasons = dynamic_check([c[4] for c in cands], [c[5] for c in cands])
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
        pairs.append(
            dict(
                pair_id=f"{fam.lower()}_{counters[fam]:04d}",
                family=fam,
                weather=WEATHERS[wi],
                sha256=meta["content_hash"],
                params=params,
            )
        )
    short = {k: v for k, v in filled.items() if v < pairs_per_slot}
    missing = [
        (WEATHERS[w], FAMILIES[f])
        for w in range(len(WEATHERS))
        for f in range(len(FAMILIES))
        if filled.get((w, f), 0) < pairs_per_slot
    ]
    if missing:
        raise RuntimeError(f"not enough valid candidates for slots {missing} ({short})")
    pairs.sort(key=lambda p: (FAMILIES.index(p["family"]), p["pair_id"]))
    report = dict(
        candidates_per_slot=candidates_per_slot,
        static_rejected=static_rejects,
        dynamic_tried=tried,
        expert_pass_rate={f: passed[f] / max(tried[f], 1) for f in FAMILIES},
        dynamic_reject_reasons={f: sorted(set(r))[:10] for f, r in rejects.items()},
    )
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


def write_manifest(manifest: dict, path: str | Path) -> None:
    """Write a manifest atomically (:func:`lantern_jax.files.atomic_write`).

    Raises:
        IsADirectoryError: when ``path`` is a folder (nothing is written).
    """
    atomic_write(path, json.dumps(manifest, indent=1, sort_keys=False) + "\n")


# ---------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------
def _shipped_path(name: str):
    return resources.files("lantern_jax") / "data" / f"{name}.json"


def load_suite(name_or_path: str | Path = SUITE_ID) -> Suite:
    """Load a suite manifest (a shipped suite id or a JSON path) and check every hash.

    Raises:
        ValueError: naming the first pair whose parameters do not match its hash, or the suite
            hash mismatch.
        FileNotFoundError: for an unknown suite name.
    """
    p = Path(name_or_path)
    if p.suffix == ".json" and p.exists():
        text = p.read_text()
    else:
        res = _shipped_path(str(name_or_path))
        if not res.is_file():
            raise FileNotFoundError(f"unknown suite {name_or_path!r}; shipped suites: {SUITE_ID}")
        text = res.read_text()
    raw = json.loads(text)
    for key in ("suite_id", "pairs", "suite_sha256"):
        if key not in raw:
            raise ValueError(f"suite manifest: missing field {key!r}")
    pairs = []
    for i, d in enumerate(raw["pairs"]):
        for key in ("pair_id", "family", "weather", "params", "sha256"):
            if key not in d:
                raise ValueError(f"suite manifest: pairs[{i}] lacks field {key!r}")
        h = content_hash(d["params"])
        if h != d["sha256"]:
            raise ValueError(
                f"suite {raw['suite_id']}: pair {d['pair_id']} does not match its manifest hash "
                f"(manifest {d['sha256'][:12]}..., content {h[:12]}...)"
            )
        pairs.append(PairSpec(d["pair_id"], d["family"], d["weather"], d["params"], d["sha256"]))
    got = suite_hash(pairs)
    if got != raw["suite_sha256"]:
        raise ValueError(f"suite {raw['suite_id']}: suite hash mismatch ({got[:12]}...)")
    return Suite(raw["suite_id"], tuple(pairs), got, int(raw.get("seed", -1)),
                 raw.get("generation_report", {}))  # fmt: skip


def verify_regeneration(name: str = SUITE_ID) -> tuple[bool, str]:
    """Regenerate a shipped suite from its seed and compare every pair hash and the suite hash."""
    shipped = load_suite(name)
    fresh = generate_suite(shipped.seed, progress=False)
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


def build_suite_worlds(suite: Suite) -> tuple[list[World], list[World], list[dict]]:
    """Build Route A and Route B worlds of every pair (in suite order)."""
    wa, wb, metas = [], [], []
    for p in suite.pairs:
        a, b, meta = build_pair(p.params)
        wa.append(a)
        wb.append(b)
        metas.append(meta)
    return wa, wb, metas
