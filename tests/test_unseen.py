"""The paper's unseen hazards as families, the public family registry, and the response measures
of the unseen-hazard tables.

A family defined in a test file (``tests/family_example.py``, registered with the public API
only) is built, validated, written to a suite file and evaluated through the Python API and the
command line.

Registration is process-wide, and test files share worker processes: the families are
registered by a module fixture, not on import, and forgotten when this module's tests are done
(:func:`lantern_jax.scenarios.registry.snapshot` / ``restore``), so other test files see the six
alone.
"""

from __future__ import annotations

import ast
import dataclasses
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from lantern_jax.apps.diagnostics import run_recorded
from lantern_jax.apps.evaluation import evaluate, family_table
from lantern_jax.cli import main
from lantern_jax.core import family_codes
from lantern_jax.core.constants import (
    DT,
    EGO_MAX_BRAKE,
    FAMILIES,
    KIND_VEHICLE,
    NUM_ACTOR_KINDS,
    WAYPOINT_DT,
)
from lantern_jax.policies.base import Policy
from lantern_jax.policies.planner import route_point
from lantern_jax.scenarios import registry
from lantern_jax.scenarios import warnings as w
from lantern_jax.scenarios.duplicates import near_duplicates, route_samples
from lantern_jax.scenarios.families import build_pair, family, sample_params
from lantern_jax.scenarios.premise import premise_error
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, load_suite, static_check, suite_hash
from lantern_jax.scenarios.warnings import TEMPLATES, render_warning
from lantern_jax.scoring.response import (
    brake_signal,
    pre_event_speed_drop,
    response_time,
    step_start_speeds,
)
from lantern_jax.sim.settings import default_settings

TESTS = Path(__file__).parent
CODES = ("CYC", "EMV", "REV")
#: Modules that register families on import, set by :func:`registered` (module scope).
transfer = unseen = family_example = None
REGISTERING_MODULES = (
    "family_example",
    "lantern_jax.apps.transfer",
    "lantern_jax.scenarios.unseen",
    "lantern_jax_user_families_family_example",
)


@pytest.fixture(scope="module", autouse=True)
def registered():
    """Register the unseen families and JWK for this module's tests, then forget them."""
    global transfer, unseen, family_example
    state = registry.snapshot()
    sys.path.insert(0, str(TESTS))
    try:
        import family_example as fe

        from lantern_jax.apps import transfer as tr
        from lantern_jax.scenarios import unseen as un

        transfer, unseen, family_example = tr, un, fe
        yield
    finally:
        sys.path.remove(str(TESTS))
        for name in REGISTERING_MODULES:
            sys.modules.pop(name, None)
        registry.restore(state)


@pytest.fixture(scope="module")
def suite():
    return transfer.unseen_suite()


def first_pairs(suite):
    """The first pair of every unseen family."""
    return suite.select([f"{c.lower()}_0001" for c in CODES])


# ---------------------------------------------------------------------------------------------
# the unseen families
# ---------------------------------------------------------------------------------------------
def test_the_unseen_families_follow_the_six_and_stay_out_of_the_built_in_suite(suite):
    assert unseen.UNSEEN_CODES == CODES
    assert family_codes.codes()[:6] == FAMILIES
    assert [family(c).index for c in CODES] == [family_codes.index(c) for c in CODES]
    assert min(family(c).index for c in CODES) >= len(FAMILIES)
    assert {p.family for p in load_suite().pairs} == set(FAMILIES)
    assert {p.family for p in suite.pairs} == set(CODES)
    assert all(sum(p.family == c for p in suite.pairs) == 10 for c in CODES)


@pytest.mark.parametrize("code", CODES)
def test_every_shipped_pair_passes_static_validation_and_the_premise_rule(suite, code):
    seen: set[str] = set()
    for p in (p for p in suite.pairs if p.family == code):
        a, _, meta = static_check(p.params, seen)  # raises on a failed check, the premise too
        seen.add(meta["content_hash"])
        assert premise_error(a, meta) is None
        assert meta["family"] == code and int(a.config.family) == family_codes.index(code)
        s_warn, s_event, s_conflict = (float(getattr(a.config, f))
                                       for f in ("s_warn", "s_event", "s_conflict"))  # fmt: skip
        assert 0.0 < s_warn < s_event < s_conflict


@pytest.mark.parametrize("code", CODES)
def test_no_two_routes_of_a_family_are_near_duplicates(suite, code):
    pairs = [p for p in suite.pairs if p.family == code]
    routes = [route_samples(build_pair(p.params)[0]) for p in pairs]
    assert near_duplicates(routes) == []
    for p, r in zip(pairs, routes, strict=True):  # the manifest records the built routes
        np.testing.assert_allclose(np.asarray(p.route_2m), r, atol=1.5e-3)


@pytest.mark.parametrize("code", CODES)
def test_the_hazard_is_hidden_only_by_the_occluders(suite, code):
    """Without the map's occluders the camera sees the hazard at the warning point: the premise
    holds because of them."""
    p = next(p for p in suite.pairs if p.family == code)
    a, _, meta = build_pair(p.params)
    bare = a.replace(occluders=a.occluders.replace(valid=jnp.zeros_like(a.occluders.valid)))
    assert premise_error(a, meta) is None
    assert "premise violated" in premise_error(bare, meta)


def test_the_cyclist_is_a_vehicle_with_a_bicycles_extent_and_kinds_are_unchanged(suite):
    a, _, _ = build_pair(suite.pairs[0].params)
    assert suite.pairs[0].family == "CYC"
    assert int(a.actors.kind[0]) == KIND_VEHICLE
    np.testing.assert_allclose(np.asarray(a.actors.extent[0]), unseen.BIKE_EXTENT)
    assert float(a.actors.v_post[0]) == pytest.approx(4.5)  # the paper's speed
    assert NUM_ACTOR_KINDS == 3  # the learned models' object tokens: 10 + 3 features


def test_warning_texts_are_the_papers_and_none_is_a_canonical_template():
    cyc = family("CYC")
    assert render_warning(w.canonical_text_id("CYC"), (12.34, -3.0)) == (
        "A cyclist hidden behind the parked van at (12.3, -3.0) is about to cross the ego lane"
    )
    assert render_warning(w.paraphrase_text_id("CYC"), (12.34, -3.0)) == (
        "Watch for a bicycle rider emerging from behind the roadside vehicle near (12.3, -3.0); "
        "the rider will enter your path."
    )
    assert cyc.template == unseen.CYCLIST.warning
    for code in CODES:
        for tid in (w.canonical_text_id(code), w.paraphrase_text_id(code)):
            e = w.get_text(tid)
            assert e.family == family_codes.index(code) and e.has_position
            assert e.text not in TEMPLATES
            tokens, values = w.warning_language(jnp.int32(tid), jnp.bool_(True),
                                                jnp.asarray([5.0, -1.5]))  # fmt: skip
            assert w.warning_string(tokens, values) == render_warning(tid, (5.0, -1.5))


def _blind_act(params, obs):
    """Follow the route at the reference speed, seeing nothing."""
    k = jnp.arange(1, 11) * WAYPOINT_DT * obs.v_ref
    return jax.vmap(lambda a: route_point(obs.route, a))(k)


def test_each_hazard_is_a_real_conflict(suite):
    """An ego that follows its route at v_ref and reacts to nothing collides with the hazard
    in every family (the event lead puts them at the conflict point together)."""
    blind = Policy("blind", lambda key: None, _blind_act)
    pairs = first_pairs(suite).pairs
    scenes = [build_pair(p.params)[0] for p in pairs]
    scenes = [s.replace(config=s.config.replace(warning_enabled=np.asarray(False))) for s in scenes]
    _, _, metrics = run_recorded(blind, None, scenes, default_settings())
    assert np.asarray(metrics.gate_collision).tolist() == [0, 0, 0]


@pytest.fixture(scope="module")
def coop_rows(suite):
    return transfer.run_transfer("coop", first_pairs(suite)).rows


def test_the_lifecycle_order_holds(coop_rows):
    """Warning on (at the warning point), event on, direct observation, clearance, in order,
    for every pair and condition."""
    for r in coop_rows.to_dict("records"):
        times = [r["t_on_s"], r["t_event_s"], r["t_seen_s"], r["t_clear_s"]]
        assert np.all(np.isfinite(times)), r
        assert times == sorted(times), r
        assert times[0] < times[1], r


def test_coop_answers_the_words_its_keyword_rule_knows(coop_rows):
    """coop's rule matches "ego lane": the cyclist's free-form and the reversing vehicle's exact
    warning slow it before the event; the paraphrases and the emergency vehicle's warning
    ("ego path") leave it as without a warning."""
    g = coop_rows.set_index(["family", "condition"])
    for code in CODES:
        none, para = g.loc[(code, "no warning")], g.loc[(code, "held-out paraphrase")]
        assert para["dv_mps"] == none["dv_mps"] and para["CUS"] == none["CUS"]
    assert g.loc[("CYC", "warning"), "dv_mps"] > g.loc[("CYC", "no warning"), "dv_mps"] + 0.5
    assert g.loc[("REV", "warning"), "dv_mps"] > g.loc[("REV", "no warning"), "dv_mps"] + 0.5
    assert g.loc[("EMV", "warning"), "CUS"] == g.loc[("EMV", "no warning"), "CUS"]


def test_summary_and_tables(coop_rows):
    summary = transfer.summarize(coop_rows)
    assert len(summary) == 3 * len(transfer.CONDITIONS)
    groups = transfer.table_groups(summary)
    assert [fams for _, fams in groups] == [("CYC",), ("EMV", "REV")]
    rows = transfer.table_rows(summary, ("EMV", "REV"))
    assert list(rows.columns) == list(transfer.HEADERS)
    assert rows["Condition"].tolist() == ["no warning", "exact warning", "held-out paraphrase"] * 2
    assert "[" not in "".join(rows["RC"])  # one pair: no interval
    assert "+2.00 s" in transfer.paper_note(("EMV",))


# ---------------------------------------------------------------------------------------------
# response measures
# ---------------------------------------------------------------------------------------------
def _plan(v0: float, accel: float) -> np.ndarray:
    """(10, 2) waypoints of a constant-acceleration plan from speed ``v0`` (straight ahead)."""
    t = np.arange(1, 11) * WAYPOINT_DT
    x = np.maximum(v0 * t + 0.5 * accel * t**2, 0.0)
    return np.stack([x, np.zeros_like(x)], -1).astype(np.float32)


@pytest.mark.parametrize("decel", [0.0, 2.0, 4.0, 6.0])
def test_brake_signal_is_the_commanded_deceleration_over_the_brake_limit(decel):
    """A constant-deceleration plan commands exactly its deceleration (the controller's
    feed-forward), so its brake signal is decel / 8 m/s^2."""
    got = float(brake_signal(jnp.float32(10.0), jnp.asarray(_plan(10.0, -decel)), jnp.float32(1.0)))
    assert got == pytest.approx(decel / EGO_MAX_BRAKE, abs=2e-3)


def test_a_standing_plan_is_full_brake():
    assert float(brake_signal(jnp.float32(3.0), jnp.zeros((10, 2)), jnp.float32(1.0))) == 1.0


def test_response_time_is_the_first_of_three_consecutive_braking_steps():
    t_end = (np.arange(1, 21) * DT).astype(np.float64)
    brake = np.zeros(20)
    brake[[2, 3]] = 0.9  # two steps only: no response
    brake[[6]] = 0.7  # before t_from: ignored with it
    brake[7:12] = 0.6
    live = np.ones(20, bool)
    assert response_time(t_end, brake, live, 0.0) == pytest.approx(t_end[6] - DT)
    assert response_time(t_end, brake, live, t_end[6]) == pytest.approx(t_end[7] - DT)
    assert np.isnan(response_time(t_end, brake, live, t_end[12]))
    assert np.isnan(response_time(t_end, brake, live, np.nan))
    dead = live.copy()
    dead[9:] = False  # the execution ended: steps 7-8 alone are not three
    assert np.isnan(response_time(t_end, brake, dead, t_end[6]))


def test_pre_event_speed_drop():
    t_end = np.arange(1, 11) * 1.0
    speed = np.array([10, 10, 9, 7, 6, 6.5, 8, 3, 3, 3], np.float64)
    live = np.ones(10, bool)
    # onset at t = 2 (10 m/s), event at t = 6: lowest 6 m/s before it
    assert pre_event_speed_drop(t_end, speed, live, 10.0, 2.0, 6.0) == pytest.approx(4.0)
    # onset between ticks: speed interpolated (t = 2.5: 9.5 m/s)
    assert pre_event_speed_drop(t_end, speed, live, 10.0, 2.5, 6.0) == pytest.approx(3.5)
    # no event: the rest of the execution
    assert pre_event_speed_drop(t_end, speed, live, 10.0, 2.0, np.nan) == pytest.approx(7.0)
    assert np.isnan(pre_event_speed_drop(t_end, speed, live, 10.0, np.nan, 6.0))
    np.testing.assert_array_equal(step_start_speeds(5.0, speed[:3]), [5.0, 10.0, 10.0])


def test_bootstrap_interval():
    lo, hi = transfer.bootstrap_interval(np.full(7, 2.5))
    assert (lo, hi) == (2.5, 2.5)
    x = np.arange(10.0)
    lo, hi = transfer.bootstrap_interval(x)
    assert lo < x.mean() < hi and x.min() <= lo and hi <= x.max()
    assert np.isnan(transfer.bootstrap_interval(np.array([1.0, np.nan]))[0])


# ---------------------------------------------------------------------------------------------
# the registry
# ---------------------------------------------------------------------------------------------
def test_the_unseen_modules_use_only_the_public_api():
    """The unseen families (``unseen.py`` and the ``unseen_*`` modules it builds on) import
    nothing of the package but the registry and each other."""
    paths = sorted(Path(unseen.__file__).parent.glob("unseen*.py"))
    assert {p.stem for p in paths} >= {"unseen", "unseen_common"}
    ours = {f"lantern_jax.scenarios.{p.stem}" for p in paths}
    for path in paths:
        tree = ast.parse(path.read_text())
        imported = {
            n.module if isinstance(n, ast.ImportFrom) else a.name
            for n in ast.walk(tree)
            if isinstance(n, ast.Import | ast.ImportFrom)
            for a in n.names
        }
        inside = {m for m in imported if m and m.startswith("lantern_jax")}
        assert inside <= {"lantern_jax.scenarios", *ours}, path.name
        assert "from lantern_jax.scenarios import registry as fam" in path.read_text(), path.name


def test_registering_again_returns_the_same_family_and_a_clash_is_refused():
    assert registry.register_family(family_example.RECORD) is family_example.FAMILY
    other = dataclasses.replace(family_example.RECORD, name="Another Jaywalker")
    with pytest.raises(ValueError, match="already registered"):
        registry.register_family(other)


def _seed_as_a_field(r):
    return dict(code="JWK2", ranges={**r.ranges, "seed": registry.IntRange(0, 1)})


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda r: dict(code="PE"), "built-in"),
        (lambda r: dict(code="jwk2"), "upper-case"),
        (lambda r: dict(code="JWK2", ranges={"route_length": registry.FloatRange(1, 2)}),
         "v_ref"),
        (_seed_as_a_field, "common fields"),
        (lambda r: dict(code="JWK2", premise="sometimes"), "premise"),
        (lambda r: dict(code="JWK2", knobs={"hazard_warp": (0.0, 1.0)}), "knobs"),
        (lambda r: dict(code="JWK2", paraphrases={}), "paraphrase"),
        (lambda r: dict(code="JWK2", warning="A van at<FRONT_CAR_POS> is stopped."),
         "exactly one space"),
        (lambda r: dict(code="JWK2", paraphrases={"high": ("Near <FRONT_CAR_POS> a van.",)}),
         "no position"),
    ],
)  # fmt: skip
def test_bad_records_are_refused_before_anything_is_registered(change, match):
    known, bank = family_codes.codes(), len(w.registered_bank())
    record = family_example.RECORD
    with pytest.raises(ValueError, match=match):
        registry.register_family(dataclasses.replace(record, **change(record)))
    assert family_codes.codes() == known and len(w.registered_bank()) == bank


def test_snapshot_and_restore_forget_what_was_registered_since():
    state = registry.snapshot()
    bank = len(w.registered_bank())
    other = dataclasses.replace(family_example.RECORD, code="JWK3")
    assert registry.register_family(other).index == len(family_codes.codes()) - 1
    assert "JWK3" in family_codes.codes() and len(w.registered_bank()) == bank + 2
    registry.restore(state)
    assert "JWK3" not in family_codes.codes() and len(w.registered_bank()) == bank
    with pytest.raises(ValueError, match="JWK3"):
        family("JWK3")
    assert family("JWK") is family_example.FAMILY  # what was there before stays


def test_a_user_family_validates_its_parameters_by_its_own_ranges():
    p = sample_params("JWK", np.random.default_rng(0))
    assert set(p) == {"family", "seed", "bg_seed", "weather", "rotation_deg",
                      *family_example.RANGES}  # fmt: skip
    with pytest.raises(ValueError, match=r"JWK.v_ref: 12.0 outside \[7, 9\]"):
        build_pair({**p, "v_ref": 12.0})
    with pytest.raises(ValueError, match="JWK.van_length: missing"):
        build_pair({k: v for k, v in p.items() if k != "van_length"})
    with pytest.raises(ValueError, match="JWK.lanes: unknown parameter"):
        build_pair({**p, "lanes": 2})


def _manifest(pairs: list[dict], suite_id: str) -> dict:
    specs = [PairSpec(d["pair_id"], d["family"], d["weather"], d["params"],
                      content_hash(d["params"])) for d in pairs]  # fmt: skip
    rows = [dict(d, sha256=s.sha256) for d, s in zip(pairs, specs, strict=True)]
    return dict(suite_id=suite_id, pairs=rows, suite_sha256=suite_hash(specs))


@pytest.fixture(scope="module")
def user_suite_file(tmp_path_factory):
    """A suite file of two JWK pairs that pass static validation."""
    rng, pairs = np.random.default_rng(3), []
    while len(pairs) < 2:
        p = sample_params("JWK", rng, "wet_day")
        try:
            static_check(p, set())
        except ValueError:
            continue
        pairs.append(dict(pair_id=f"jwk_{len(pairs) + 1:04d}", family="JWK", weather="wet_day",
                          params=p))  # fmt: skip
    path = tmp_path_factory.mktemp("user") / "jwk_suite.json"
    path.write_text(json.dumps(_manifest(pairs, "jwk-test")))
    return path


def test_a_user_family_evaluates_end_to_end_through_the_api_and_the_command_line(
    user_suite_file, tmp_path, capsys
):
    s = load_suite(str(user_suite_file))
    assert [p.family for p in s.pairs] == ["JWK", "JWK"] and len(s.subset(1)) == 1
    # the split path: the session's world program (a registered family is data to it)
    result = evaluate(["coop"], suite=s, progress=False, path="split")
    fam = result.family_table
    assert list(fam.columns) == ["model", "condition", *FAMILIES, "JWK", "Overall"]
    assert fam[list(FAMILIES)].isna().all().all()
    np.testing.assert_allclose(fam["Overall"], fam["JWK"])  # the only family with pairs
    assert result.premise.iloc[-1]["JWK"] == 4.0  # Route A executions: 2 pairs x 2 conditions
    argv = ["--families", str(TESTS / "family_example.py"), "evaluate", "--policy", "coop",
            "--suite", str(user_suite_file), "--rollout", "split", "--quiet",
            "--out", str(tmp_path)]  # fmt: skip
    code = main(argv)
    out = capsys.readouterr().out
    assert code == 0, out
    assert "JWK" in out.splitlines()[1]  # the family table's header
    written = pd.read_csv(tmp_path / "family_cus.csv")
    np.testing.assert_allclose(written["JWK"], fam["JWK"], atol=1e-6)


def test_tables_of_the_six_are_unchanged_by_registered_families():
    rows = pd.DataFrame(dict(model="m", condition="warning", family=list(FAMILIES),
                             CUS=np.arange(6.0)))  # fmt: skip
    table = family_table(rows)
    assert list(table.columns) == ["model", "condition", *FAMILIES, "Overall"]
    assert family_codes.table_codes(["PE", "CYC", "XX"]) == [*FAMILIES, "CYC"]


def test_an_unknown_family_is_refused():
    with pytest.raises(ValueError, match="family"):
        sample_params("NOPE", np.random.default_rng(0))


def test_the_unseen_command_prints_and_writes_the_tables(suite, coop_rows, tmp_path, capsys):
    subset = first_pairs(suite)
    path = tmp_path / "three.json"
    pairs = [dict(pair_id=p.pair_id, family=p.family, weather=p.weather, params=p.params)
             for p in subset.pairs]  # fmt: skip
    path.write_text(json.dumps(_manifest(pairs, "unseen-three")))
    code = main(["unseen", "--policy", "coop", "--suite", str(path), "--quiet",
                 "--out", str(tmp_path / "out")])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0, out
    assert "Held-out occluded-cyclist case study  (coop" in out
    assert "Controlled transfer to two additional physical events" in out
    assert "paper (Coop-SimLingo, one route), CYC: no warning -0.60 s" in out
    written = pd.read_csv(tmp_path / "out" / "unseen_pairs.csv")
    np.testing.assert_allclose(written["CUS"], coop_rows["CUS"], rtol=1e-4)
    assert main(["unseen", "--policy", "nobody", "--out", str(tmp_path)]) == 2


@pytest.mark.slow
def test_the_unseen_suite_regenerates_from_its_seed(suite):
    from lantern_jax.apps.suite_generation import generate_suite

    fresh = generate_suite(transfer.UNSEEN_SEED, pairs_per_slot=2, families=CODES,
                           suite_id=transfer.UNSEEN_SUITE_ID, progress=False)  # fmt: skip
    assert fresh["suite_sha256"] == suite.suite_sha256
    got = [(p["pair_id"], p["route_2m"]) for p in fresh["pairs"]]
    assert got == [(p.pair_id, p.route_2m) for p in suite.pairs]


def test_the_dataset_plans_a_registered_family_on_its_own_stream():
    from lantern_jax.apps.dataset.generation import _plan_key
    from lantern_jax.apps.dataset.scenes import build_scenes, plan_scenes

    specs = plan_scenes(2, seed=5, families=["JWK"])
    assert [(s.family, s.weather) for s in specs] == [("JWK", "clear_day"), ("JWK", "cloudy_day")]
    rng = np.random.default_rng([5, family_codes.stream("JWK")])
    assert specs[0].params == family("JWK").sample(rng, "clear_day")
    route_a, route_b = build_scenes(specs)
    assert not bool(route_a[0].config.force_event)  # open loop, as the six
    assert "families" not in _plan_key(1, 2, 3) and _plan_key(1, 2, 3, ["JWK"])["families"]


def test_held_out_paraphrases_of_a_family_without_every_tier():
    ids = w.held_out_text_ids(["CYC"] * 3, ["a", "b", "c"])
    assert set(ids.tolist()) == {w.paraphrase_text_id("CYC")}  # only a low-tier text: every tier
    assert w.canonical_text_id("PE") == 0 and w.paraphrase_text_id("PE") == 6
