"""The one-call evaluator: batch invariance, determinism, reference-policy invariants, policy
output failures, ablations.

Every test runs on a two-pair suite (one PE pair, one LWW pair) or on one of its pairs alone.
``ego`` and ``coop`` share one act function and differ in their sensors (the privileged
``expert`` has its own act), and an evaluation of all three runs them in one program
(:mod:`lantern_jax.sim.switch`, ego and coop in one branch); module-scoped fixtures share the
runs.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from lantern_jax.apps.evaluation import (
    CONDITIONS,
    ablation_names,
    build_executions,
    evaluate,
    params_hash,
)
from lantern_jax.core.constants import FAMILIES, KIND_PEDESTRIAN
from lantern_jax.policies.base import Policy
from lantern_jax.policies.reference import reference_act
from lantern_jax.policies.registry import get_policy
from lantern_jax.report import OUTPUT_FILES, RUN_RECORD_JSON, write_outputs
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scenarios.warnings import TIERS, get_text, paraphrase_tiers
from lantern_jax.scoring.table import (
    compare_route_tables,
    schema_columns,
    validate_route_table,
)
from lantern_jax.sim.engine import SUITE_BATCH_SHAPE, batch_shape, finalize_batch
from lantern_jax.types.observation import warning_delivered

PAIRS = ["pe_0001", "lww_0001"]  # v_ref 8.45 m/s and 6.29 m/s
ALONE = "lww_0001"  # shorter timeout than pe_0001: alone it runs a shorter horizon
V_SPLIT = 7.5  # m/s, between the two pairs' reference speeds
KEYS = ["model", "condition", "pair_id"]


@pytest.fixture(scope="module")
def shipped():
    return load_suite()


@pytest.fixture(scope="module")
def suite2(shipped):
    return shipped.select(PAIRS)


@pytest.fixture(scope="module")
def base(suite2):
    """The three reference policies on the two-pair suite (one compile)."""
    return evaluate(["expert", "ego", "coop"], suite=suite2, progress=False)


def rows(df: pd.DataFrame, model: str | None = None, condition: str | None = None, drop=()):
    """Rows of a route table (optionally one model / condition) sorted by pair, keys dropped
    where asked, index reset."""
    sel = df
    if model is not None:
        sel = sel[sel["model"] == model]
    if condition is not None:
        sel = sel[sel["condition"] == condition]
    return sel.sort_values("pair_id").drop(columns=list(drop)).reset_index(drop=True)


# ---------------------------------------------------------------------------------------------
# basic shape of the result
# ---------------------------------------------------------------------------------------------
def test_slots_per_device_are_the_backends_or_the_variables(monkeypatch):
    """24 slots per CPU device, the accelerator's count elsewhere; the environment variable
    sets them on any backend, and a value that is not a whole number >= 1 is refused naming
    it."""
    from lantern_jax.sim import engine

    monkeypatch.delenv(engine.COMPACT_SLOTS_ENV, raising=False)
    assert engine.compact_slots("cpu") == engine.COMPACT_SLOTS["cpu"] == 24
    assert engine.compact_slots("gpu") == engine.COMPACT_SLOTS_OTHER
    assert engine.COMPACT_SLOTS_OTHER >= SUITE_BATCH_SHAPE[0]  # the suite in one wave there
    monkeypatch.setenv(engine.COMPACT_SLOTS_ENV, "12")
    assert engine.compact_slots("cpu") == engine.compact_slots("gpu") == 12
    for bad in ("0", "-3", "many", "2.5"):
        monkeypatch.setenv(engine.COMPACT_SLOTS_ENV, bad)
        with pytest.raises(ValueError, match=engine.COMPACT_SLOTS_ENV):
            engine.compact_slots()


def test_result_tables(base, suite2):
    rt = base.route_table
    validate_route_table(rt)
    assert list(rt.columns) == [c for c, _ in schema_columns()]
    assert len(rt) == 3 * len(CONDITIONS) * len(PAIRS)
    assert list(dict.fromkeys(rt["model"])) == ["expert", "ego", "coop"]
    ft = base.family_table
    assert list(ft.columns) == ["model", "condition", *FAMILIES, "Overall"]
    assert len(ft) == 3 * 3  # warning, no-warning, warning gain per model
    # Families without pairs are NaN and left out of Overall.
    present = ["PE", "LWW"]
    absent = [f for f in FAMILIES if f not in present]
    assert ft[absent].isna().all().all()
    np.testing.assert_allclose(ft["Overall"], ft[present].mean(axis=1), rtol=0, atol=1e-9)
    assert len(base.decomposition) == 3 * len(CONDITIONS)
    # Route B efficiency: the expert is the yardstick, so its own time is 100 % of it
    dec = base.decomposition.set_index(["model", "condition"])["B-Time/Exp."]
    assert (dec.loc["expert"] == 100.0).all() and dec.notna().all()
    # intervals: one row per table row, each holding its point estimate
    fam_iv = base.intervals.family.set_index(["model", "condition"])
    for r in ft.to_dict("records"):
        iv = fam_iv.loc[(r["model"], r["condition"])]
        assert iv["Overall_lo"] - 1e-9 <= r["Overall"] <= iv["Overall_hi"] + 1e-9
        assert iv["PE_n"] == 1 and iv["VC_n"] == 0 and iv["Overall_n"] == 2
    assert len(base.intervals.decomposition) == len(base.decomposition)
    m = base.manifest
    assert m["suite_sha256"] == suite2.suite_sha256
    assert m["num_pairs"] == 2 and m["ablation"] == "none"
    assert m["executions_per_policy"] == 6
    coop = get_policy("coop")
    by_name = {p["name"]: p for p in m["policies"]}
    assert by_name["coop"]["params_sha256"] == params_hash(coop.init(jax.random.PRNGKey(0)))
    assert {"jax", "jaxlib", "numpy", "python"} <= set(m["packages"])


# ---------------------------------------------------------------------------------------------
# (a) batch invariance
# ---------------------------------------------------------------------------------------------
def test_pair_alone_equals_pair_in_suite(base, shipped):
    """The reproducibility promise (``REPRODUCIBLE_ATOL``): a pair scored alone equals its rows
    in a larger suite — ids, gates and discrete columns exactly, continuous ones to the
    tolerance (a batch of 1 and a batch of 2 are differently shaped compiled programs)."""
    alone = evaluate(["coop"], suite=shipped.select([ALONE]), progress=False)
    # Alone, the batch is smaller and its horizon shorter; the pair's rows must not change.
    assert alone.manifest["max_ticks"] < base.manifest["max_ticks"]
    got = alone.route_table
    want = base.route_table[
        (base.route_table["pair_id"] == ALONE) & (base.route_table["model"] == "coop")
    ]
    assert len(got) == len(CONDITIONS)
    ok, report = compare_route_tables(want.reset_index(drop=True), got)
    assert ok, report


def test_built_in_suite_shape_is_the_bucket(shipped):
    """:data:`~lantern_jax.sim.engine.SUITE_BATCH_SHAPE` is the built-in suite's trimmed batch,
    and a subset is built at that shape (its slots kept, its executions padded to it)."""
    assert batch_shape(build_executions(shipped).scenarios) == SUITE_BATCH_SHAPE
    sub = build_executions(shipped.select(PAIRS), bucket=True)
    assert sub.pad_to == SUITE_BATCH_SHAPE[0]
    assert batch_shape(sub.scenarios)[1:] == SUITE_BATCH_SHAPE[1:]
    assert build_executions(shipped.select(PAIRS)).pad_to is None


def test_batches_of_different_sizes_share_one_program(base, shipped):
    """Evaluations of different subsets (one pair, three pairs) run the program of the built-in
    suite's batch shape: the second compiles nothing."""
    one = evaluate(["coop"], suite=shipped.select(["vc_0001"]), progress=False)
    three = evaluate(["coop"], suite=shipped.select(["or_0001", "rty_0001", "pe_0002"]),
                     progress=False)  # fmt: skip
    assert len(one.route_table) == 2 and len(three.route_table) == 6
    spent = three.runs[0].timings
    assert spent["trace + lower"] == spent["XLA compile"] == spent["program load"] == 0.0


@pytest.mark.slow  # compiles its own programs; run by the slow tier
def test_one_program_serves_every_policy(base, suite2):
    """``expert`` and ``ego``/``coop`` run in one compiled program (a policy switch): only the
    first policy compiles, and each policy's rows equal those of its own program (the promise;
    on the shipped suite they are identical to the bit)."""
    assert [r.timings["XLA compile"] for r in base.runs[1:]] == [0.0, 0.0]
    own = evaluate(["expert", "ego", "coop"], suite=suite2, progress=False, one_program=False)
    ok, report = compare_route_tables(own.route_table, base.route_table)
    assert ok, report


# ---------------------------------------------------------------------------------------------
# (b) determinism
# ---------------------------------------------------------------------------------------------
def test_same_inputs_give_identical_files(base, suite2, tmp_path):
    r1 = evaluate(["coop"], suite=suite2, progress=False)
    r2 = evaluate(["coop"], suite=suite2, progress=False)
    coop_rows = base.route_table[base.route_table["model"] == "coop"].reset_index(drop=True)
    pd.testing.assert_frame_equal(r1.route_table, coop_rows, check_exact=True)
    f1 = write_outputs(r1, tmp_path / "one")
    f2 = r2.write(tmp_path / "two")  # EvalResult.write: the same files as write_outputs
    assert list(f1) == list(OUTPUT_FILES) == list(f2)
    for name in OUTPUT_FILES:  # the manifest too; only the run record holds wall times
        if name != RUN_RECORD_JSON:
            assert f1[name].read_bytes() == f2[name].read_bytes(), name


# ---------------------------------------------------------------------------------------------
# (c) policies that ignore warnings gain nothing from them
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("model", ["ego", "expert"])
def test_warning_blind_policies_have_zero_gain(base, model):
    ft = base.family_table
    gain = ft[(ft["model"] == model) & (ft["condition"] == "warning gain")]
    assert len(gain) == 1
    values = gain[["PE", "LWW", "Overall"]].to_numpy(float)
    assert np.all(values == 0.0), values
    # Their Route A executions with and without warning are identical.
    differ = ["condition", "t_warn_on_s", "warning_ticks", "warning_delivered"]
    warned = rows(base.route_table, model, "warning")
    silent = rows(base.route_table, model, "no-warning")
    pd.testing.assert_frame_equal(
        warned.drop(columns=differ), silent.drop(columns=differ), check_exact=True
    )
    assert warned["t_warn_on_s"].notna().all() and silent["t_warn_on_s"].isna().all()


def test_coop_gains_from_warnings(base):
    ft = base.family_table
    gain = ft[(ft["model"] == "coop") & (ft["condition"] == "warning gain")]
    assert float(gain["Overall"].iloc[0]) > 0.0


def test_each_run_keeps_the_telemetry_its_metrics_were_read_from(base, suite2):
    """``PolicyRun.telemetry`` is every execution's final telemetry: finalised, it gives the
    run's metrics bit for bit; the soft score of a pair reads it without a second rollout and
    is a CUS in [0, 100]."""
    from lantern_jax.core.constants import ROUTE_B, WARNING_CONDITION
    from lantern_jax.scoring.cus import soft_pair_cus

    execs = build_executions(suite2, bucket=True)
    for run in base.runs:
        assert jax.tree.leaves(run.telemetry)[0].shape[0] == execs.num_executions
        again = finalize_batch(run.telemetry)
        for name, value in run.metrics.items():
            np.testing.assert_array_equal(getattr(again, name), value, err_msg=name)
        tel_a, tel_b = (execs.take(run.telemetry, c) for c in (WARNING_CONDITION, ROUTE_B))
        d_safe = execs.take(execs.scenarios.config.d_safe, WARNING_CONDITION)
        soft = np.asarray(jax.vmap(soft_pair_cus)(tel_a, tel_b, d_safe))
        assert soft.shape == (len(suite2.pairs),) and np.all((soft >= 0) & (soft <= 100))


# ---------------------------------------------------------------------------------------------
# (d), (e) malformed policy outputs
# ---------------------------------------------------------------------------------------------
def test_wrong_output_shape_is_a_clear_error(shipped):
    bad = Policy("bad", lambda key: jnp.zeros(()), lambda params, obs: jnp.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"'bad'.*\(5, 2\).*expected .*\(10, 2\)"):
        evaluate([bad], suite=shipped.select([ALONE]), progress=False)


def _nan_when_warned_fast(params, obs):
    """``coop``, but NaN waypoints while a warning is delivered on a route faster than
    V_SPLIT."""
    wps = reference_act(params, obs)
    return jnp.where(warning_delivered(obs) & (obs.v_ref > V_SPLIT), jnp.nan, wps)


def _nan_late_on_pe_route_b(params, saw_pedestrian, obs):
    """``coop``, but NaN waypoints in the last 40 m of a fast route on which it never saw a
    pedestrian: of the two-pair suite, only PE's Route B (the PE Route A executions see the
    pedestrian emerge; the LWW route is slower than V_SPLIT).  Its carry remembers whether a
    pedestrian was ever in view."""
    wps = reference_act(params, obs)
    saw_pedestrian = saw_pedestrian | jnp.any(obs.visible & (obs.actor_kind == KIND_PEDESTRIAN))
    late = ~saw_pedestrian & (obs.v_ref > V_SPLIT) & (obs.dist_to_route_end < 40.0)
    return jnp.where(late, jnp.nan, wps), saw_pedestrian


@pytest.fixture(scope="module")
def faulty(suite2):
    """Both faulting policies in one evaluation (one compiled program for the two)."""
    coop = get_policy("coop")
    policies = [Policy("coop-nan", coop.init, _nan_when_warned_fast, sensors=coop.sensors),
                Policy("coop-nan-b", coop.init, _nan_late_on_pe_route_b, sensors=coop.sensors,
                       init_carry=lambda p: jnp.asarray(False))]  # fmt: skip
    return evaluate(policies, suite=suite2, progress=False)


def test_nan_waypoints_are_recorded_failures(base, suite2, faulty):
    """NaN waypoints in one execution of the batch fail that row's block gate (CUS 0); every
    other row equals the run of the intact policy."""
    v_ref = {p.pair_id: p.params["v_ref"] for p in suite2.pairs}
    assert v_ref["pe_0001"] > V_SPLIT > v_ref["lww_0001"]
    validate_route_table(faulty.route_table)
    mine = faulty.route_table[faulty.route_table["model"] == "coop-nan"]
    got = mine.set_index(["condition", "pair_id"]).drop(columns="model")
    want = (
        base.route_table[base.route_table["model"] == "coop"]
        .set_index(["condition", "pair_id"])
        .drop(columns="model")
    )
    hit = ("warning", "pe_0001")
    row = got.loc[hit]
    assert row["controller_fault"] == 1
    assert row["not_blocked"] == 0
    assert row["CUS"] == 0.0
    assert want.loc[hit, "controller_fault"] == 0 and want.loc[hit, "CUS"] > 0
    others = [k for k in want.index if k != hit]
    assert len(others) == 3
    pd.testing.assert_frame_equal(got.loc[others], want.loc[others], check_exact=True)
    ft = faulty.family_table
    assert not ft.loc[ft["model"] == "coop-nan", ["PE", "LWW", "Overall"]].isna().any().any()


def test_route_b_fault_is_recorded_and_fails_no_gate(base, faulty):
    """A policy that faults only on Route B: the row says so (route and time), Route A columns
    and every gate are those of the intact policy, and the fault costs only Route B progress (the
    paper: Route B infractions other than false braking affect the CUS only through P_B)."""
    mine = faulty.route_table[faulty.route_table["model"] == "coop-nan-b"]
    got = mine.set_index(["condition", "pair_id"])
    want = base.route_table[base.route_table["model"] == "coop"].set_index(["condition", "pair_id"])
    want = want.loc[got.index]
    pe = got.index.get_level_values("pair_id") == "pe_0001"
    assert (got.loc[pe, "B_controller_fault"] == 1).all()
    assert (got.loc[pe, "B_t_fault_s"] > 3.0).all()
    assert (got.loc[~pe, "B_controller_fault"] == 0).all() and got.loc[
        ~pe, "B_t_fault_s"
    ].isna().all()
    assert (got["controller_fault"] == 0).all() and got["t_fault_s"].isna().all()
    for g in (c for c in got.columns if c.startswith("gate_")):
        assert (got[g] == want[g]).all(), g
    assert (got.loc[pe, "B_progress"] < want.loc[pe, "B_progress"]).all()
    assert (got["A_progress"] == want["A_progress"]).all()
    assert (want["B_controller_fault"] == 0).all() and want["B_t_fault_s"].isna().all()


def test_warning_delivery_is_counted(base):
    """The warning reaches the policy for a number of ticks in the warning condition, never in
    the no-warning condition; a warning-aware policy sees it as long as the others do."""
    t = base.route_table
    warned = t[t["condition"] == "warning"]
    silent = t[t["condition"] == "no-warning"]
    assert (warned["warning_delivered"] == 1).all() and (warned["warning_ticks"] > 5).all()
    assert (silent["warning_delivered"] == 0).all() and (silent["warning_ticks"] == 0).all()
    # The warning lasts from the warning point to termination: at least 1 tick per 0.05 s of
    # [t_warn_on, t_warn_off), rounded.
    span = (warned["t_warn_off_s"] - warned["t_warn_on_s"]) / 0.05
    assert (np.abs(warned["warning_ticks"] - span) <= 1.0).all()


# ---------------------------------------------------------------------------------------------
# (f), (g) ablations
# ---------------------------------------------------------------------------------------------
def test_unknown_ablation_lists_valid_ones(suite2):
    with pytest.raises(ValueError, match="unknown ablation 'nope'.*late_onset.*no_anti_deadlock"):
        evaluate(["coop"], suite=suite2, ablation="nope", progress=False)
    with pytest.raises(ValueError, match="held_out_paraphrase"):
        build_executions(suite2, "nope")


@pytest.fixture(scope="module")
def ablated(base, suite2):
    """coop under every ablation on the two-pair suite (shares the compile of ``base``)."""
    out = {}
    for name in ablation_names():
        if name != "none":
            out[name] = evaluate(["coop"], suite=suite2, ablation=name, progress=False)
    return out


def _route_a_params(suite, ablation):
    """Scenario parameters of every execution (``[A warning | A no-warning | B]`` x pairs) and
    the number of pairs; ablations change the Route A executions."""
    ex = build_executions(suite, ablation)
    return ex.scenarios.config, ex.num_pairs


def test_ablations_are_recorded_and_valid(ablated):
    assert set(ablated) == set(ablation_names()) - {"none"}
    for name, r in ablated.items():
        assert r.manifest["ablation"] == name
        validate_route_table(r.route_table)


def test_late_onset(base, ablated):
    rt = ablated["late_onset"].route_table
    warned = rows(rt, "coop", "warning")
    np.testing.assert_array_equal(warned["t_warn_on_s"], warned["t_event_s"])
    base_warned = rows(base.route_table, "coop", "warning")
    assert (base_warned["t_warn_on_s"] < base_warned["t_event_s"]).all()
    pd.testing.assert_frame_equal(
        rows(rt, "coop", "no-warning"), rows(base.route_table, "coop", "no-warning")
    )


def test_warning_beyond_termination(base, ablated, suite2):
    params, n = _route_a_params(suite2, "warning_beyond_termination")
    np.testing.assert_array_equal(np.asarray(params.warn_hold_extra)[: 2 * n], 10.0)
    rt = ablated["warning_beyond_termination"].route_table
    # coop keeps yielding to a hazard that is gone: recovery takes longer.
    new = rows(rt, "coop", "warning")["recovery_latency_s"].to_numpy()
    old = rows(base.route_table, "coop", "warning")["recovery_latency_s"].to_numpy()
    assert np.all(new >= old) and np.any(new > old)
    pd.testing.assert_frame_equal(
        rows(rt, "coop", "no-warning"), rows(base.route_table, "coop", "no-warning")
    )


def test_no_anti_deadlock(ablated, suite2):
    params, n = _route_a_params(suite2, "no_anti_deadlock")
    assert not np.any(np.asarray(params.force_event)[: 2 * n])
    rt = ablated["no_anti_deadlock"].route_table
    assert len(rt) == len(CONDITIONS) * len(PAIRS)
    assert rt["CUS"].between(0.0, 100.0).all()


def test_noisy_position(base, ablated, suite2):
    params, n = _route_a_params(suite2, "noisy_position")
    np.testing.assert_array_equal(np.asarray(params.pos_noise_m)[: 2 * n], 2.0)
    np.testing.assert_array_equal(np.asarray(params.pos_noise_m)[2 * n :], 0.0)  # Route B
    rt = ablated["noisy_position"].route_table
    pd.testing.assert_frame_equal(
        rows(rt, "coop", "no-warning"), rows(base.route_table, "coop", "no-warning")
    )
    new = rows(rt, "coop", "warning").select_dtypes("float")
    old = rows(base.route_table, "coop", "warning").select_dtypes("float")
    assert not new.equals(old)


def test_held_out_paraphrase(ablated, suite2):
    params, n = _route_a_params(suite2, "held_out_paraphrase")
    route_a = jax.tree.map(lambda x: x[:n], params)
    tiers = paraphrase_tiers(route_a)
    assert sorted(tiers.tolist()) == [0, 1]  # two pairs: two different tiers
    for f, tid, tier in zip(np.asarray(params.family)[:n], np.asarray(params.text_id)[:n], tiers,
                            strict=True):  # fmt: skip
        e = get_text(int(tid))
        assert (e.family, e.kind, e.tier) == (int(f), "paraphrase", TIERS[tier])
    text = np.asarray(params.text_id)
    np.testing.assert_array_equal(text[n : 2 * n], text[:n])  # both Route A conditions
    # coop was built for the canonical wording: a paraphrased warning changes nothing.
    rt = ablated["held_out_paraphrase"].route_table
    differ = ["condition", "t_warn_on_s", "warning_ticks", "warning_delivered"]
    pd.testing.assert_frame_equal(
        rows(rt, "coop", "warning", drop=differ),
        rows(rt, "coop", "no-warning", drop=differ),
        check_exact=True,
    )


def test_wording_table_of_a_template_matcher(base, ablated, suite2):
    """coop understands only the canonical wording: under every tier its paraphrase CUS is its
    no-warning CUS, so retention = no-warning / canonical."""
    from lantern_jax.apps.diagnostics import tier_rows

    params, n = _route_a_params(suite2, "held_out_paraphrase")
    tiers = paraphrase_tiers(jax.tree.map(lambda x: x[:n], params))
    ids = [p.pair_id for p in suite2.pairs]
    canon = rows(base.route_table, "coop", "warning")
    para = rows(ablated["held_out_paraphrase"].route_table, "coop", "warning")
    none = rows(base.route_table, "coop", "no-warning").set_index("pair_id")["CUS"]
    t = tier_rows(canon, para, tiers, ids).set_index("Wording")
    assert t.loc["All tiers", "n"] == len(ids)
    assert t.loc["All tiers", "Paraphrase CUS"] == pytest.approx(none.mean())
    for k, tier in enumerate(TIERS):
        label = [w for w in t.index if w.lower().startswith(tier)][0]
        members = [i for i, tk in zip(ids, tiers, strict=True) if tk == k]
        if members:
            assert t.loc[label, "Paraphrase CUS"] == pytest.approx(none[members].mean())


def test_ablation_table_rows(base, ablated):
    """The paper's ablation columns from each variant's route rows (Event Exposure included)."""
    from lantern_jax.apps.ablation_table import TABLE_COLUMNS, ablation_rows

    full = ablation_rows(base.route_table).set_index(["model", "condition"])
    assert list(full.columns) == list(TABLE_COLUMNS)
    coop = full.loc[("coop", "warning")]
    assert coop["CUS"] == pytest.approx(
        base.family_table.query("model == 'coop' and condition == 'warning'")["Overall"].item()
    )
    assert coop["Event Exp."] == 100.0
    rt = base.route_table
    assert set(rt["event_exposed"]) <= {0, 1}
    assert (rt["event_exposed"] == rt["t_event_s"].notna().astype(int)).all()
    late = ablation_rows(ablated["late_onset"].route_table).set_index(["model", "condition"])
    assert late.loc[("coop", "warning"), "Ant."] <= coop["Ant."]


def test_premise_table(base):
    """The premise, measured: the route table's 0/1 columns and the per-family shares."""
    rt = base.route_table
    for col in ("hazard_hidden_at_warning", "hazard_hidden_before_warning"):
        assert set(rt[col]) <= {0, 1}
    # hidden for the whole approach implies hidden at the warning point
    assert (rt["hazard_hidden_before_warning"] <= rt["hazard_hidden_at_warning"]).all()
    # the PE pedestrian is hidden behind its truck for every model and condition
    assert (rt.loc[rt["family"] == "PE", "hazard_hidden_before_warning"] == 1).all()
    # policies that ignore warnings approach identically with and without the warning
    for model in ("expert", "ego"):
        a = rows(rt, model, "warning")[["hazard_hidden_at_warning", "hazard_hidden_before_warning"]]
        b = rows(rt, model, "no-warning")[list(a.columns)]
        pd.testing.assert_frame_equal(a, b)
    t = base.premise.set_index("measure")
    assert list(t.columns) == [*FAMILIES, "Overall"]
    assert t.loc["hidden at the warning point", "PE"] == 100.0
    assert t.loc["Route A executions", "PE"] == 6 and t.loc["Route A executions", "Overall"] == 12
    share = 100.0 * rt.loc[rt["family"] == "LWW", "hazard_hidden_at_warning"].mean()
    assert t.loc["hidden at the warning point", "LWW"] == pytest.approx(share)


@pytest.mark.slow
def test_slot_scheduling_matches_one_group(shipped, monkeypatch):
    """Stepping the executions in a few refilled slots, 80 ticks per call, gives the same
    results as stepping the whole batch in lockstep to the end (continuous values to float32
    rounding, discrete ones exactly)."""
    from lantern_jax.scoring.metrics import finalize
    from lantern_jax.scoring.thresholds import DEFAULT_SCORING
    from lantern_jax.sim import engine as ev
    from lantern_jax.sim import programs

    monkeypatch.setattr(ev, "REFILL_TICKS", 80)
    monkeypatch.setattr(ev, "compact_slots", lambda backend=None: 4 // jax.device_count())
    execs = build_executions(shipped.select(["pe_0001", "rty_0001", "or_0001"]))
    pol = get_policy("coop")
    params = pol.init(jax.random.PRNGKey(0))

    def init_programs():
        return {k for k in programs._EXECUTABLES if k[0] is ev.initial_states}

    known = init_programs()
    one, _ = ev.run_executions(pol, execs.scenarios, params, execs.max_ticks, compact=False)
    two, _ = ev.run_executions(pol, execs.scenarios, params, execs.max_ticks, compact=True)
    # refilled slots start from the shared initial-state program: one per batch shape (9 and 4
    # slots here), whatever the number of refills
    assert len(init_programs() - known) <= 2 and len(init_programs()) >= 2
    assert int(np.max(np.asarray(one.tick))) > 160  # some executions needed several calls
    assert np.asarray(two.done).all()
    m1, m2 = finalize(one.telemetry, DEFAULT_SCORING), finalize(two.telemetry, DEFAULT_SCORING)
    for f in dataclasses.fields(m1):
        a, b = np.asarray(getattr(m1, f.name)), np.asarray(getattr(m2, f.name))
        if a.dtype.kind == "b":
            np.testing.assert_array_equal(a, b, err_msg=f.name)
        else:
            np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4, err_msg=f.name)


@pytest.mark.parametrize("policy", ["coop", pytest.param("expert", marks=pytest.mark.slow)])
def test_trimmed_padding_changes_no_result(base, suite2, policy):
    """Cutting the unused actor and lane slots (the default batch) keeps every valid slot and
    every result: discrete outputs exactly, continuous ones to the reproducibility promise.
    Both batches run as an evaluation runs them (the policy as its member of the reference
    switch, padded to the suite's batch), so the cut one is the program ``base`` compiled;
    slots cut to the last one a batch uses are :func:`test_trim_padding_on_hand_built_slots`'s."""
    from lantern_jax.apps.evaluation import run_executions
    from lantern_jax.scoring.metrics import finalize
    from lantern_jax.scoring.table import REPRODUCIBLE_ATOL, REPRODUCIBLE_RTOL
    from lantern_jax.sim.switch import reference_driver

    full = build_executions(suite2, trim=False)
    cut = build_executions(suite2, bucket=True)  # cut to the built-in suite's slots
    for part in ("actors", "lanes"):
        v_full = np.asarray(getattr(full.scenarios, part).valid)
        v_cut = np.asarray(getattr(cut.scenarios, part).valid)
        n = v_cut.shape[-1]
        assert n < v_full.shape[-1], part  # these pairs leave trailing slots unused
        np.testing.assert_array_equal(v_cut, v_full[:, :n])
        assert not v_full[:, n:].any()
    pol = get_policy(policy)
    driver, params = reference_driver(pol, pol.init(jax.random.PRNGKey(0)))
    got = [
        finalize(run_executions(driver, e.scenarios, params, e.max_ticks, pad_to=e.pad_to)[0]
                 .telemetry)
        for e in (full, cut)
    ]  # fmt: skip
    for f in dataclasses.fields(got[0]):
        a, b = np.asarray(getattr(got[0], f.name)), np.asarray(getattr(got[1], f.name))
        if a.dtype.kind in "bi":
            np.testing.assert_array_equal(a, b, err_msg=f.name)
        else:
            np.testing.assert_allclose(
                a, b, rtol=REPRODUCIBLE_RTOL, atol=REPRODUCIBLE_ATOL, err_msg=f.name
            )


def test_trim_padding_on_hand_built_slots():
    """``used_slots`` counts up to the last valid slot of any batch member (at least one)."""
    from lantern_jax.types.world import used_slots

    assert used_slots(np.array([[True, False, False, False], [False, False, True, False]])) == 3
    assert used_slots(np.zeros((2, 5), bool)) == 1
    assert used_slots(np.array([False, True, False, True])) == 4


def test_trimmed_batch_keeps_the_flat_observation_vector(suite2):
    """Fixed-size consumers of the observation (the PPO policy, host models) read
    ``observation_vector``: a trimmed batch gives the same vector, padded back to ``OBS_SIZE``."""
    from lantern_jax.policies.features import OBS_SIZE, observation_vector
    from lantern_jax.sim.observe import observe
    from lantern_jax.sim.state import init_state

    vec = jax.jit(jax.vmap(lambda sc: observation_vector(observe(sc, init_state(sc)))))
    full = np.asarray(vec(build_executions(suite2, trim=False).scenarios))
    cut_execs = build_executions(suite2)
    assert cut_execs.scenarios.actors.valid.shape[-1] < 16
    cut = np.asarray(vec(cut_execs.scenarios))
    assert cut.shape == full.shape == (6, OBS_SIZE)
    np.testing.assert_array_equal(cut, full)


def test_batch_bucket_depends_on_the_batch_alone():
    """A batch that fits in the built-in suite's shape runs at it, any other at its own, whatever
    the process compiled before (so an evaluation gives the same bits in any process)."""
    from lantern_jax.sim import engine

    assert engine.batch_bucket((6, 8, 7)) == SUITE_BATCH_SHAPE
    assert engine.batch_bucket(SUITE_BATCH_SHAPE) == SUITE_BATCH_SHAPE
    assert engine.batch_bucket((400, 8, 7)) == (400, 8, 7)  # more executions than the suite
    assert engine.batch_bucket((6, 12, 7)) == (6, 12, 7)  # wider than the suite


def test_the_batch_blocks_are_read_by_name():
    """``Executions.block``/``take``: Route A with and without the warning, then Route B, each
    ``num_pairs`` long in pair order; both Route A blocks hold the same physical scene."""
    from lantern_jax.core.constants import BLOCKS, EXECUTIONS_PER_PAIR, ROUTE_B
    from lantern_jax.sim.engine import build_executions

    execs = build_executions(load_suite().select(PAIRS + ["rty_0001"]))
    n = execs.num_pairs
    assert n == 3 and execs.num_executions == EXECUTIONS_PER_PAIR * n == 9
    assert jax.tree.leaves(execs.scenarios)[0].shape[0] == execs.num_executions
    assert [execs.block(b) for b in BLOCKS] == [slice(0, 3), slice(3, 6), slice(6, 9)]
    ids = np.arange(execs.num_executions)
    assert [execs.take(ids, b).tolist() for b in BLOCKS] == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    xy = np.asarray(execs.scenarios.actors0.xy)
    warned, unwarned = (execs.take(xy, c) for c in BLOCKS[:2])
    np.testing.assert_array_equal(warned, unwarned)
    assert not np.array_equal(warned, execs.take(xy, ROUTE_B))  # no hazard on Route B
    with pytest.raises(ValueError, match="block: 'A' is not one of warning, no-warning, route-b"):
        execs.block("A")
