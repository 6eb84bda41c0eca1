"""The warning text bank: fixed canonical ids, paraphrases by ambiguity tier, the paper's
non-actionable texts, and the tier assignment over a suite (disjoint, covering, balanced)."""

from __future__ import annotations

import collections

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import FAMILIES
from lantern_jax.scenarios import warnings as w
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.suite import load_suite


@pytest.fixture(scope="module")
def suite():
    return load_suite()


def test_canonical_ids_and_texts_are_fixed():
    assert [e.text_id for e in w.DEFAULT_BANK.entries[:6]] == list(range(6))
    assert all(e.kind == "canonical" and e.family == e.text_id for e in w.DEFAULT_BANK.entries[:6])
    assert w.DEFAULT_BANK[0].text == (
        "The pedestrian at position <FRONT_CAR_POS> is about to enter the ego lane."
    )
    assert [e.text_id for e in w.DEFAULT_BANK] == list(range(len(w.DEFAULT_BANK)))


def test_first_paraphrase_ids_are_kept():
    for f in range(len(FAMILIES)):
        e = w.get_text(w.paraphrase_text_id(f))
        assert e.text_id == 6 + f and e.family == f and e.tier == "low"


@pytest.mark.parametrize("family", FAMILIES)
def test_three_paraphrases_per_tier_with_the_tiers_position_rule(family):
    f = FAMILIES.index(family)
    for tier in w.TIERS:
        ids = w.tier_text_ids(family, tier)
        assert len(ids) >= 3, (family, tier)
        for i in ids:
            e = w.get_text(i)
            assert (e.family, e.kind, e.tier) == (f, "paraphrase", tier)
            assert e.has_position == (tier != "high"), e.text
            assert e.text != w.TEMPLATES[f]
    texts = [w.get_text(i).text for t in w.TIERS for i in w.tier_text_ids(family, t)]
    assert len(set(texts)) == len(texts)


def test_non_actionable_texts_are_the_papers_verbatim_and_state_no_position():
    ids = w.non_actionable_text_ids()
    assert [w.get_text(i).text for i in ids[:5]] == [
        "Caution: maintenance equipment is operating behind the roadside barrier.",
        "Warning: a delivery van is parked in an off-road service area.",
        "Caution: a pedestrian is waiting behind a roadside fence and remains clear of traffic.",
        "Warning: a cyclist is traveling away on a physically separated path.",
        "Caution: traffic is restricted on a parallel road outside the ego route.",
    ]
    for i in ids:
        e = w.get_text(i)
        assert e.family == w.NO_FAMILY and not e.has_position
        assert w.render_warning(i, None) == e.text  # no position to ground


def test_distance_conditioned_warning_renders_the_papers_positions():
    assert w.render_warning(0, w.DISTANCE_POSITIONS["near"]) == (
        "The pedestrian at position (12.0, 0.5) is about to enter the ego lane."
    )
    assert "(100.0, 0.5)" in w.render_warning(0, w.DISTANCE_POSITIONS["far"])


@pytest.mark.parametrize(
    "args,match",
    [
        (("PE", "canonical", "x"), "canonical texts are fixed"),
        (("PE", "paraphrase", "A car near <FRONT_CAR_POS> is stopped.", "extreme"), "tier"),
        (("PE", "paraphrase", "A pedestrian is crossing.", "low"), "must state the position"),
        (("PE", "paraphrase", "A car at <FRONT_CAR_POS> is stopped.", "high"), "no position"),
        (("PE", "non_actionable", "A car.", "low"), "only paraphrases have a tier"),
        (("PE", "paraphrase", "Cars at <FRONT_CAR_POS> and <FRONT_CAR_POS> now.", "low"),
         "2 positions"),
        (("PE", "paraphrase", "A car at <FRONT_CAR_POS> .", "low"), "exactly one space"),
        (("XX", "paraphrase", "A car.", "high"), "family"),
        ((w.NO_FAMILY, "paraphrase", "A car.", "high"), "family"),
    ],
)  # fmt: skip
def test_with_text_refuses_bad_entries(args, match):
    n = len(w.DEFAULT_BANK)
    with pytest.raises(ValueError, match=match):
        w.DEFAULT_BANK.with_text(*args)
    assert len(w.DEFAULT_BANK) == n


def test_with_text_returns_a_new_bank_and_leaves_the_default_alone():
    n = len(w.DEFAULT_BANK)
    bank = w.DEFAULT_BANK.with_text(
        "PE", "paraphrase", "A car near <FRONT_CAR_POS> is stopped.", "low"
    )
    assert len(bank) == n + 1 and len(w.DEFAULT_BANK) == n
    assert bank.get(n).text_id == n and bank.get(n).tier == "low"
    assert n + 1 == len(w.token_table(bank)) and len(w.token_table(w.DEFAULT_BANK)) == n
    assert hash(bank) != hash(w.DEFAULT_BANK) and bank != w.DEFAULT_BANK


# ---------------------------------------------------------------------------------------------
# tiers over a suite
# ---------------------------------------------------------------------------------------------
def _suite_tiers(suite):
    return w.ambiguity_tiers([p.family for p in suite.pairs], [p.sha256 for p in suite.pairs])


def test_tiers_partition_the_suite_into_three_forties(suite):
    tiers = _suite_tiers(suite)
    assert len(tiers) == 120 and set(tiers.tolist()) == {0, 1, 2}  # each pair exactly one tier
    assert np.bincount(tiers).tolist() == [40, 40, 40]
    pairs = zip(suite.pairs, tiers, strict=True)
    per_family = collections.Counter((p.family, int(t)) for p, t in pairs)
    assert sorted(set(per_family.values())) == [6, 7]  # every family spread over the tiers


@given(st.lists(st.tuples(st.sampled_from(FAMILIES), st.text(min_size=1, max_size=8)),
                min_size=1, max_size=40, unique_by=lambda x: x[1]))  # fmt: skip
@settings(max_examples=60, deadline=None)
def test_tiers_are_balanced_and_order_free(pairs):
    fams, keys = [p[0] for p in pairs], [p[1] for p in pairs]
    tiers = w.ambiguity_tiers(fams, keys)
    counts = np.bincount(tiers, minlength=3)
    assert counts.max() - counts.min() <= 1
    perm = np.random.default_rng(len(pairs)).permutation(len(pairs))
    again = w.ambiguity_tiers([fams[i] for i in perm], [keys[i] for i in perm])
    np.testing.assert_array_equal(again, tiers[perm])
    ids = w.held_out_text_ids(fams, keys)
    for f, t, i in zip(fams, tiers, ids, strict=True):
        e = w.get_text(int(i))
        assert (FAMILIES[e.family], e.tier) == (f, w.TIERS[t])


def test_every_paraphrase_is_used_on_the_suite(suite):
    ids = set(w.held_out_text_ids([p.family for p in suite.pairs], [p.sha256 for p in suite.pairs]))
    want = {i for f in FAMILIES for t in w.TIERS for i in w.tier_text_ids(f, t)}
    assert ids == want


def test_held_out_ablation_uses_the_tiers(suite):
    """The ablation keys the tiers on the pair's generation seed (``noise_seed``), which the
    built executions carry: 40 / 40 / 40 on the suite, each pair's text of its own family."""
    small = suite.subset(3)  # 18 pairs: 6 / 6 / 6
    configs = [build_pair(p.params)[0].config for p in small.pairs]
    batch = jax.tree.map(lambda *x: np.stack(x), *configs)
    ids = w.paraphrase_text_ids(batch)
    tiers = w.paraphrase_tiers(batch)
    assert np.bincount(tiers).tolist() == [6, 6, 6]
    for p, i, t in zip(small.pairs, ids, tiers, strict=True):
        e = w.get_text(int(i))
        assert FAMILIES[e.family] == p.family and e.tier == w.TIERS[t]
