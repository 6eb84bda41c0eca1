"""The frozen closed-loop suite ``lantern-v3``: pairs, static validation, manifest, loading.

120 matched Route A/B pairs: 20 per family, five weather profiles x 24 pairs (4 per family per
profile), as in the paper's appendix A.  A suite is generated from a seed by
:mod:`lantern_jax.apps.suite_generation` (which needs the simulator and the expert to validate
candidates dynamically); this module holds what does not: the :class:`Suite` and
:class:`PairSpec` types, **static validation** (:func:`static_check`: a candidate whose parameters
are out of range or infeasible — occluders overlapping the route corridor included —, whose markers
are out of order or off the route, whose recovery stretch is shorter than 29 m, whose junction has
fewer than three arms or turns the wrong way, whose Route A and Route B disagree on anything they
must share, whose hazard the front camera can see at the warning point (the premise,
:mod:`lantern_jax.scenarios.premise`), or whose content hash repeats, is rejected), manifest
writing and loading.  Near duplicates within a family (:mod:`lantern_jax.scenarios.duplicates`)
are rejected by generation, which knows the pairs already selected.

The manifest (``lantern_jax/data/lantern-v3.json``) stores every pair's parameter dict, its
SHA-256 content hash and its route resampled every 2 m (``route_2m``, world frame, so anyone
can re-check near duplicates from the file alone), the suite hash, and the generation report
(candidate counts, rejections by reason, the expert's pass rate before filtering).
:func:`load_suite` validates the whole file — types, ranges, labels, duplicates, every hash —
before anything is built, and names the file, the pair and the field of every problem.
"""

from __future__ import annotations

import collections
import copy
import dataclasses
import hashlib
import json
import os
from importlib import resources
from pathlib import Path

import jax
import numpy as np

from lantern_jax.core import family_codes
from lantern_jax.core.constants import SUITE_ID, WEATHERS
from lantern_jax.io.files import atomic_write
from lantern_jax.scenarios.adversary import uniform_tracks
from lantern_jax.scenarios.assemble import host_arrays
from lantern_jax.scenarios.families import build_pair, param_errors, validate_params
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY
from lantern_jax.scenarios.premise import premise_error
from lantern_jax.scenarios.spec import MIN_RECOVERY_M, SEED_MAX, content_hash
from lantern_jax.types.world import Scenario

TURN_FAMILIES = {"LWW": 1.0, "RWW": -1.0, "RTY": -1.0}  # sign of the heading change


@dataclasses.dataclass(frozen=True)
class PairSpec:
    """One pair of a suite: its id, family, weather, parameter dict, content hash and (from a
    manifest that records it) its route resampled every 2 m."""

    pair_id: str
    family: str
    weather: str
    params: dict
    sha256: str
    route_2m: list | None = None  # [[x, y], ...] m, world frame


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
        """The first ``n_per_family`` pairs of every family (for quick runs and tests).

        Raises:
            ValueError: when ``n_per_family`` is not a positive integer.
        """
        if isinstance(n_per_family, bool) or not isinstance(n_per_family, int) or n_per_family < 1:
            raise ValueError(f"pairs per family must be an integer >= 1, got {n_per_family!r}")
        keep, count = [], dict.fromkeys(family_codes.codes(), 0)
        for p in self.pairs:
            if count.get(p.family, 0) < n_per_family:
                keep.append(p)
                count[p.family] = count.get(p.family, 0) + 1
        return dataclasses.replace(
            self, pairs=tuple(keep), suite_sha256=suite_hash(keep), suite_id=self.suite_id + "-sub"
        )

    def select(self, pair_ids: list[str]) -> Suite:
        """The pairs with the given ids, in the given order.

        Raises:
            ValueError: for an empty selection or an id given more than once.
            KeyError: listing the ids that are not in the suite.
        """
        if isinstance(pair_ids, str):
            pair_ids = [pair_ids]
        if not pair_ids:
            raise ValueError(f"no pair ids given (suite {self.suite_id} has {len(self)} pairs)")
        twice = sorted({i for i in pair_ids if list(pair_ids).count(i) > 1})
        if twice:
            raise ValueError(f"pair ids given more than once: {', '.join(twice)}")
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


def _slots_equal(a, b) -> np.ndarray:
    """(A,) bool: whether two trees whose every leaf leads with the ``A`` actor slots hold equal
    values in slot ``i`` (every leaf; NaN equals nothing, as in :func:`_tree_equal`).  Compared
    on host copies, all slots at once: indexing device arrays slot by slot dispatched one
    operation per leaf and slot, most of a suite generation's time."""
    la = [np.asarray(x) for x in jax.tree.leaves(a)]
    lb = [np.asarray(y) for y in jax.tree.leaves(b)]
    n = len(la[0]) if la else 0
    if len(la) != len(lb) or any(x.shape != y.shape for x, y in zip(la, lb, strict=True)):
        return np.zeros(n, bool)
    same = np.ones(n, bool)
    for x, y in zip(la, lb, strict=True):
        if x.size:  # a leaf of no values per slot compares equal
            same &= (x == y).reshape(n, -1).all(axis=1)
    return same


def _heading_change(scenario: Scenario, s0: float, s1: float) -> float:
    """rad, the route's heading change from arc ``s0`` to arc ``s1`` (the turn through the
    junction box, so that gently bending arms do not count)."""
    r = np.asarray(scenario.route.xy, np.float64)[np.asarray(scenario.route.valid)]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))])
    d = np.diff(r, axis=0)
    h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    mid = 0.5 * (s[1:] + s[:-1])
    return float(np.interp(s1, mid, h) - np.interp(s0, mid, h))


def static_check(params: dict, seen_hashes: set[str]) -> tuple[Scenario, Scenario, dict]:
    """Static validation of one candidate; returns the built pair.

    Raises:
        ValueError: naming the failed check.
    """
    validate_params(params)
    a, b, meta = build_pair(params, validate=False)
    a.validate()
    b.validate()
    fam = meta["family"]
    pa = a.config
    s_warn, s_event, s_conflict = float(pa.s_warn), float(pa.s_event), float(pa.s_conflict)
    if fam == "RTY":
        if not (s_warn == s_event < s_conflict or s_warn == s_event == s_conflict):
            raise ValueError(f"{fam}: warning and event points must coincide")
    elif not s_warn < s_event < s_conflict:
        raise ValueError(f"{fam}: markers out of order ({s_warn}, {s_event}, {s_conflict})")
    length = float(a.route.length)
    if length - s_conflict < MIN_RECOVERY_M - 1e-3:
        raise ValueError(f"{fam}: recovery {length - s_conflict:.1f} m < {MIN_RECOVERY_M} m")
    if fam in TURN_FAMILIES:
        box = meta["canonical"]
        turn = _heading_change(a, box["box_in_s"], box["box_out_s"])
        if np.sign(turn) != TURN_FAMILIES[fam] or abs(turn) < np.pi / 3:
            raise ValueError(f"{fam}: route turns {np.degrees(turn):.0f} deg, wrong direction")
        arms = len(
            {ch for name in meta["lanes"] if ">" not in name for ch in name.split("_")[0]}
            & set("NSEW")
        )
        if arms < 3:
            raise ValueError(f"{fam}: junction with {arms} arms (need >= 3)")
    # Route A and Route B share everything but the hazard behaviour.
    for name in ("route", "lanes", "occluders", "lights"):
        if not _tree_equal(getattr(a, name), getattr(b, name)):
            raise ValueError(f"{fam}: Route A and Route B differ in {name}")
    for f in ("s_warn", "s_event", "s_conflict", "friction", "sensing_range", "v_ref",
              "timeout_s", "ego_light", "ego_stop_s", "family"):  # fmt: skip
        if float(getattr(a.config, f)) != float(getattr(b.config, f)):
            raise ValueError(f"{fam}: Route A and Route B differ in {f}")
    if not _tree_equal(a.ego0, b.ego0):
        raise ValueError(f"{fam}: Route A and Route B differ in the ego start")
    same = _slots_equal((a.actors, a.actors0), (b.actors, b.actors0))
    for i in range(a.actors.num):
        if i not in meta["scenario_slots"] and not same[i]:
            raise ValueError(f"{fam}: Route A and Route B differ in actor slot {i}")
    h = content_hash(params)
    if h in seen_hashes:
        raise ValueError(f"{fam}: duplicate content hash {h[:12]}")
    why = premise_error(a, meta)
    if why is not None:
        raise ValueError(why)
    return a, b, meta


def write_manifest(manifest: dict, path: str | Path) -> None:
    """Write a manifest atomically (:func:`lantern_jax.io.files.atomic_write`).

    Raises:
        IsADirectoryError: when ``path`` is a folder (nothing is written).
    """
    atomic_write(path, json.dumps(manifest, indent=1, sort_keys=False) + "\n")


# ---------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------
def _shipped_path(name: str):
    return resources.files("lantern_jax") / "data" / f"{name}.json"


def shipped_suite_hash(suite_id: str) -> str | None:
    """The suite hash of the shipped suite ``suite_id`` (as its file records it, which
    :func:`load_suite` checks), or None when no suite of that id ships."""
    res = _shipped_path(suite_id)
    if suite_id != SUITE_ID or not res.is_file():
        return None
    return json.loads(res.read_text(encoding="utf-8"))["suite_sha256"]


class SuiteError(ValueError):
    """A suite file that is not valid.

    Attributes:
        source: the file (or shipped suite id) as the caller named it.
        errors: every problem found, each a full message naming the file, the pair (where
            there is one) and the field, e.g.
            ``"suite my.json: pair pe_0003: PE.route_length: 150.0 outside [68, 135]"``.
    """

    MAX_SHOWN = 20

    def __init__(self, source: str, errors: list[str]) -> None:
        self.source = source
        self.errors = list(errors)
        shown = self.errors[: self.MAX_SHOWN]
        more = len(self.errors) - len(shown)
        text = "\n".join(shown) + (f"\n... and {more} more" if more else "")
        super().__init__(text)


def _unregistered_families(raw: object) -> str:
    """One line naming the family codes of a suite file that no registered family has, and how
    to register them ("" when every code is known, or the file is too broken to say)."""
    pairs = raw.get("pairs") if isinstance(raw, dict) else None
    if not isinstance(pairs, list):
        return ""
    known = set(family_codes.codes())

    def code(p: object) -> str | None:  # a family its label and its parameters agree on
        if not isinstance(p, dict) or not isinstance(p.get("params"), dict):
            return None
        label = p.get("family")
        return label if isinstance(label, str) and p["params"].get("family") == label else None

    codes = sorted({c for c in map(code, pairs) if c is not None and c not in known})
    if not codes:
        return ""
    return (f"family code(s) {', '.join(codes)} are not registered in this process; register "
            "them first: on the command line --families FILE.py (the shipped unseen hazards: "
            "--families lantern_jax.scenarios.unseen, or run lantern-jax unseen), from Python "
            "by importing the module that registers them")  # fmt: skip


#: Fields of a suite manifest: name -> required.
MANIFEST_FIELDS = {
    "suite_id": True,
    "format_version": False,
    "seed": False,
    "pairs": True,
    "suite_sha256": True,
    "generation_report": False,
}
PAIR_FIELDS = ("pair_id", "family", "weather", "params", "sha256", "route_2m")
OPTIONAL_PAIR_FIELDS = ("route_2m",)  # a hand-written suite file may leave the route out
_HEX = set("0123456789abcdef")


class _JsonObject(dict):
    """A JSON object that remembers the keys it held more than once."""

    duplicates: tuple[str, ...] = ()


def _json_object(items: list[tuple[str, object]]) -> _JsonObject:
    obj = _JsonObject(items)
    if len(obj) != len(items):
        seen: set[str] = set()
        obj.duplicates = tuple(k for k, _ in items if k in seen or seen.add(k))
    return obj


def _type_name(v: object) -> str:
    names = {dict: "object", _JsonObject: "object", list: "array", str: "string", bool: "bool"}
    return "null" if v is None else names.get(type(v), type(v).__name__)


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_sha256(v: object) -> bool:
    return isinstance(v, str) and len(v) == 64 and set(v) <= _HEX


def _valid_pair_id(v: object) -> bool:
    return (
        isinstance(v, str)
        and v != ""
        and all(c.isascii() and (c.isalnum() or c in "_-.") for c in v)
    )


def _route_problem(route: object) -> str | None:
    """What is wrong with a manifest's ``route_2m`` entry (None when it is a list of at least
    two finite ``[x, y]`` points)."""
    if not isinstance(route, list) or len(route) < 2:
        return f"expected a JSON array of at least two [x, y] points, got {_type_name(route)}"
    for k, pt in enumerate(route):
        ok = (
            isinstance(pt, list)
            and len(pt) == 2
            and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                for v in pt
            )
        )
        if not ok:
            return f"point {k}: expected [x, y] with finite numbers, got {pt!r}"
    return None


def _pair_errors(d: object, i: int) -> tuple[str, list[str], PairSpec | None]:
    """Problems of ``pairs[i]`` (each prefixed ``"pair <id>: "``) and its spec when valid."""
    if not isinstance(d, dict):
        return f"pairs[{i}]", [f"pairs[{i}]: expected a JSON object, got {_type_name(d)}"], None
    pid = d.get("pair_id")
    label = f"pair {pid}" if _valid_pair_id(pid) else f"pairs[{i}]"
    errs: list[str] = []

    def err(field: str, msg: str) -> None:
        errs.append(f"{label}: {field}: {msg}")

    for key in getattr(d, "duplicates", ()):
        err(key, "given more than once")
    for key in d:
        if key not in PAIR_FIELDS:
            err(key, f"unknown field (known: {', '.join(PAIR_FIELDS)})")
    for key in PAIR_FIELDS:
        if key not in d and key not in OPTIONAL_PAIR_FIELDS:
            err(key, "missing")
    if "route_2m" in d:
        problem = _route_problem(d["route_2m"])
        if problem:
            err("route_2m", problem)
    if "pair_id" in d and not _valid_pair_id(pid):
        err("pair_id", f"expected a non-empty string of letters, digits, '_', '-' or '.', "
                       f"got {_type_name(pid)} {pid!r}")  # fmt: skip
    fam, weather, params, sha = (d.get(k) for k in ("family", "weather", "params", "sha256"))
    known = ", ".join(family_codes.codes())
    if "family" in d and not family_codes.is_known(fam):
        err("family", f"{fam!r} not one of {{{known}}}")
    if "weather" in d and (not isinstance(weather, str) or weather not in WEATHERS):
        err("weather", f"{weather!r} not one of {{{', '.join(WEATHERS)}}}")
    if "sha256" in d and not _is_sha256(sha):
        err("sha256", f"expected a 64-digit lowercase hex string, got {_type_name(sha)} {sha!r}")
    if "params" in d:
        if not isinstance(params, dict):
            err("params", f"expected a JSON object, got {_type_name(params)}")
        else:
            for key in getattr(params, "duplicates", ()):
                err(f"params.{key}", "given more than once")
            pfam, pweather = params.get("family"), params.get("weather")
            if not family_codes.is_known(pfam):
                err("params.family", f"{pfam!r} not one of {{{known}}}")
            elif family_codes.is_known(fam) and fam != pfam:
                # the parameters are checked against their own family only once the label
                # agrees; otherwise every field would be reported against the wrong table
                err("family", f"label {fam!r} disagrees with params.family {pfam!r}")
            else:
                if isinstance(weather, str) and "weather" in params and weather != pweather:
                    err("weather", f"label {weather!r} disagrees with params.weather {pweather!r}")
                errs.extend(f"{label}: {m}" for m in param_errors(params))
            if _is_sha256(sha):
                try:
                    h = content_hash(params)
                except ValueError:
                    h = None  # a non-finite or unsupported value, reported above
                if h is not None and h != sha:
                    err("sha256", f"does not match its parameters (manifest {sha[:12]}..., "
                                  f"content {h[:12]}...)")  # fmt: skip
    if errs:
        return label, errs, None
    return label, [], PairSpec(pid, fam, weather, params, sha, d.get("route_2m"))


def _manifest_errors(raw: object) -> tuple[list[str], Suite | None]:
    """Every problem of a parsed manifest (without the file prefix) and the suite when valid."""
    if not isinstance(raw, dict):
        return [f"expected a JSON object at the top level, got {_type_name(raw)}"], None
    errs = [f"{k}: given more than once" for k in getattr(raw, "duplicates", ())]
    for key in raw:
        if key not in MANIFEST_FIELDS:
            errs.append(f"{key}: unknown field (known: {', '.join(MANIFEST_FIELDS)})")
    for key, required in MANIFEST_FIELDS.items():
        if required and key not in raw:
            errs.append(f"{key}: missing")
    sid = raw.get("suite_id")
    if "suite_id" in raw and not (isinstance(sid, str) and sid.strip()):
        errs.append(f"suite_id: expected a non-empty string, got {_type_name(sid)} {sid!r}")
    if "format_version" in raw and (not _is_int(raw["format_version"])
                                    or raw["format_version"] != 1):  # fmt: skip
        errs.append(f"format_version: {raw['format_version']!r} not supported (expected 1)")
    seed = raw.get("seed", -1)
    if "seed" in raw and not (_is_int(seed) and 0 <= seed <= SEED_MAX):
        errs.append(f"seed: expected an integer in [0, {SEED_MAX}], got {_type_name(seed)} "
                    f"{seed!r}")  # fmt: skip
    report = raw.get("generation_report", {})
    if not isinstance(report, dict):
        errs.append(f"generation_report: expected a JSON object, got {_type_name(report)}")
    if "suite_sha256" in raw and not _is_sha256(raw["suite_sha256"]):
        got = raw["suite_sha256"]
        errs.append(f"suite_sha256: expected a 64-digit lowercase hex string, got "
                    f"{_type_name(got)} {got!r}")  # fmt: skip
    pairs_raw = raw.get("pairs", [])
    if not isinstance(pairs_raw, list):
        errs.append(f"pairs: expected a JSON array, got {_type_name(pairs_raw)}")
        pairs_raw = []
    elif "pairs" in raw and not pairs_raw:
        errs.append("pairs: empty (a suite needs at least one pair)")
    pairs: list[PairSpec] = []
    first_at: dict[str, str] = {}
    first_hash: dict[str, str] = {}
    for i, d in enumerate(pairs_raw):
        label, perrs, spec = _pair_errors(d, i)
        errs.extend(perrs)
        pid = d.get("pair_id") if isinstance(d, dict) else None
        if _valid_pair_id(pid):
            if pid in first_at:
                errs.append(f"{label}: pair_id: duplicate (also pairs[{first_at[pid]}])")
            else:
                first_at[pid] = str(i)
        if spec is not None:
            if spec.sha256 in first_hash:
                errs.append(f"{label}: params: same parameters (content hash) as pair "
                            f"{first_hash[spec.sha256]}")  # fmt: skip
            else:
                first_hash[spec.sha256] = spec.pair_id
            pairs.append(spec)
    if errs:
        return errs, None
    got = suite_hash(pairs)
    if got != raw["suite_sha256"]:
        return [f"suite_sha256: suite hash mismatch (manifest {raw['suite_sha256'][:12]}..., "
                f"pairs give {got[:12]}...)"], None  # fmt: skip
    return [], Suite(sid, tuple(pairs), got, int(seed), dict(report))


#: Suites this process has validated, by what their validation read: the manifest's text (its
#: SHA-256) and the registered families (their entries, held here so that their ids stay
#: theirs).  Validating the built-in suite's 120 pairs takes about 0.4 s on a 2-core CPU (each
#: family's feasibility rules), and a process loads a suite many times (every evaluation that
#: names it, every subset); an edited file or another set of families is another key.  At most
#: :data:`VALIDATED_SUITES_KEPT` are kept, the least recently loaded dropped first.
_VALIDATED: collections.OrderedDict[tuple, tuple[tuple, Suite]] = collections.OrderedDict()
VALIDATED_SUITES_KEPT = 8


def _validation_key(text: str) -> tuple[tuple, tuple]:
    """``(key, entries)``: the cache key of a manifest's validation and the family entries it
    names by id."""
    entries = FAMILY_REGISTRY.entries()
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    return (digest, tuple(map(id, entries)), family_codes.registered()), entries


def load_suite(name_or_path: str | Path = SUITE_ID) -> Suite:
    """Load a suite manifest (a shipped suite id or a JSON path) and validate all of it.

    Before anything is built, every field is checked: JSON types of the manifest and of every
    pair, known family and weather labels that agree with the parameters, every parameter's
    type and range and the family's feasibility rules (:func:`~lantern_jax.scenarios.spec.
    param_errors`), duplicate keys, pair ids and scenarios, each pair's content hash and the
    suite hash; a file that carries the id of a shipped suite must carry its pairs too (its
    suite hash).

    Args:
        name_or_path: a shipped suite id (``"lantern-v3"``) or the path of a manifest file.

    Returns:
        The :class:`Suite`.

    Raises:
        SuiteError: listing every problem, each naming the file, the pair and the field
            (``"suite my.json: pair pe_0003: PE.route_length: 150.0 outside [68, 135]"``).
        FileNotFoundError: for an unknown suite name or a missing file.
    """
    p = Path(name_or_path)
    source = str(name_or_path)
    looks_like_path = p.suffix == ".json" or os.sep in source or "/" in source
    if looks_like_path and not p.exists():
        raise FileNotFoundError(f"suite file {source} not found")
    try:
        if looks_like_path:
            text = p.read_text(encoding="utf-8")
        else:
            res = _shipped_path(source)
            if not res.is_file():
                raise FileNotFoundError(f"unknown suite {source!r}; shipped suites: {SUITE_ID}")
            text = res.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise SuiteError(source, [f"suite {source}: cannot read ({e})"]) from None
    key, entries = _validation_key(text)
    if key in _VALIDATED:
        _VALIDATED.move_to_end(key)
        suite = copy.deepcopy(_VALIDATED[key][1])  # the caller's own, as a fresh load gives
    else:
        try:
            raw = json.loads(text, object_pairs_hook=_json_object)
        except json.JSONDecodeError as e:
            raise SuiteError(source, [f"suite {source}: not valid JSON ({e})"]) from None
        unregistered = _unregistered_families(raw)
        if unregistered:
            raise SuiteError(source, [f"suite {source}: {unregistered}"])
        errs, suite = _manifest_errors(raw)
        if errs:
            raise SuiteError(source, [f"suite {source}: {m}" for m in errs])
        _VALIDATED[key] = (entries, copy.deepcopy(suite))
        while len(_VALIDATED) > VALIDATED_SUITES_KEPT:
            _VALIDATED.popitem(last=False)
    shipped = shipped_suite_hash(suite.suite_id) if looks_like_path else None
    if shipped is not None and suite.suite_sha256 != shipped:
        raise SuiteError(source, [
            f"suite {source}: suite_id: {suite.suite_id!r} is the shipped suite's id, but the "
            f"pairs hash to {suite.suite_sha256[:12]}... (shipped: {shipped[:12]}...); give an "
            "edited suite an id of its own"
        ])  # fmt: skip
    return suite


def build_suite_scenarios(suite: Suite) -> tuple[list[Scenario], list[Scenario], list[dict]]:
    """Build Route A and Route B scenarios of every pair (in suite order).

    The pairs' parameters are not checked again: a :class:`Suite` holds only parameters that
    :func:`load_suite` (or the generator) validated.
    """
    wa, wb, metas = [], [], []
    for p in suite.pairs:
        a, b, meta = build_pair(p.params, validate=False)
        wa.append(a)
        wb.append(b)
        metas.append(meta)
    return wa, wb, metas


def build_suite_batches(suite: Suite) -> tuple[Scenario, Scenario]:
    """The Route A and the Route B scenarios of every pair, each stacked along a leading pair
    axis (suite order): built on the host (:func:`~lantern_jax.scenarios.assemble.host_arrays`)
    and stacked there, so the batch costs one transfer instead of one per leaf and pair.

    Returns:
        ``(route_a, route_b)``, Scenario pytrees of NumPy arrays with leading axis ``len(suite)``.
    """
    with host_arrays():
        wa, wb, _ = build_suite_scenarios(suite)
    wa, wb = uniform_tracks(wa), uniform_tracks(wb)  # pairs with and without actor tracks
    stack = lambda items: jax.tree.map(lambda *xs: np.stack(xs), *items)  # noqa: E731
    return stack(wa), stack(wb)
