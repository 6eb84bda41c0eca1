"""The language diagnostic's replacement texts: which text each variant delivers, the held-out
probe sentences and their bank, and what a policy reads of them (the tables themselves:
``tests/test_policy_boundary.py``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from lantern_jax.apps import language_sensitivity as ls
from lantern_jax.apps.training.counterfactual import STRAIGHT, nonactionable_ids
from lantern_jax.core.constants import FAMILIES, NO_WARNING_CONDITION, WARNING_CONDITION
from lantern_jax.scenarios.warning_texts import NO_FAMILY, PROBE_IRRELEVANT, PROBE_NEGATED
from lantern_jax.scenarios.warnings import (
    DEFAULT_BANK,
    EMPTY_TEXT_ID,
    get_text,
    registered_bank,
    warning_language,
)
from lantern_jax.types import language

FAMILY_INDEX = np.arange(len(FAMILIES))


def test_same_road_type_swaps_stay_on_the_road_type_and_never_keep_the_family():
    swap = ls.SAME_ROAD_OTHER_FAMILY
    assert sorted(swap.values()) == list(FAMILY_INDEX)  # a permutation
    for f, g in swap.items():
        assert f != g
        assert (FAMILIES[f] in STRAIGHT) == (FAMILIES[g] in STRAIGHT)
    for f, g in ls.OTHER_FAMILY.items():
        assert (FAMILIES[f] in STRAIGHT) != (FAMILIES[g] in STRAIGHT)


def test_each_variant_delivers_its_text():
    _, probe_ids = ls.probe_bank(DEFAULT_BANK)
    ids = {v: ls._replacement_ids(v, FAMILY_INDEX, probe_ids)
           for v in ls.LANGUAGE_VARIANTS if v not in ("delivered text", "no warning")}  # fmt: skip
    assert [get_text(i).kind for i in ids["other family's text"]] == ["canonical"] * 6
    same_road = [get_text(i) for i in ids["same road type, other family's paraphrase"]]
    assert all(e.kind == "paraphrase" and e.tier == "low" and e.has_position for e in same_road)
    assert [e.family for e in same_road] == [ls.SAME_ROAD_OTHER_FAMILY[f] for f in FAMILY_INDEX]
    assert set(ids["empty text"]) == {EMPTY_TEXT_ID}
    assert set(ids["irrelevant sentence with the position"]) == {len(DEFAULT_BANK)}
    assert set(ids["negated sentence with the position"]) == {len(DEFAULT_BANK) + 1}


def test_the_probes_are_held_out_of_every_bank_and_every_training_text():
    probes = {PROBE_IRRELEVANT, PROBE_NEGATED}
    assert probes.isdisjoint(e.text for e in DEFAULT_BANK)
    assert probes.isdisjoint(e.text for e in registered_bank())
    assert probes.isdisjoint(get_text(int(i)).text for i in nonactionable_ids())
    bank, ids = ls.probe_bank(DEFAULT_BANK)
    assert bank.entries[: len(DEFAULT_BANK)] == DEFAULT_BANK.entries  # earlier ids unchanged
    for variant, text_id in ids.items():
        entry = bank.get(text_id)
        assert entry.text == ls.PROBE_VARIANTS[variant]
        assert entry.kind == "non_actionable" and entry.family == NO_FAMILY
        assert entry.has_position


@pytest.mark.parametrize("text", [PROBE_IRRELEVANT, PROBE_NEGATED])
def test_a_policy_reads_a_probe_with_the_hazard_s_position(text):
    """The warning sensor's reading of a probe: its own tokens, and the grounded position in
    the value channel at the text's two number tokens, as for any text that states one."""
    bank, ids = ls.probe_bank(DEFAULT_BANK)
    text_id = next(i for v, i in ids.items() if ls.PROBE_VARIANTS[v] == text)
    tokens, values = warning_language(np.int32(text_id), np.bool_(True),
                                      np.asarray([23.46, -1.5], np.float32), bank)  # fmt: skip
    expected = language.pad(language.tokenize(text))
    np.testing.assert_array_equal(np.asarray(tokens), expected)
    x_slot, y_slot = language.number_slots(language.tokenize(text))
    values = np.asarray(values)
    assert values[x_slot] == pytest.approx(float(language.round_number(np.float32(23.46))))
    assert values[y_slot] == pytest.approx(-1.5)
    assert np.count_nonzero(values) == 2


def test_an_unknown_variant_is_refused_naming_it_before_anything_runs():
    with pytest.raises(ValueError, match=r"variants: \['bakery'\] not among"):
        ls.language_table("coop", "lantern-v3", variants=("bakery",))


def _route_rows(cus_by_pair: dict[str, float], condition: str) -> pd.DataFrame:
    families = [p[:2].upper() for p in cus_by_pair]
    return pd.DataFrame({"pair_id": list(cus_by_pair), "family": families,
                         "condition": condition, "CUS": list(cus_by_pair.values())})  # fmt: skip


def test_table_from_route_tables_with_derived_shares_and_intervals():
    """Two PE and two VC pairs with hand-set CUS: each cell is the family's mean, Overall the
    mean of the families, and a share the ratio of the mean differences (50 % here in every
    column, derived below); every estimate lies in its interval; a family without pairs is
    NaN."""
    pairs = ["pe_1", "pe_2", "vc_1", "vc_2"]
    delivered = dict(zip(pairs, [90.0, 80.0, 60.0, 70.0], strict=True))
    no_warning = dict(zip(pairs, [10.0, 20.0, 50.0, 50.0], strict=True))
    other = dict(zip(pairs, [50.0, 50.0, 55.0, 60.0], strict=True))
    # PE: (50 - 15) / (85 - 15) = 0.5; VC: (57.5 - 50) / (65 - 50) = 0.5;
    # Overall: (53.75 - 32.5) / (75 - 32.5) = 0.5
    runs = {
        "delivered text": pd.concat([_route_rows(delivered, WARNING_CONDITION),
                                     _route_rows(no_warning, NO_WARNING_CONDITION)]),  # fmt: skip
        "other family's text": _route_rows(other, WARNING_CONDITION),
        "empty text": _route_rows(no_warning, WARNING_CONDITION),
    }
    runs["no warning"] = runs["delivered text"]
    chosen = ["delivered text", "other family's text", "empty text", "no warning"]
    table = ls._with_intervals(runs, chosen, seed=0).set_index("Variant")
    assert table.loc["delivered text", "PE"] == pytest.approx(85.0)
    assert table.loc["no warning", "VC"] == pytest.approx(50.0)
    assert table.loc["delivered text", "Overall"] == pytest.approx(75.0)
    kept = table.loc["gain kept by other family's text (%)"]
    assert [kept["PE"], kept["VC"], kept["Overall"]] == pytest.approx([50.0, 50.0, 50.0])
    assert table.loc["gain kept by empty text (%)", "PE"] == pytest.approx(0.0)
    assert np.isnan(table.loc["delivered text", "OR"]) and np.isnan(kept["OR"])
    assert set(table["n"]) == {2}
    for col in ("PE", "VC", "Overall"):
        values = table[[f"{col}_lo", col, f"{col}_hi"]].to_numpy(float)
        assert np.all(values[:, 0] <= values[:, 1] + 1e-9)
        assert np.all(values[:, 1] <= values[:, 2] + 1e-9)
