"""The open-loop dataset: labels equal the expert's actual future, flags, determinism, resume,
Route B controls, observation parity with the closed loop, and refused bad folders.

One tiny dataset (one pair per family, two chunks) is generated once per module; compiling the
recorder dominates the cost, so the module runs with the slow tests (CI runs them too).
"""

from __future__ import annotations

import json
import shutil

import jax
import numpy as np
import pytest

from lantern_jax.apps.dataset import frames as fr
from lantern_jax.apps.dataset import generation as generate_module
from lantern_jax.apps.dataset.generation import generate_dataset
from lantern_jax.apps.dataset.record import FRAME_TICKS, FRONT_SENSORS, RIG_SENSORS, record
from lantern_jax.apps.dataset.scenes import PLAN_JSON, build_scenes, plan_scenes, read_plan
from lantern_jax.apps.dataset.store import (
    CARD_JSON,
    DatasetError,
    card_markdown,
    column_array,
    dataset_provenance,
    dataset_sha256,
    load_frames,
    load_sequences,
    read_card,
)
from lantern_jax.core.constants import FAMILIES, NUM_WAYPOINTS, WEATHERS
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.duplicates import near_duplicate, route_samples
from lantern_jax.scenarios.families import build_pair, sample_params
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import PairSpec, Suite, load_suite
from lantern_jax.sim.observe import observe
from lantern_jax.sim.rollout import rollout
from lantern_jax.types.language import PAD_ID

pytestmark = pytest.mark.slow

SEED = 11
PAIRS = 1  # per family
CHUNK = 3  # pairs per chunk: two chunks (tests/test_training.py's and test_closed_loop.py's too)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ds") / "one"
    card = generate_dataset(folder, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                            progress=False)  # fmt: skip
    return folder, card


def test_card_counts_add_up(made):
    folder, card = made
    assert card["chunks_done"] == card["chunks"] == 2
    assert card["sequences_recorded"] == 12
    assert card["sequences_accepted"] == card["route_a"] + card["route_b"]
    assert card["sequences_accepted"] + sum(card["rejected"].values()) == 12
    frames = load_frames(folder, include_crossing=True)
    assert len(frames) == card["frames"] == sum(c["frames"] for c in card["counts"])
    assert (folder / "dataset_card.md").read_text().startswith("# LANTERN open-loop dataset")


def test_card_summary_keeps_its_order_through_json(made):
    """The Markdown card written after a resume (from the card read back from its sorted JSON)
    equals the one written by the first run: columns and families in their fixed order."""
    _, card = made
    again = json.loads(json.dumps(card, sort_keys=True))
    assert card_markdown(again) == card_markdown(card)
    header = next(ln for ln in card_markdown(again).splitlines() if ln.startswith("| family"))
    assert [c.strip() for c in header.strip("|").split("|")] == [
        "family", "route", "sequences", "frames"
    ]  # fmt: skip


def test_waypoints_are_the_experts_actual_future(made):
    """Frame f's k-th waypoint is the expert's position at tick 5 (f + k), expressed in the ego
    frame at tick 5 f — checked against an independent recorded rollout of the same scene."""
    folder, _ = made
    frames = load_frames(folder, include_crossing=True)
    spec = plan_scenes(PAIRS, SEED, load_suite())[0]
    seq = f"{spec.family.lower()}_{spec.index:05d}_A"
    mine = frames[frames["sequence_id"] == seq]
    assert len(mine) > 5, "the first Route A sequence should have been accepted"
    scenario = build_scenes([spec])[0][0]
    expert = get_policy("expert")
    n_ticks = FRAME_TICKS * (int(mine["frame"].max()) + NUM_WAYPOINTS + 1)
    _, rec = jax.jit(lambda sc: rollout(sc, expert, expert.init(None), n_ticks, record=True))(
        scenario
    )
    xy = np.concatenate([np.asarray(scenario.ego0.xy)[None], np.asarray(rec.ego_xy)])
    yaw = np.concatenate([np.asarray(scenario.ego0.yaw)[None], np.asarray(rec.ego_yaw)])
    wps = column_array(mine, "waypoints", [NUM_WAYPOINTS, 2])
    for row, f in enumerate(mine["frame"].to_numpy()):
        t0, future = FRAME_TICKS * f, FRAME_TICKS * (f + 1 + np.arange(NUM_WAYPOINTS))
        c, s = np.cos(yaw[t0]), np.sin(yaw[t0])
        rel = xy[future] - xy[t0]
        want = np.stack([rel[:, 0] * c + rel[:, 1] * s, rel[:, 0] * s - rel[:, 1] * c], -1)
        np.testing.assert_allclose(wps[row], want, atol=2e-3, err_msg=f"frame {f}")


def test_horizon_crossing_frames_are_exactly_the_flagged_ones(made):
    folder, _ = made
    frames = load_frames(folder, include_crossing=True)
    seqs = {}
    for k in range(2):
        import pandas as pd

        seqs.update({r.sequence_id: r for r in pd.read_parquet(
            folder / f"sequences-{k:05d}.parquet").itertuples()})  # fmt: skip
    for sid, group in frames.groupby("sequence_id"):
        r = seqs[sid]
        t = group["t_s"].to_numpy(np.float64)
        want = np.zeros(len(t), bool)
        if r.route == "A":
            for mark in (r.t_warn_on, r.t_warn_off):
                want |= (t < mark) & (mark <= t + 2.5)
        np.testing.assert_array_equal(group["horizon_crossing"].to_numpy(bool), want, sid)
    assert frames["horizon_crossing"].any(), "some frame should straddle a warning boundary"
    assert len(load_frames(folder)) == int((~frames["horizon_crossing"].astype(bool)).sum())


def test_onset_only_rule_keeps_exactly_the_termination_crossing_frames(made):
    """``exclude_crossing="onset"`` drops the frames whose horizon holds Route A's warning onset
    (recomputed here from the sequences table) and keeps every other one, including those that
    cross termination only."""
    folder, _ = made
    frames = load_frames(folder, exclude_crossing="none")
    seqs = load_sequences(folder).set_index("sequence_id")
    t = frames["t_s"].to_numpy(np.float64)
    on = seqs["t_warn_on"].reindex(frames["sequence_id"]).to_numpy()
    crosses_onset = (frames["route"].to_numpy() == "A") & (t < on) & (on <= t + 2.5)
    kept = load_frames(folder, exclude_crossing="onset")
    assert len(kept) == int((~crosses_onset).sum())
    want = frames[~crosses_onset][["sequence_id", "frame"]].reset_index(drop=True)
    assert kept[["sequence_id", "frame"]].equals(want)
    only_termination = frames["horizon_crossing"].to_numpy(bool) & ~crosses_onset
    assert only_termination.any(), "some frame should cross warning termination only"
    assert len(kept) > len(load_frames(folder, exclude_crossing="both"))
    sub = load_frames(folder, exclude_crossing="onset", columns=["obs.warning_tokens"])
    assert list(sub.columns) == ["obs.warning_tokens"] and len(sub) == len(kept)


def test_route_b_carries_no_warning_and_no_hazard(made):
    folder, card = made
    frames = load_frames(folder, include_crossing=True)
    shape = card["frame_columns"]["obs.warning_tokens"]
    b = frames[frames["route"] == "B"]
    assert len(b) > 0
    assert np.all(column_array(b, "obs.warning_tokens", shape) == PAD_ID)  # no text delivered
    a = frames[frames["route"] == "A"]
    assert np.any(column_array(a, "obs.warning_tokens", shape) != PAD_ID)


def test_same_seed_gives_identical_shards_and_resume_finishes_the_same(made, tmp_path):
    """A second generation from the same seed writes the same bytes; one interrupted after its
    first chunk (second chunk's files and card entry gone) resumes to the same result."""
    folder, card = made
    again = tmp_path / "again"
    generate_dataset(again, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK, progress=False)
    for shard in card["shards"]:
        for key in ("frames", "sequences"):
            assert (again / shard[key]).read_bytes() == (folder / shard[key]).read_bytes()
    # interrupt: keep the first chunk only (as the card after chunk 0 would be)
    cut = tmp_path / "cut"
    shutil.copytree(again, cut)
    first = json.loads((cut / CARD_JSON).read_text())
    second = first["shards"][1]
    (cut / second["frames"]).unlink()
    (cut / second["sequences"]).unlink()
    resumed = generate_dataset(cut, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                               progress=False)  # fmt: skip
    assert [s["frames_sha256"] for s in resumed["shards"]] == [
        s["frames_sha256"] for s in card["shards"]
    ]
    assert dataset_sha256(resumed) == dataset_sha256(card)  # same content, another folder


def test_the_dataset_digest_is_the_shards_digests_in_order():
    """``dataset_sha256`` hashes the card's shard digests, frames and sequences, in order:
    derived by hand here, and any one shard's change, or a swap, changes it."""
    import hashlib

    card = {"frames": 7, "shards": [
        {"frames_sha256": "a" * 64, "sequences_sha256": "b" * 64},
        {"frames_sha256": "c" * 64, "sequences_sha256": "d" * 64},
    ]}  # fmt: skip
    text = f"{'a' * 64}:{'b' * 64}\n{'c' * 64}:{'d' * 64}"
    assert dataset_sha256(card) == hashlib.sha256(text.encode()).hexdigest()
    assert dataset_provenance(card) == {"dataset_sha256": dataset_sha256(card),
                                        "dataset_frames": 7}  # fmt: skip
    one = json.loads(json.dumps(card))
    one["shards"][1]["sequences_sha256"] = "e" * 64
    swapped = dict(card, shards=card["shards"][::-1])
    assert len({dataset_sha256(c) for c in (card, one, swapped)}) == 3


def test_resume_records_from_the_kept_plan(made, tmp_path, monkeypatch):
    """A resumed generation reads its scenes from ``plan.json`` instead of planning again, and
    finishes with the same shards."""
    folder, card = made
    cut = tmp_path / "cut"
    shutil.copytree(folder, cut)
    first = json.loads((cut / CARD_JSON).read_text())
    for key in ("frames", "sequences"):
        (cut / first["shards"][1][key]).unlink()

    def no_planning(*args, **kwargs):
        raise AssertionError("planned again although plan.json holds the plan")

    monkeypatch.setattr(generate_module, "plan_scenes", no_planning)
    resumed = generate_dataset(cut, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                               progress=False)  # fmt: skip
    assert [s["frames_sha256"] for s in resumed["shards"]] == [
        s["frames_sha256"] for s in card["shards"]
    ]
    assert read_plan(cut, {"seed": SEED + 1}, "0" * 64) is None  # another plan: plan again
    # a first chunk interrupted before the card was written: the kept plan is used too
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(cut / PLAN_JSON, fresh / PLAN_JSON)
    redone = generate_dataset(fresh, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                              progress=False)  # fmt: skip
    assert redone["shards"] == resumed["shards"]
    assert redone["suite_near_duplicates_skipped"] == card["suite_near_duplicates_skipped"]


def test_closed_loop_observation_equals_the_dataset_frame(made):
    """The observation a policy gets in the closed loop at tick 5 f equals frame f's stored
    observation, field by field (a policy trained on the data runs in the benchmark unchanged)."""
    spec = plan_scenes(PAIRS, SEED, load_suite())[0]
    scenario = build_scenes([spec])[0][0]
    expert = get_policy("expert")
    params = expert.init(None)
    recs, _ = jax.jit(lambda sc: record(sc, expert, params, 12))(scenario)
    f = 8
    final, _ = jax.jit(lambda sc: rollout(sc, expert, params, FRAME_TICKS * f))(scenario)
    live = jax.jit(lambda sc, st: observe(sc, st, FRONT_SENSORS))(scenario, final)
    stored = jax.tree.map(lambda x: x[f], recs.obs)
    pairs = zip(jax.tree_util.tree_leaves_with_path(live),
                jax.tree_util.tree_leaves_with_path(stored), strict=True)  # fmt: skip
    for (path, a), (_, b) in pairs:
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-5,
                                   err_msg=jax.tree_util.keystr(path))  # fmt: skip
    # the six-camera rig: Observation.surround of a surround policy equals the stored view
    rig = jax.jit(lambda sc, st: observe(sc, st, RIG_SENSORS).surround)(scenario, final)
    for name in ("visible", "ranges", "hit_class"):
        np.testing.assert_allclose(np.asarray(getattr(rig, name)),
                                   np.asarray(getattr(recs.rig.surround, name))[f],
                                   rtol=1e-5, atol=1e-5, err_msg=name)  # fmt: skip
    assert np.asarray(live.range_class).dtype == np.int32


def test_acceptance_rules_on_hand_made_records():
    """The timeline rule accepts RTY's coincident onset and rejects it elsewhere."""
    assert fr.REASONS[4] == "timeline out of order"
    t = np.arange(40) * 0.25
    crossing = fr.horizon_crossing(t, 3.0, 6.1)
    assert crossing[np.flatnonzero((t < 3.0) & (t + 2.5 >= 3.0))].all()
    assert not crossing[t >= 6.1].any() and not crossing[t < 0.5].any()
    # per-frame marks (one per frame, e.g. each frame's own sequence onset) and marks that
    # never happened
    per_frame = fr.horizon_crossing(t, np.full(t.shape, 3.0), np.full(t.shape, 6.1))
    np.testing.assert_array_equal(per_frame, crossing)
    assert not fr.horizon_crossing(t, np.nan, 1e9).any()


def test_scenes_are_disjoint_from_the_suite_by_the_near_duplicate_rule():
    """No planned scene's route is a near duplicate of a suite route of its family, and a
    candidate whose geometry is a suite pair's is skipped and counted."""
    suite = load_suite()
    rejected: dict = {}
    specs = plan_scenes(2, SEED, suite, rejected=rejected)
    assert [s.family for s in specs] == [f for f in suite_families(suite) for _ in range(2)]
    routes = {}
    for p in suite.pairs:
        routes.setdefault(p.family, []).append(np.asarray(p.route_2m))
    built, _ = build_scenes(specs)
    for spec, scenario in zip(specs, built, strict=True):
        mine = route_samples(scenario)
        assert not any(near_duplicate(mine, r) for r in routes[spec.family]), spec.index
    # a suite holding the first unfiltered PE candidate: that candidate must be skipped
    first = plan_scenes(1, SEED)[0]
    twin = Suite("twin", (PairSpec("pe_0001", "PE", first.weather, first.params, "0" * 64),),
                 "0" * 64, 0, {})  # fmt: skip
    got: dict = {}
    again = plan_scenes(1, SEED, twin, rejected=got)
    assert got["PE"] >= 1 and again[0].sha256 != first.sha256


def test_plan_equals_sampling_validated_params_one_by_one():
    """The planner validates only the candidates that survive the duplicate tests; its plan
    must be the one a plain loop over ``sample_params`` (validating every draw) gives."""
    suite = load_suite()
    routes = {}
    for p in suite.pairs:
        routes.setdefault(p.family, []).append(np.asarray(p.route_2m))
    taken = {p.sha256 for p in suite.pairs}
    expected = []
    for fi, fam in enumerate(FAMILIES):
        rng = np.random.default_rng([SEED, fi])
        k = 0
        while k < 2:
            params = sample_params(fam, rng, WEATHERS[k % len(WEATHERS)])
            h = content_hash(params)
            if h in taken:
                continue
            taken.add(h)
            route = route_samples(build_pair(params, validate=False)[0])
            if any(near_duplicate(route, r) for r in routes[fam]):
                continue
            expected.append((fam, h))
            k += 1
    got = [(s.family, s.sha256) for s in plan_scenes(2, SEED, suite)]
    assert got == expected


def test_a_smaller_plan_is_the_first_scenes_of_every_family_of_a_larger_one():
    """What lets the README say the shipped models were trained on the first 280 scenes of each
    family of the default 380-pair plan: family by family, a smaller plan is a prefix."""
    suite = load_suite()
    small, large = plan_scenes(2, SEED, suite), plan_scenes(3, SEED, suite)
    for fam in FAMILIES:
        head = [s.sha256 for s in large if s.family == fam][:2]
        assert [s.sha256 for s in small if s.family == fam] == head, fam


def test_card_states_the_papers_release_next_to_ours(made):
    _, card = made
    text = card_markdown(card)
    assert f"{card['frames']} frames at 4 Hz" in text
    paper = "The paper's release: 3272 sequences (Route A 1631, Route B 1641), 236309 frames."
    assert paper in text


def suite_families(suite):
    return list(dict.fromkeys(p.family for p in suite.pairs))


# ---------------------------------------------------------------------------------------------
# bad dataset folders
# ---------------------------------------------------------------------------------------------
@pytest.fixture()
def copy(made, tmp_path):
    folder, _ = made
    dst = tmp_path / "copy"
    shutil.copytree(folder, dst)
    return dst


def test_missing_shard_is_named(copy):
    card = read_card(copy)
    (copy / card["shards"][0]["frames"]).unlink()
    with pytest.raises(DatasetError, match=r"frames-00000.parquet: missing shard"):
        load_frames(copy)


def test_corrupted_shard_is_named(copy):
    card = read_card(copy)
    path = copy / card["shards"][1]["frames"]
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(DatasetError, match=r"frames-00001.parquet: content does not match"):
        load_frames(copy)


def test_corrupted_sequences_shard_is_named(copy):
    card = read_card(copy)
    path = copy / card["shards"][0]["sequences"]
    path.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(DatasetError, match=r"sequences-00000.parquet: content does not match"):
        load_frames(copy, exclude_crossing="onset")


def test_unknown_exclusion_rule_is_refused(made):
    folder, _ = made
    with pytest.raises(ValueError, match=r"exclude_crossing: 'termination' is not one of"):
        load_frames(folder, exclude_crossing="termination")


def test_schema_mismatch_is_named(copy):
    card = json.loads((copy / CARD_JSON).read_text())
    card["frame_columns"]["obs.new_field"] = [3]
    (copy / CARD_JSON).write_text(json.dumps(card))
    with pytest.raises(DatasetError, match=r"frames-00000.parquet: columns \['obs.new_field'\]"):
        load_frames(copy)


def test_incompatible_version_is_named(copy):
    card = json.loads((copy / CARD_JSON).read_text())
    card["format_version"] = 99
    (copy / CARD_JSON).write_text(json.dumps(card))
    with pytest.raises(DatasetError, match=r"dataset_card.json: format_version 99"):
        load_frames(copy)


def test_tampered_plan_is_named(copy):
    body = json.loads((copy / PLAN_JSON).read_text())
    body["specs"][0]["params"]["route_length"] += 1.0
    (copy / PLAN_JSON).write_text(json.dumps(body))
    with pytest.raises(DatasetError, match=r"plan.json: scene 0 \(PE\) does not match"):
        generate_dataset(copy, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                         progress=False)  # fmt: skip
    body["specs"][0]["params"]["route_length"] -= 1.0
    body["suite_sha256"] = "0" * 64
    (copy / PLAN_JSON).write_text(json.dumps(body))
    with pytest.raises(DatasetError, match=r"plan.json: made for another plan or suite"):
        generate_dataset(copy, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                         progress=False)  # fmt: skip
    (copy / PLAN_JSON).write_text("{not json")
    with pytest.raises(DatasetError, match=r"plan.json: not a readable scene plan"):
        generate_dataset(copy, pairs_per_family=PAIRS, seed=SEED, chunk_pairs=CHUNK,
                         progress=False)  # fmt: skip


def test_other_plan_is_refused(made):
    folder, _ = made
    with pytest.raises(DatasetError, match=r"written for another plan"):
        generate_dataset(folder, pairs_per_family=PAIRS, seed=SEED + 1, chunk_pairs=CHUNK,
                         progress=False)  # fmt: skip
