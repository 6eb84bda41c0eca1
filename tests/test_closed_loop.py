"""Closed-loop training (DAgger): relabelling, counterfactual warnings, the recipe end to end.

The fast tests check the pieces on synthetic data; the slow ones drive the simulator (each
compiles the rollout: about a minute on two CPU cores).
"""

from __future__ import annotations

import collections
import json
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
import pandas as pd
import pytest

from lantern_jax.apps.dataset import frames as fr
from lantern_jax.apps.dataset.record import DATA_ACTORS
from lantern_jax.apps.training import counterfactual as cf
from lantern_jax.apps.training.closed_loop import family_shares, round_specs
from lantern_jax.apps.training.config import (
    ConfigError,
    TrainConfig,
    load_config,
    parse_family_weights,
)
from lantern_jax.apps.training.data import Examples
from lantern_jax.apps.training.relabel import ego_frame_offsets
from lantern_jax.core.constants import FAMILIES, NUM_WAYPOINTS
from lantern_jax.core.times import NEVER
from lantern_jax.types.language import PAD_ID
from lantern_jax.types.observation import stated_position

ROOT = Path(__file__).resolve().parents[1]


def test_relabel_offsets_are_the_dataset_labellers_waypoints():
    rng = np.random.default_rng(0)
    xy = np.cumsum(rng.normal(size=(14, 2)), axis=0).astype(np.float32) * 3
    yaw = rng.uniform(-3, 3, 14).astype(np.float32)
    for f in (0, 3):
        ref = fr.future_waypoints(xy, yaw, f)
        got = ego_frame_offsets(xy[f], yaw[f], xy[f + 1 : f + 1 + NUM_WAYPOINTS])
        np.testing.assert_allclose(np.asarray(got), ref, atol=1e-5)


def _examples(n: int) -> tuple[Examples, np.ndarray, np.ndarray]:
    from lantern_jax.types.language import MAX_TOKENS

    rng = np.random.default_rng(1)
    obs = dict(warning_tokens=np.full((n, MAX_TOKENS), PAD_ID, np.int32),
               warning_values=np.zeros((n, MAX_TOKENS), np.float32),
               ego_speed=rng.uniform(0, 10, n).astype(np.float32))  # fmt: skip
    targets = rng.normal(size=(n, NUM_WAYPOINTS, 2)).astype(np.float32)
    seq = np.asarray([f"s{i}" for i in range(n)])
    families = np.asarray([FAMILIES[i % len(FAMILIES)] for i in range(n)])
    routes = np.asarray(["A" if i % 4 == 0 else "B" for i in range(n)])
    return Examples(obs, targets, seq, np.ones(n, bool)), families, routes


def test_counterfactual_frames_carry_the_ordinary_label_and_a_text_of_no_hazard_here():
    from lantern_jax.scenarios.warnings import text_tables
    from lantern_jax.types.observation import stated_position

    ex, families, routes = _examples(240)
    out, variant = cf.counterfactual_examples(ex, families, routes, share=0.5, seed=0)
    n_b = int(np.sum(routes == "B"))
    assert len(out) == round(0.5 * n_b) and set(variant) == {0, 1}
    src = np.asarray([int(s[1:]) for s in out.sequence])
    assert np.all(routes[src] == "B")  # only frames whose route holds no hazard
    np.testing.assert_array_equal(out.targets, ex.targets[src])  # the ordinary expert plan
    np.testing.assert_array_equal(out.obs["ego_speed"], ex.obs["ego_speed"][src])
    assert not out.base_style.any()
    tables = text_tables()
    ids = {tuple(t): i for i, t in enumerate(tables.tokens)}
    text = np.asarray([ids[tuple(t)] for t in out.obs["warning_tokens"]])
    na = set(cf.nonactionable_ids().tolist())
    for i in np.flatnonzero(variant == 0):  # another road type's family: not on this route
        assert text[i] in cf.other_road_families(families[src][i])
    assert all(t in na for t in text[variant == 1])
    # the value channel states a near position where the text writes one
    for i in np.flatnonzero(variant == 0)[:5]:
        text_obs = SimpleNamespace(warning_tokens=out.obs["warning_tokens"][i],
                                   warning_values=out.obs["warning_values"][i])  # fmt: skip
        pos, stated = stated_position(text_obs)
        assert bool(stated) and cf.NEAR_X_M[0] <= float(pos[0]) <= cf.NEAR_X_M[1]


def test_distractor_sentences_replace_a_share_of_the_counterfactual_texts_only():
    from lantern_jax.scenarios.warnings import text_tables
    from lantern_jax.types.observation import stated_position

    ex, families, routes = _examples(240)
    plain, v0 = cf.counterfactual_examples(ex, families, routes, share=0.5, seed=0)
    out, variant = cf.counterfactual_examples(ex, families, routes, 0.5, 0, distractors=0.5)
    # the same frames and labels; off the distractor stream, the same texts and positions
    np.testing.assert_array_equal(out.sequence, plain.sequence)
    np.testing.assert_array_equal(out.targets, plain.targets)
    kept = variant != 2
    assert 0.3 < 1 - kept.mean() < 0.7 and np.array_equal(variant[kept], v0[kept])
    for key in ("warning_tokens", "warning_values"):
        np.testing.assert_array_equal(out.obs[key][kept], plain.obs[key][kept])
    bank, ids = cf.distractor_bank()
    rows = {tuple(t): i for i, t in enumerate(text_tables(bank).tokens)}
    told = [rows[tuple(t)] for t in out.obs["warning_tokens"][~kept]]
    assert set(told) <= set(ids.tolist()) and len(set(told)) > 6
    for i in np.flatnonzero(~kept)[:5]:  # each states a near position in the value channel
        text_obs = SimpleNamespace(warning_tokens=out.obs["warning_tokens"][i],
                                   warning_values=out.obs["warning_values"][i])  # fmt: skip
        pos, stated = stated_position(text_obs)
        assert bool(stated) and cf.NEAR_X_M[0] <= float(pos[0]) <= cf.NEAR_X_M[1]


def test_stated_positions_are_drawn_where_the_familys_true_warnings_state_theirs():
    """With ``positions="stated"`` a counterfactual states a position that a true warning of
    its frame's family states in the examples (a Route A frame's text); a family whose examples
    state none keeps the near box; frames, texts and variants are those of the near draw."""
    from lantern_jax.scenarios.warnings import text_tables

    ex, families, routes = _examples(480)
    tables = text_tables()
    told_at = {"LWW": [(12.5, -24.0), (14.0, -22.5)], "RWW": [(9.5, 21.0)]}
    turning = np.flatnonzero(np.isin(families, list(told_at)))
    routes[turning[::3]] = "A"  # a third of their frames: Route A, the warning delivered
    seen = collections.Counter()
    for i in turning[::3]:
        fam = str(families[i])
        if fam in told_at:
            f = FAMILIES.index(fam)  # the family's canonical text: it states a position
            ex.obs["warning_tokens"][i] = tables.tokens[f]
            x, y = told_at[fam][seen[fam] % len(told_at[fam])]
            seen[fam] += 1
            ex.obs["warning_values"][i, tables.x_slot[f]] = x
            ex.obs["warning_values"][i, tables.y_slot[f]] = y
    pool = cf.stated_positions(ex, families, routes)
    assert {tuple(p) for p in pool["LWW"]} == set(told_at["LWW"]) and len(pool["PE"]) == 0
    near, v_near = cf.counterfactual_examples(ex, families, routes, 0.5, 0, distractors=0.5)
    out, variant = cf.counterfactual_examples(ex, families, routes, 0.5, 0, distractors=0.5,
                                              positions="stated")  # fmt: skip
    np.testing.assert_array_equal(variant, v_near)
    np.testing.assert_array_equal(out.obs["warning_tokens"], near.obs["warning_tokens"])
    fam = families[np.asarray([int(s[1:]) for s in out.sequence])]
    moved = 0
    for i in range(len(out)):
        text_obs = SimpleNamespace(warning_tokens=out.obs["warning_tokens"][i],
                                   warning_values=out.obs["warning_values"][i])  # fmt: skip
        pos, stated = stated_position(text_obs)
        if not bool(stated):
            continue
        if fam[i] in told_at:
            assert tuple(np.round(np.asarray(pos), 2)) in set(told_at[fam[i]])
            moved += 1
        else:  # no position stated for this family: the near draw
            np.testing.assert_array_equal(out.obs["warning_values"][i],
                                          near.obs["warning_values"][i])
    assert moved > 10
    with pytest.raises(ValueError, match="positions"):
        cf.counterfactual_examples(ex, families, routes, 0.5, 0, positions="far")


def test_a_share_of_stated_positions_moves_that_share_and_keeps_the_rest_near():
    """``stated_share`` draws about that share of the position-stating counterfactuals among
    the stated positions; every other frame is the near draw, bit for bit; 1 is the whole."""
    from lantern_jax.scenarios.warnings import text_tables

    ex, families, routes = _examples(1400)
    tables = text_tables()
    turning = np.flatnonzero(families == "LWW")
    routes[turning] = np.where(np.arange(len(turning)) % 2 == 0, "A", "B")
    f = FAMILIES.index("LWW")  # every LWW frame states the one position below
    ex.obs["warning_tokens"][turning] = tables.tokens[f]
    ex.obs["warning_values"][turning, tables.x_slot[f]] = 12.5
    ex.obs["warning_values"][turning, tables.y_slot[f]] = -24.0
    args = (ex, families, routes, 1.0, 0)
    near, _ = cf.counterfactual_examples(*args)
    whole, _ = cf.counterfactual_examples(*args, positions="stated")
    np.testing.assert_array_equal(
        cf.counterfactual_examples(*args, positions="stated", stated_share=1.0)[0]
        .obs["warning_values"], whole.obs["warning_values"])  # fmt: skip
    half, _ = cf.counterfactual_examples(*args, positions="stated", stated_share=0.5)
    fam = families[np.asarray([int(s[1:]) for s in half.sequence])]
    moved = kept = 0
    for i in np.flatnonzero(fam == "LWW"):
        text_obs = SimpleNamespace(warning_tokens=half.obs["warning_tokens"][i],
                                   warning_values=half.obs["warning_values"][i])  # fmt: skip
        pos, stated = stated_position(text_obs)
        if not bool(stated):
            continue
        if tuple(np.round(np.asarray(pos), 2)) == (12.5, -24.0):
            moved += 1
            np.testing.assert_array_equal(half.obs["warning_values"][i],
                                          whole.obs["warning_values"][i])  # fmt: skip
        else:
            kept += 1
            np.testing.assert_array_equal(half.obs["warning_values"][i],
                                          near.obs["warning_values"][i])  # fmt: skip
    assert moved + kept > 40 and 0.3 < moved / (moved + kept) < 0.7


def test_training_distractors_are_not_the_language_probes():
    from lantern_jax.scenarios.warning_texts import (
        DEFAULT_BANK,
        DISTRACTOR_SETS,
        PROBE_IRRELEVANT,
        PROBE_NEGATED,
        TRAINING_DISTRACTORS,
        TRAINING_LANE_DISTRACTORS,
        TRAINING_NEGATION_DISTRACTORS,
    )

    bank_texts = {e.text for e in DEFAULT_BANK}
    every = TRAINING_DISTRACTORS + TRAINING_LANE_DISTRACTORS + TRAINING_NEGATION_DISTRACTORS
    assert len(set(every)) == len(every)
    for text in every:
        assert text not in bank_texts and text not in (PROBE_IRRELEVANT, PROBE_NEGATED)
        lower = text.lower()
        assert not any(w in lower for w in ("nothing", "clear", "bakery", "bread"))
        assert "<FRONT_CAR_POS>" in text  # each states a position
    # the position statements avoid the templates' phrase too; the lane set is made of it
    assert not any("ego lane" in t.lower() for t in TRAINING_DISTRACTORS)
    assert all(("ego lane" in t) or ("turn path" in t) for t in TRAINING_LANE_DISTRACTORS)
    assert DISTRACTOR_SETS["position"] == TRAINING_DISTRACTORS
    assert DISTRACTOR_SETS["position_and_lane"] == TRAINING_DISTRACTORS + TRAINING_LANE_DISTRACTORS
    assert DISTRACTOR_SETS["position_lane_negations"] == every
    # the negations in other words: each negates, none with the word "no" the other sets use
    for text in TRAINING_NEGATION_DISTRACTORS:
        words = text.lower().replace(";", " ").replace(".", " ").split()
        assert "no" not in words and {"not", "never", "isn't", "won't", "none", "neither"} & set(
            words), text  # fmt: skip


def test_the_lane_distractor_set_extends_the_position_set():
    from lantern_jax.scenarios.warnings import text_tables

    small, small_ids = cf.distractor_bank("position")
    large, large_ids = cf.distractor_bank("position_and_lane")
    assert len(large_ids) == len(small_ids) + 8
    np.testing.assert_array_equal(large_ids[: len(small_ids)], small_ids)
    assert [large[int(i)].text for i in small_ids] == [small[int(i)].text for i in small_ids]
    with pytest.raises(ValueError, match="distractor_texts: 'lanes' not one of"):
        cf.distractor_bank("lanes")
    largest, largest_ids = cf.distractor_bank("position_lane_negations")
    assert len(largest_ids) == len(large_ids) + 7
    np.testing.assert_array_equal(largest_ids[: len(large_ids)], large_ids)
    ex, families, routes = _examples(240)
    out, variant = cf.counterfactual_examples(ex, families, routes, 0.5, 0, distractors=1.0,
                                              distractor_texts="position_and_lane")  # fmt: skip
    rows = {tuple(t): i for i, t in enumerate(text_tables(large).tokens)}
    told = {rows[tuple(t)] for t in out.obs["warning_tokens"][variant == 2]}
    assert told <= set(large_ids.tolist()) and told & set(large_ids[len(small_ids) :].tolist())


def test_failure_visits_are_the_grid_and_the_seconds_before_a_collision():
    from lantern_jax.apps.training.closed_loop import _chosen

    t = np.tile(0.5 * np.arange(12, dtype=np.float32), (2, 1))  # s, visits every 0.5 s
    t_coll = np.stack([np.full(12, 4.2, np.float32), np.full(12, NEVER, np.float32)])
    v = SimpleNamespace(t=t, t_collision=t_coll)
    grid = np.arange(12) % 4 == 0
    np.testing.assert_array_equal(_chosen(v, 4, 0.0), np.stack([grid, grid]))
    near = (t[0] >= 4.2 - 1.5) & (t[0] < 4.2)  # 3.0, 3.5, 4.0 s
    np.testing.assert_array_equal(_chosen(v, 4, 1.5)[0], grid | near)
    np.testing.assert_array_equal(_chosen(v, 4, 1.5)[1], grid)  # no collision: the grid only
    np.testing.assert_array_equal(_chosen(v, 1, 0.0), np.ones((2, 12), bool))


def test_failure_visit_settings_are_checked(tmp_path):
    bad = tmp_path / "bad.toml"
    base = '[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
    bad.write_text(base + "failure_window_s = 3.0\nfailure_every_s = 0.75\n")
    with pytest.raises(ConfigError, match="failure_every_s.*divide"):
        load_config(bad)
    bad.write_text(base + "failure_window_s = -1.0\n")
    with pytest.raises(ConfigError, match="failure_window_s"):
        load_config(bad)
    bad.write_text(base + "distractors = 1.5\n")
    with pytest.raises(ConfigError, match="distractors"):
        load_config(bad)
    bad.write_text(base + "failure_window_s = 3.0\nfailure_every_s = 0.5\n")
    assert load_config(bad).failure_window_s == 3.0


def test_a_language_recipe_may_read_the_six_camera_rig(tmp_path):
    """``rig`` is the recipe's own unless given (the surround recipe's is the rig, every other
    recipe's the front camera); a language recipe may take the rig, the surround recipe keeps
    it, and a rig that does not exist is refused naming the key."""
    cfg = tmp_path / "c.toml"
    base = '[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
    cfg.write_text(base)
    assert load_config(cfg).rig == "front"
    cfg.write_text(base + 'rig = "surround"\n')
    assert load_config(cfg).rig == "surround" and load_config(cfg).language
    assert TrainConfig(name="x", recipe="surround").rig == "surround"
    assert TrainConfig(name="x", recipe="distance", rig="surround").rig == "surround"
    cfg.write_text(base + 'rig = "fisheye"\n')
    with pytest.raises(ConfigError, match=r"train\.rig.*'fisheye' not one of front, surround"):
        load_config(cfg)
    cfg.write_text('[train]\nname = "x"\nrecipe = "surround"\nrig = "front"\n')
    with pytest.raises(ConfigError, match=r"train\.rig.*six-camera"):
        load_config(cfg)


@pytest.mark.parametrize("rig", ["front", "surround"])
def test_visits_become_examples_with_the_rigs_columns(rig):
    """A visit's observation (as the relabelling program returns it for a learner of ``rig``)
    becomes an example with the dataset's columns for that rig: the six-camera view's
    ``surround_*`` columns from ``Observation.surround``, every other column from its field."""
    from lantern_jax.apps.dataset.record import FRONT_SENSORS, RIG_SENSORS
    from lantern_jax.apps.training.closed_loop import visits_to_examples
    from lantern_jax.apps.training.data import SURROUND_COLUMNS, ranges_width
    from lantern_jax.apps.training.relabel import Visits
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.scenarios.suite import load_suite
    from lantern_jax.sim.engine import build_executions
    from lantern_jax.sim.observe import observe
    from lantern_jax.sim.rollout import start_state
    from lantern_jax.sim.settings import DEFAULT_SETTINGS

    scenario = jax.tree.map(
        lambda x: x[0], build_executions(load_suite().select(["pe_0001"])).scenarios
    )
    sensors = RIG_SENSORS if rig == "surround" else FRONT_SENSORS
    expert = get_policy("expert")

    def obs_of():
        s = start_state(scenario, expert, expert.init(jax.random.PRNGKey(0)), DEFAULT_SETTINGS)
        return observe(scenario, s, sensors, DEFAULT_SETTINGS.bank)

    shapes = jax.eval_shape(obs_of)  # traced, not compiled
    rng = np.random.default_rng(0)
    # a batch of one execution with three visits; every array distinct
    obs = jax.tree.map(lambda x: rng.integers(0, 100, (1, 3, *x.shape)).astype(x.dtype), shapes)
    zeros = np.zeros((1, 3), np.float32)
    v = Visits(obs, np.ones((1, 3, NUM_WAYPOINTS, 2), np.float32), np.ones((1, 3), bool), zeros,
               zeros.astype(bool), zeros.astype(bool), zeros)  # fmt: skip
    names = ["visible", "actor_xy", "range_image", "warning_tokens"]
    if rig == "surround":
        names += [c.replace(".", "_") for c in SURROUND_COLUMNS]
    like = Examples({n: np.zeros((0,), np.float32) for n in names}, np.zeros((0, 10, 2)),
                    np.zeros((0,), str), np.zeros((0,), bool))  # fmt: skip
    keep = np.asarray([[True, False, True]])
    ex = visits_to_examples(v, ["pe_00001_A"], like, keep)
    assert sorted(ex.obs) == sorted(names) and len(ex) == 2
    np.testing.assert_array_equal(ex.obs["actor_xy"], np.asarray(obs.actor_xy)[0, [0, 2]])
    if rig == "surround":
        for name in ("visible", "ranges", "hit_class"):
            got = ex.obs[f"surround_{name}"]
            np.testing.assert_array_equal(got, getattr(obs.surround, name)[0, [0, 2]])
        assert ranges_width(ex, rig) == np.asarray(obs.surround.ranges).shape[-1]
    else:
        assert obs.surround is None
        assert ranges_width(ex, rig) == np.asarray(obs.range_image).shape[-1]


def test_other_road_families_split_straight_and_junction():
    assert [FAMILIES[i] for i in cf.other_road_families("PE")] == ["LWW", "RWW", "RTY"]
    assert [FAMILIES[i] for i in cf.other_road_families("RTY")] == ["PE", "VC", "OR"]


def test_closed_loop_config_loads_and_needs_a_model_to_start_from(tmp_path):
    cfg = load_config(ROOT / "configs" / "train_closed_loop.toml")
    assert cfg.recipe == "closed_loop" and cfg.init_from and cfg.rounds >= 1
    bad = tmp_path / "bad.toml"
    bad.write_text('[train]\nname = "x"\nrecipe = "closed_loop"\n')
    with pytest.raises(ConfigError, match="init_from"):
        load_config(bad)
    bad.write_text('[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\nbeta = 2.0\n')
    with pytest.raises(ConfigError, match="beta"):
        load_config(bad)


def test_round_specs_spread_over_families_and_change_by_round():
    from lantern_jax.apps.dataset.scenes import SceneSpec

    specs = [SceneSpec(i, FAMILIES[i % 6], "clear", {}, f"{i:064x}") for i in range(60)]
    a, b = round_specs(specs, 12, 0, 0), round_specs(specs, 12, 0, 1)
    assert pd.Series([s.family for s in a]).value_counts().to_dict() == {f: 2 for f in FAMILIES}
    assert [s.index for s in a] != [s.index for s in b]
    assert [s.index for s in a] == [s.index for s in round_specs(specs, 12, 0, 0)]


def test_family_weights_spread_a_round_in_proportion():
    """Weights 2 for three families of six: 48 pairs as 5 / 5 / 5 / 11 / 11 / 11 (45 rounded
    down, the three larger remainders 2/3 each take one more); equal weights are the even
    spread itself, draw for draw; a family never gives more pairs than its pool holds."""
    from lantern_jax.apps.dataset.scenes import SceneSpec

    assert family_shares(48, [1, 1, 1, 2, 2, 2]) == [5, 5, 5, 11, 11, 11]
    assert family_shares(13, [1.0] * 6) == [3, 2, 2, 2, 2, 2]
    assert family_shares(7, [1, 3]) == [2, 5]  # 1.75 / 5.25: the larger remainder takes one
    specs = [SceneSpec(i, FAMILIES[i % 6], "clear", {}, f"{i:064x}") for i in range(120)]
    weights = parse_family_weights("LWW=2, RWW=2,RTY=2")
    assert weights == {"LWW": 2.0, "RWW": 2.0, "RTY": 2.0}
    got = pd.Series([s.family for s in round_specs(specs, 48, 0, 0, weights)]).value_counts()
    assert got.to_dict() == {"PE": 5, "VC": 5, "OR": 5, "LWW": 11, "RWW": 11, "RTY": 11}
    even = [s.index for s in round_specs(specs, 48, 3, 2)]
    assert [s.index for s in round_specs(specs, 48, 3, 2, {f: 4.0 for f in FAMILIES})] == even
    assert [s.index for s in round_specs(specs, 48, 3, 2, {})] == even
    few = round_specs(specs, 48, 0, 0, {"PE": 100.0})  # PE's pool holds 20
    assert sum(s.family == "PE" for s in few) == 20


@pytest.mark.parametrize("text, match", [
    ("LWW=0", "'LWW=0' is not FAMILY=WEIGHT"), ("XX=1", "'XX=1'"), ("LWW", "'LWW'"),
    ("LWW=two", "'LWW=two'"), ("LWW=nan", "'LWW=nan'"), ("LWW=1,LWW=2", "LWW is given twice"),
    ("LWW=1,", "'' is not"),
])  # fmt: skip
def test_bad_family_weights_are_refused_naming_the_entry(text, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        parse_family_weights(text)
    bad = tmp_path / "c.toml"
    bad.write_text('[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
                   f'family_weights = "{text}"\n')  # fmt: skip
    with pytest.raises(ConfigError, match="train.family_weights"):
        load_config(bad)


@pytest.mark.slow
def test_relabel_of_an_expert_state_is_the_dataset_label():
    from lantern_jax.apps.dataset.generation import NUM_FRAMES
    from lantern_jax.apps.dataset.record import batched_recorder
    from lantern_jax.apps.dataset.scenes import build_scenes, plan_scenes
    from lantern_jax.apps.training.relabel import relabel_batch
    from lantern_jax.policies.registry import get_policy
    from lantern_jax.types.world import tree_stack

    specs = plan_scenes(1, 5, families=("PE",))
    a, b = build_scenes(specs)
    batch = tree_stack(a + b)
    expert = get_policy("expert")
    ep = expert.init(jax.random.PRNGKey(0))
    # recorded as the dataset records a chunk of three pairs (six executions, NUM_FRAMES frames):
    # the program tests/test_dataset.py compiles; the two scenes repeated three times
    six = tree_stack(3 * (a + b))
    recs = jax.device_get(batched_recorder(expert, NUM_FRAMES)(six, ep)[0])
    # a grid four times finer (as failure visits use it): every fourth visit is the 40-tick one
    dense = jax.device_get(relabel_batch(batch, expert, ep, expert, ep, jax.random.PRNGKey(0),
                                         num_visits=12, every=10, phase=5, segment=4))  # fmt: skip
    v = jax.tree.map(lambda x: x[:, ::4], dense)
    ticks = np.broadcast_to(5 + 10 * np.arange(5), (2, 5))
    np.testing.assert_allclose(np.asarray(dense.t)[:, :5], 0.05 * ticks, atol=1e-4)
    assert np.all(np.asarray(dense.t_collision) == NEVER)  # the expert does not collide here
    valid = np.asarray(v.valid)
    assert valid.sum() >= 3, valid
    for j in range(2):
        one = jax.tree.map(lambda x, j=j: x[j], recs)
        live = np.asarray(one.live)
        for k in range(3):
            f = (5 + 40 * k) // 5  # the recorded frame of the visit's tick
            # valid exactly where the dataset would keep the frame: it and ten more are live
            assert valid[j, k] == bool(live[f : f + NUM_WAYPOINTS + 1].all()), (j, k)
            if not valid[j, k]:
                continue
            ref = fr.future_waypoints(np.asarray(one.ego_xy), np.asarray(one.ego_yaw), f)
            np.testing.assert_allclose(v.waypoints[j, k], ref, atol=1e-4)
            np.testing.assert_array_equal(v.obs.warning_tokens[j, k], one.obs.warning_tokens[f])
            np.testing.assert_allclose(v.obs.range_image[j, k], one.obs.range_image[f], atol=1e-4)


@pytest.mark.slow
def test_one_round_trains_checkpoints_and_resumes(tmp_path):
    from lantern_jax.apps.dataset.generation import generate_dataset
    from lantern_jax.apps.dataset.store import dataset_sha256, read_card
    from lantern_jax.apps.training.behaviour_cloning import train
    from lantern_jax.policies.learned.checkpoint import checkpoint_policy, read_meta

    ds = tmp_path / "ds"
    # chunks of three pairs: the recording program of tests/test_dataset.py's chunks
    generate_dataset(ds, pairs_per_family=1, seed=5, chunk_pairs=3, progress=False)
    common = dict(dataset=str(ds), width=16, heads=2, epochs=1, batch_size=32,
                  val_fraction=0.2, seed=3)  # fmt: skip
    train(TrainConfig(name="learned-tiny", recipe="base", out=str(tmp_path / "b"), **common),
          progress=False)  # fmt: skip
    cl = dict(common, name="learned-tiny-cl", recipe="closed_loop", out=str(tmp_path / "c"),
              init_from=str(tmp_path / "b" / "learned-tiny.msgpack"), rounds=1,
              scenes_per_round=2, max_seconds=6.0, exclude_crossing="onset",
              failure_window_s=2.0, failure_every_s=1.0)  # fmt: skip
    s = train(TrainConfig(**cl), progress=False)
    r0 = tmp_path / "c" / "round-0"
    assert s["rounds"] == 1 and s["kept_visits"] > 0 and s["executions"] == 4
    assert 0 <= s["failure_visits"] <= s["kept_visits"]
    assert (r0 / "visits.npz").exists() and (r0 / "done.json").exists()
    assert checkpoint_policy(tmp_path / "c" / "learned-tiny-cl.msgpack").name == "learned-tiny-cl"
    # an interrupted round resumes its training from the latest epoch (visits kept)
    (r0 / "done.json").unlink()
    again = train(TrainConfig(**dict(cl, epochs=2)), progress=False)
    assert list(pd.read_csv(r0 / "curve.csv")["epoch"]) == [0, 1] and again["epochs"] == 2
    assert json.loads((r0 / "done.json").read_text())["visits"] == s["visits"]
    meta = read_meta(tmp_path / "c" / "learned-tiny-cl")
    assert meta["recipe"] == "closed_loop"
    assert meta["dataset_sha256"] == again["dataset_sha256"] == dataset_sha256(read_card(ds))
    assert read_meta(r0 / "learned-tiny-cl")["dataset_frames"] == read_card(ds)["frames"]


def _two_pe_two_vc():
    """Four scene specs of a seeded draw: PE, PE, VC, VC (indices 0-3)."""
    from lantern_jax.apps.dataset.scenes import SceneSpec
    from lantern_jax.scenarios.families import sample_params

    rng = np.random.default_rng(0)
    return [SceneSpec(i, f, "clear_day", sample_params(f, rng), "") for i, f in
            enumerate(["PE", "PE", "VC", "VC"])]  # fmt: skip


def _stub_collection(monkeypatch, fake_relabel, *fields: str) -> Examples:
    """``closed_loop.collect`` with the relabelling program replaced by ``fake_relabel`` and a
    learner that needs no model; returns an empty ``like`` with the observation ``fields``
    (``visible`` bool (A,), ``warning_tokens`` int32 (4,))."""
    from lantern_jax.apps.training import closed_loop as cl

    monkeypatch.setattr(cl, "relabel_batch", fake_relabel)
    monkeypatch.setattr(cl, "model_policy", lambda name, model: SimpleNamespace(
        init=lambda key: None))  # fmt: skip
    empty = {"visible": np.zeros((0, 1), bool), "warning_tokens": np.zeros((0, 4), np.int32)}
    return Examples({f: empty[f] for f in fields}, np.zeros((0, NUM_WAYPOINTS, 2)),
                    np.zeros((0,), str), np.zeros((0,), bool))  # fmt: skip


def test_no_warning_visits_drive_route_a_unwarned_and_keep_the_hazard_in_view(monkeypatch):
    """With ``no_warning`` a share of the round's pairs (spread over the families) drives Route
    A a second time with the warning off, the learner alone (beta 0) on the finer grid of
    ``no_warning_every_s``; of those executions only the visits at which *the hazard actor*
    is in the learner's view are kept (another actor in view does not count), under their own
    sequence ids."""
    from lantern_jax.apps.training import closed_loop as cl
    from lantern_jax.sim.rollout import horizon_ticks

    specs = _two_pe_two_vc()
    calls = []

    def fake_relabel(scenarios, learner, lp, expert, ep, key, beta=0.0, num_visits=40, every=40,
                     phase=0, settings=None, segment=1):  # fmt: skip
        cfg_ = scenarios.config
        b, a = cfg_.family.shape[0], scenarios.actors0.xy.shape[1]
        calls.append(dict(warned=np.asarray(cfg_.warning_enabled), route_a=np.asarray(
            cfg_.is_route_a), beta=beta, num_visits=num_visits, every=every))  # fmt: skip
        h = np.asarray(cfg_.hazard_index)
        visible = np.zeros((b, num_visits, a), bool)
        visible[np.arange(b), num_visits // 2 :, h] = True  # the hazard: the later half
        visible[np.arange(b), :, (h + 1) % a] = True  # another actor: always
        obs = SimpleNamespace(visible=visible,
                              warning_tokens=np.full((b, num_visits, 4), PAD_ID, np.int32))
        z = np.zeros((b, num_visits), np.float32)
        return SimpleNamespace(obs=obs, waypoints=np.zeros((b, num_visits, NUM_WAYPOINTS, 2)),
                               valid=np.ones((b, num_visits), bool), t=z,
                               crosses_onset=z.astype(bool), crosses_termination=z.astype(bool),
                               t_collision=z + NEVER)  # fmt: skip

    like = _stub_collection(monkeypatch, fake_relabel, "visible", "warning_tokens")
    cfg = TrainConfig(name="x", recipe="closed_loop", init_from="m", no_warning=0.5,
                      max_seconds=6.0, beta=0.5)  # fmt: skip
    ex, counts = cl.collect(cfg, None, like, specs, r=0)

    assert len(calls) == 2
    ab, quiet = calls
    assert ab["beta"] == 0.5 and ab["warned"].tolist() == [True] * 4 + [False] * 4
    assert quiet["beta"] == 0.0 and quiet["route_a"].all() and not quiet["warned"].any()
    assert quiet["every"] == horizon_ticks(0.5) and quiet["num_visits"] == 12
    n_quiet = 2 * (12 - 6)  # specs 0 (PE) and 2 (VC), the later half of their visits
    assert counts["no_warning_visits"] == n_quiet and counts["executions"] == 8 + 2
    assert counts["kept_visits"] == 8 * 3 + n_quiet  # the A/B grid keeps every valid visit
    seq = ex.sequence[-n_quiet:]
    assert set(seq) == {"pe_00000_A-no-warning", "vc_00002_A-no-warning"}
    none = TrainConfig(name="x", recipe="closed_loop", init_from="m", max_seconds=6.0)
    calls.clear()
    assert cl.collect(none, None, like, specs, r=0)[1]["no_warning_visits"] == 0
    assert len(calls) == 1


def test_collect_keeps_the_told_visits_with_the_learners_own_plan(monkeypatch):
    """With ``distractor_drives`` a share of the round's pairs (spread over the families) is
    driven once more on Route A, the learner alone (beta 0) on the grid of
    ``distractor_drive_every_s``, with the distractor bank; only the visits whose observation
    holds the sentence are kept, under their own sequence ids, and their targets are what
    ``own_plans`` returns, not the expert's."""
    from lantern_jax.apps.training import closed_loop as cl
    from lantern_jax.apps.training.counterfactual import distractor_bank
    from lantern_jax.sim.rollout import horizon_ticks

    specs = _two_pe_two_vc()
    calls = []

    def fake_relabel(scenarios, learner, lp, expert, ep, key, beta=0.0, num_visits=40, every=40,
                     phase=0, settings=None, segment=1):  # fmt: skip
        c = scenarios.config
        b = c.family.shape[0]
        calls.append(dict(beta=beta, every=every, num_visits=num_visits, settings=settings,
                          route_a=np.asarray(c.is_route_a), warned=np.asarray(c.warning_enabled),
                          text_id=np.asarray(c.text_id).reshape(-1)))  # fmt: skip
        tokens = np.full((b, num_visits, 4), PAD_ID, np.int32)
        tokens[:, 2:5, 0] = 7  # a text from the third visit to the fifth
        obs = SimpleNamespace(warning_tokens=tokens, visible=np.zeros((b, num_visits, 1), bool))
        z = np.zeros((b, num_visits), np.float32)
        return _Visits(obs, np.zeros((b, num_visits, NUM_WAYPOINTS, 2), np.float32),
                       np.ones((b, num_visits), bool), z, z.astype(bool), z.astype(bool),
                       z + NEVER)  # fmt: skip

    like = _stub_collection(monkeypatch, fake_relabel, "warning_tokens")
    monkeypatch.setattr(cl, "own_plans", lambda params, obs: np.full(
        (*np.shape(obs.warning_tokens)[:2], NUM_WAYPOINTS, 2), 7.0, np.float32))  # fmt: skip
    cfg = TrainConfig(name="x", recipe="closed_loop", init_from="m", distractor_drives=0.5,
                      max_seconds=6.0, beta=0.5)  # fmt: skip
    ex, counts = cl.collect(cfg, None, like, specs, r=0)

    assert len(calls) == 2
    pairs, told = calls
    assert pairs["beta"] == 0.5 and pairs["settings"].actors == DATA_ACTORS
    assert told["beta"] == 0.0 and told["route_a"].all() and told["warned"].all()
    assert told["every"] == horizon_ticks(0.5) and told["num_visits"] == 12
    assert set(told["text_id"]) <= set(distractor_bank("position")[1].tolist())
    assert told["settings"].bank == distractor_bank("position")[0]
    assert told["settings"].actors == DATA_ACTORS
    n_told = 2 * 3  # specs 0 (PE) and 2 (VC), visits 2, 3 and 4
    assert counts["distractor_drive_visits"] == n_told and counts["executions"] == 8 + 2
    assert counts["no_warning_visits"] == 0
    seq = ex.sequence[-n_told:]
    assert set(seq) == {"pe_00000_A-distractor", "vc_00002_A-distractor"}
    assert (ex.targets[-n_told:] == 7.0).all() and (ex.targets[:-n_told] == 0.0).all()
    assert not ex.base_style[-n_told:].any()

    calls.clear()
    none = TrainConfig(name="x", recipe="closed_loop", init_from="m", max_seconds=6.0)
    assert cl.collect(none, None, like, specs, r=0)[1]["distractor_drive_visits"] == 0
    assert len(calls) == 1


def test_ego_leader_sets_the_actors_rule_of_every_drive_of_a_round(monkeypatch):
    """``ego_leader`` names the actors' rule that the pairs, the no-warning drives and the
    distractor drives all run under (the distractor drives keep their bank); left out, each
    runs under the dataset's rule."""
    from lantern_jax.apps.training import closed_loop as cl
    from lantern_jax.apps.training.counterfactual import distractor_bank

    specs = _two_pe_two_vc()
    seen = []

    def fake_relabel(scenarios, learner, lp, expert, ep, key, beta=0.0, num_visits=40, every=40,
                     phase=0, settings=None, segment=1):  # fmt: skip
        seen.append(settings)
        b = scenarios.config.family.shape[0]
        obs = SimpleNamespace(warning_tokens=np.full((b, num_visits, 4), PAD_ID, np.int32),
                              visible=np.zeros((b, num_visits, 1), bool))
        z = np.zeros((b, num_visits), np.float32)
        return _Visits(obs, np.zeros((b, num_visits, NUM_WAYPOINTS, 2), np.float32),
                       np.ones((b, num_visits), bool), z, z.astype(bool), z.astype(bool),
                       z + NEVER)  # fmt: skip

    like = _stub_collection(monkeypatch, fake_relabel, "visible", "warning_tokens")
    monkeypatch.setattr(cl, "own_plans", lambda params, obs: np.zeros(
        (*np.shape(obs.warning_tokens)[:2], NUM_WAYPOINTS, 2), np.float32))  # fmt: skip
    for rule, expected in (("heading_line_or_box", "heading_line_or_box"),
                           ("", DATA_ACTORS.ego_leader)):  # fmt: skip
        seen.clear()
        cfg = TrainConfig(name="x", recipe="closed_loop", init_from="m", max_seconds=6.0,
                          no_warning=0.5, distractor_drives=0.5, ego_leader=rule)  # fmt: skip
        cl.collect(cfg, None, like, specs, r=0)
        assert len(seen) == 3
        assert [s.actors.ego_leader for s in seen] == [expected] * 3
        assert seen[2].bank == distractor_bank("position")[0]
    assert DATA_ACTORS.ego_leader != "heading_line_or_box"  # the two runs differ


def test_ego_leader_is_checked(tmp_path):
    bad = tmp_path / "bad.toml"
    base = '[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
    bad.write_text(base + 'ego_leader = "box"\n')
    with pytest.raises(ConfigError, match=r"train\.ego_leader: 'box' not one of heading_line, "):
        load_config(bad)
    bad.write_text('[train]\nname = "x"\nrecipe = "base"\nego_leader = "heading_line"\n')
    with pytest.raises(ConfigError, match=r"train\.ego_leader: the base recipe drives nothing"):
        load_config(bad)
    bad.write_text(base + 'ego_leader = "heading_line_or_box"\n')
    assert load_config(bad).ego_leader == "heading_line_or_box"
    assert load_config(ROOT / "configs/train_closed_loop_rig_bigram_stated_half_short.toml"
                       ).ego_leader == ""  # fmt: skip


class _Visits(SimpleNamespace):
    """A stand-in for :class:`~lantern_jax.apps.training.relabel.Visits` (positional fields,
    ``replace``)."""

    def __init__(self, obs, waypoints, valid, t, crosses_onset, crosses_termination,
                 t_collision):  # fmt: skip
        super().__init__(obs=obs, waypoints=waypoints, valid=valid, t=t,
                         crosses_onset=crosses_onset, crosses_termination=crosses_termination,
                         t_collision=t_collision)  # fmt: skip

    def replace(self, **kw):
        return _Visits(**{**vars(self), **kw})


def test_no_warning_visit_settings_are_checked(tmp_path):
    bad = tmp_path / "bad.toml"
    base = '[train]\nname = "x"\nrecipe = "closed_loop"\ninit_from = "m"\n'
    for line, key in (("no_warning = 1.5", "no_warning"), ("no_warning = -0.1", "no_warning"),
                      ("no_warning_every_s = 0.0", "no_warning_every_s")):  # fmt: skip
        bad.write_text(base + line + "\n")
        with pytest.raises(ConfigError, match=rf"train\.{key}:"):
            load_config(bad)
    bad.write_text(base + "no_warning = 1.0\nno_warning_every_s = 0.25\n")
    assert load_config(bad).no_warning == 1.0 and load_config(bad).no_warning_every_s == 0.25
