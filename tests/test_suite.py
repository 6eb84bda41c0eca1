"""The frozen suite lantern-v3: composition, hashes, tamper detection, static validation,
geometric diversity (no near duplicates), the premise, recorded routes."""

from __future__ import annotations

import collections
import copy
import importlib
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import FAMILIES, WEATHERS
from lantern_jax.scenarios.duplicates import near_duplicates, route_samples
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.premise import PREMISE_NONE, hazard_visible_at_warning, premise_rule
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import (
    SUITE_ID,
    SuiteError,
    _shipped_path,
    load_suite,
    static_check,
    suite_hash,
    write_manifest,
)


@pytest.fixture(scope="module")
def suite():
    return load_suite()


@pytest.fixture(scope="module")
def raw():
    return json.loads(_shipped_path(SUITE_ID).read_text())


def test_composition(suite):
    """120 pairs: 20 per family; five weather profiles x 24 pairs, 4 per family per profile."""
    assert len(suite) == 120
    by_family = collections.Counter(p.family for p in suite.pairs)
    assert by_family == {f: 20 for f in FAMILIES}
    by_weather = collections.Counter(p.weather for p in suite.pairs)
    assert by_weather == {w: 24 for w in WEATHERS}
    cell = collections.Counter((p.family, p.weather) for p in suite.pairs)
    assert set(cell.values()) == {4}
    assert len({p.sha256 for p in suite.pairs}) == 120
    assert len({p.pair_id for p in suite.pairs}) == 120


def test_hashes_reproduce_from_parameters(suite, raw):
    for p in suite.pairs:
        assert content_hash(p.params) == p.sha256
    assert suite_hash(suite.pairs) == raw["suite_sha256"] == suite.suite_sha256


def test_tampered_manifest_names_the_first_mismatching_pair(raw, tmp_path):
    bad = copy.deepcopy(raw)
    bad["pairs"][7]["params"]["v_ref"] += 0.5
    bad["pairs"][9]["params"]["v_ref"] += 0.5
    path = tmp_path / "tampered.json"
    write_manifest(bad, path)
    first = raw["pairs"][7]["pair_id"]
    with pytest.raises(ValueError, match=rf"pair {first}: sha256: does not match its parameters"):
        load_suite(path)


def test_manifest_structure_errors(raw, tmp_path):
    bad = copy.deepcopy(raw)
    del bad["pairs"][3]["sha256"]
    path = tmp_path / "missing.json"
    write_manifest(bad, path)
    pid = raw["pairs"][3]["pair_id"]
    with pytest.raises(ValueError, match=rf"pair {pid}: sha256: missing"):
        load_suite(path)
    reordered = copy.deepcopy(raw)
    reordered["pairs"][0], reordered["pairs"][1] = reordered["pairs"][1], reordered["pairs"][0]
    path = tmp_path / "reordered.json"
    write_manifest(reordered, path)
    with pytest.raises(ValueError, match="suite hash mismatch"):
        load_suite(path)
    with pytest.raises(FileNotFoundError, match="lantern-v3"):
        load_suite("lantern-v9")


def test_every_shipped_pair_passes_static_validation(suite):
    seen: set[str] = set()
    for p in suite.pairs:
        _, _, meta = static_check(p.params, seen)
        seen.add(meta["content_hash"])
    with pytest.raises(ValueError, match="duplicate content hash"):
        static_check(suite.pairs[0].params, {suite.pairs[0].sha256})


def test_slot_comparison_equals_the_slot_by_slot_reference(suite):
    """Route A and Route B's actor slots compared all at once equal the comparison of each slot
    alone (every leaf of the script and the start state); a changed value, or a NaN, in one
    leaf of one slot makes that slot, and only it, differ."""
    from lantern_jax.scenarios.suite import _slots_equal, _tree_equal

    def reference(x, y):
        return np.array([_tree_equal(jax.tree.map(lambda v, i=i: np.asarray(v)[i], x),
                                     jax.tree.map(lambda v, i=i: np.asarray(v)[i], y))
                         for i in range(x[0].num)])  # fmt: skip

    for p in (next(q for q in suite.pairs if q.family == f) for f in ("PE", "LWW")):
        a, b, meta = build_pair(p.params)
        x, y = (a.actors, a.actors0), (b.actors, b.actors0)
        got = _slots_equal(x, y)
        np.testing.assert_array_equal(got, reference(x, y))
        assert not got[meta["scenario_slots"][0]]  # the hazard's script differs
        other = next(i for i in range(a.actors.num) if i not in meta["scenario_slots"])
        assert got[other]
        for value in (123.0, np.nan):
            xy = np.asarray(b.actors0.xy).copy()
            xy[other, 0] = value
            y2 = (b.actors, b.actors0.replace(xy=xy))
            got2 = _slots_equal(x, y2)
            np.testing.assert_array_equal(got2, reference(x, y2))
            assert not got2[other] and np.array_equal(np.delete(got2, other), np.delete(got, other))


def test_static_validation_rejects_a_short_recovery(suite):
    p = next(q for q in suite.pairs if q.family == "PE")
    params = dict(p.params)
    params["route_length"] = 68.0
    params["conflict_s"] = 48.0
    with pytest.raises(ValueError):
        static_check(params, set())


def test_no_near_duplicates_within_a_family_from_the_file_alone(suite):
    """The paper's rule (>= 70 % of 2-m samples within 3 m, both ways, start-pose frame) on the
    routes the manifest records: no pair of routes of one family is a near duplicate."""
    for fam in FAMILIES:
        routes = [np.asarray(p.route_2m, np.float64) for p in suite.pairs if p.family == fam]
        assert len(routes) == 20 and all(r.shape[1] == 2 and len(r) > 20 for r in routes)
        assert near_duplicates(routes) == [], fam


def test_recorded_routes_are_the_built_routes(suite):
    for p in suite.pairs[::11]:
        a, _, _ = build_pair(p.params)
        np.testing.assert_allclose(route_samples(a), np.asarray(p.route_2m), atol=1.5e-3)


def test_premise_holds_on_every_shipped_pair(suite):
    """PE, OR, LWW and RWW: the hazard is hidden from the front camera at the warning point."""
    assert [f for f in FAMILIES if premise_rule(f) != PREMISE_NONE] == ["PE", "OR", "LWW", "RWW"]
    for p in suite.pairs:
        if premise_rule(p.family) != PREMISE_NONE:
            a, _, meta = build_pair(p.params)
            assert not hazard_visible_at_warning(a, meta).any(), p.pair_id


def test_subset_and_select(suite):
    sub = suite.subset(2)
    assert len(sub) == 12
    assert collections.Counter(p.family for p in sub.pairs) == {f: 2 for f in FAMILIES}
    sel = suite.select(["rty_0003", "pe_0001"])
    assert [p.pair_id for p in sel.pairs] == ["rty_0003", "pe_0001"]
    with pytest.raises(KeyError, match="nope_0001"):
        suite.select(["nope_0001"])


def _soft_pair_gradients(suite, temp: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """The soft Route A safety ``S_A`` and the soft CUS of the first PE pair under coop, and
    their derivatives with respect to the pedestrian's crossing speed, through whole Route A
    and Route B executions (the route's timeout): one reverse-mode program for both."""
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.scenarios.knobs import set_knobs
    from lantern_jax.scoring.cus import soft_pair_components
    from lantern_jax.sim.rollout import horizon_ticks, rollout
    from lantern_jax.sim.settings import DEFAULT_SETTINGS

    p = next(q for q in suite.pairs if q.family == "PE")
    a, b, _ = build_pair(p.params)
    pol = get_policy("coop")
    params = pol.init(jax.random.PRNGKey(0))
    n = horizon_ticks(float(a.config.timeout_s))
    settings = DEFAULT_SETTINGS.with_temperature(temp)

    def scores(v_post):
        fa, _ = rollout(set_knobs(a, hazard_speed=v_post), pol, params, n, settings=settings)
        fb, _ = rollout(b, pol, params, n, settings=settings)
        comps = soft_pair_components(fa.telemetry, fb.telemetry, a.config.d_safe, temp)
        out = jnp.stack([comps["S_A"], comps["CUS"]])
        return out, out

    grads, values = jax.jit(jax.jacrev(scores, has_aux=True))(jnp.float32(3.0))
    return np.asarray(values), np.asarray(grads)


@pytest.mark.slow
def test_soft_safety_and_cus_gradients_through_whole_routes(suite):
    """d(soft Route A safety S_A)/d(pedestrian crossing speed) and d(soft CUS)/d(the same) over
    whole Route A and B executions (both routes completed, so the soft gates are open) are
    finite and non-zero: the crossing speed moves the pedestrian relative to the ego, so the
    soft TTC and clearance respond, and the CUS with them."""
    (s_a, cus), (d_s_a, d_cus) = _soft_pair_gradients(suite)
    assert 0.0 < s_a < 1.0 and 0.0 < cus <= 100.0
    assert np.isfinite(d_s_a) and abs(d_s_a) > 1e-4
    assert np.isfinite(d_cus) and abs(d_cus) > 1e-3


def test_a_suite_loaded_again_is_equal_and_the_callers_own():
    """A process validates a manifest once (by its text and the registered families) and hands
    every caller a copy: equal, but changing one does not change the next load."""
    a, b = load_suite(), load_suite()
    assert a == b and a is not b
    a.pairs[0].params["route_length"] = -1.0
    a.report["changed"] = True
    c = load_suite()
    assert c == b and "changed" not in c.report


def test_an_edited_manifest_is_validated_again(tmp_path, raw):
    path = tmp_path / "mine.json"
    raw = copy.deepcopy(raw)
    raw["suite_id"] = "mine"
    path.write_text(json.dumps(raw), encoding="utf-8")
    assert len(load_suite(path)) == 120
    raw["pairs"][0]["params"]["route_length"] = 1e6  # out of range: the file must fail now
    path.write_text(json.dumps(raw), encoding="utf-8")
    with pytest.raises(SuiteError, match="route_length"):
        load_suite(path)


def test_a_suite_whose_families_are_no_longer_registered_is_refused_again():
    """The registered families are part of what a validation read: once the unseen hazards
    are forgotten, their suite is refused as it would be in a new process."""
    from lantern_jax.scenarios import registry

    state = registry.snapshot()  # before anything registers the unseen hazards
    transfer = importlib.import_module("lantern_jax.apps.transfer")
    unseen = importlib.import_module("lantern_jax.scenarios.unseen")
    for record in (unseen.CYCLIST, unseen.EMERGENCY, unseen.REVERSING):
        registry.register_family(record)  # the held entry again if the import registered it
    assert len(load_suite(transfer.UNSEEN_SUITE_ID)) > 0
    registry.restore(state)
    with pytest.raises(SuiteError, match="register"):
        load_suite(transfer.UNSEEN_SUITE_ID)
