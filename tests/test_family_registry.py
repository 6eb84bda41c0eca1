"""The one family registry: the six built-in families and a user's family are entries of one
registry, registered by one call, and every reader (validation, premise rule, text bank, pair
builder, stress search space) reads the entry."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from lantern_jax.apps.stress.space import search_space
from lantern_jax.core import family_codes
from lantern_jax.core.constants import FAMILIES, FAMILY_NAMES
from lantern_jax.scenarios import families, premise, registry, spec
from lantern_jax.scenarios import warnings as w
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY, FamilyEntry, FamilyRegistry
from lantern_jax.scoring.thresholds import D_SAFE_LARGE_M, D_SAFE_SMALL_M

TESTS = Path(__file__).parent


@pytest.fixture
def example():
    """``tests/family_example.py`` (the JWK family) registered for one test, then forgotten."""
    state = registry.snapshot()
    sys.path.insert(0, str(TESTS))
    try:
        import family_example

        yield family_example
    finally:
        sys.path.remove(str(TESTS))
        sys.modules.pop("family_example", None)
        registry.restore(state)


def test_the_six_are_entries_of_the_registry_in_the_papers_order():
    entries = FAMILY_REGISTRY.entries()[: len(FAMILIES)]
    assert tuple(e.code for e in entries) == FAMILIES
    assert tuple(e.name for e in entries) == FAMILY_NAMES
    assert entries == families.BUILTIN_FAMILIES
    for i, e in enumerate(entries):
        assert isinstance(e, FamilyEntry) and e.builtin and e.index == i and e.record is None
        assert e.ranges is spec.PARAM_RANGES[e.code] and e.knobs is families.KNOB_RANGES[e.code]
        assert families.family(e.code) is e and families.family(i) is e
        assert e.template == w.get_text(w.canonical_text_id(e.code)).text


def test_d_safe_and_premise_rules_are_the_papers_and_every_scene_carries_its_entrys_d_safe():
    """2 m for PE and OR, 3 m otherwise; the premise rule hides the hazard for PE, OR, LWW, RWW
    (from the whole approach where nothing moves before the event)."""
    want_d = {"PE": D_SAFE_SMALL_M, "OR": D_SAFE_SMALL_M}
    whole, at_warning = premise.PREMISE_WHOLE_APPROACH, premise.PREMISE_AT_WARNING
    want_rule = {"PE": whole, "LWW": whole, "RWW": whole, "OR": at_warning}
    rng = np.random.default_rng(3)
    for code in FAMILIES:
        entry = FAMILY_REGISTRY.entry(code)
        assert entry.d_safe == want_d.get(code, D_SAFE_LARGE_M)
        assert premise.premise_rule(code) == entry.premise == want_rule.get(code, "none")
        a, b, _ = families.build_pair(families.sample_params(code, rng))
        assert float(a.config.d_safe) == float(b.config.d_safe) == entry.d_safe


def test_a_users_family_is_an_entry_that_every_reader_reads(example):
    entry = FAMILY_REGISTRY.entry("JWK")
    record = example.RECORD
    # the entry holds the record first registered: this one, or the same file imported under
    # another module name by an earlier command in this process (the same family)
    assert registry._identity(entry.record) == registry._identity(record)
    assert not entry.builtin and entry.index == family_codes.index("JWK") >= len(FAMILIES)
    assert registry.registered_families()["JWK"] is entry.record
    assert dict(spec.param_ranges("JWK")) == {**spec.COMMON_RANGES, **record.ranges}
    assert premise.premise_rule("JWK") == record.premise
    assert entry.template == record.warning
    assert w.get_text(w.canonical_text_id("JWK")).text == record.warning
    params = families.sample_params("JWK", np.random.default_rng(0))
    a, _, _ = families.build_pair(params)
    assert float(a.config.d_safe) == record.d_safe == D_SAFE_SMALL_M
    # registering the same record again returns the entry held; another record is refused
    assert registry.register_family(record) is entry
    with pytest.raises(ValueError, match="another record"):
        registry.register_family(dataclasses.replace(record, d_safe=2.5))


def test_a_records_d_safe_reaches_its_scenes_and_a_scene_may_override_it(example):
    record = dataclasses.replace(example.RECORD, code="JWKD", d_safe=D_SAFE_LARGE_M)
    registry.register_family(record)
    params = {**families.sample_params("JWK", np.random.default_rng(1)), "family": "JWKD"}
    a, b, _ = families.build_pair(params)
    assert float(a.config.d_safe) == float(b.config.d_safe) == D_SAFE_LARGE_M

    def build(p):
        return dataclasses.replace(example.build(p), d_safe=4.0)

    registry.register_family(dataclasses.replace(record, code="JWKO", build=build))
    a, _, _ = families.build_pair({**params, "family": "JWKO"})
    assert float(a.config.d_safe) == 4.0


@pytest.mark.parametrize("bad", [0.0, -2.0, float("nan"), True, "3"])
def test_a_record_with_a_bad_d_safe_is_refused_naming_the_field(example, bad):
    with pytest.raises(ValueError, match="d_safe"):
        registry.register_family(dataclasses.replace(example.RECORD, code="JWKB", d_safe=bad))
    assert "JWKB" not in family_codes.codes() and "JWKB" not in FAMILY_REGISTRY


def test_snapshot_and_restore_forget_the_entry_its_code_and_its_texts(example):
    state = registry.snapshot()
    bank = len(w.registered_bank())
    registry.register_family(dataclasses.replace(example.RECORD, code="JWKS"))
    assert "JWKS" in FAMILY_REGISTRY and "JWKS" in family_codes.codes()
    assert len(w.registered_bank()) == bank + 1 + sum(map(len, example.RECORD.paraphrases.values()))
    registry.restore(state)
    assert "JWKS" not in FAMILY_REGISTRY and "JWKS" not in family_codes.codes()
    assert len(w.registered_bank()) == bank
    with pytest.raises(ValueError, match="JWKS"):
        spec.param_ranges("JWKS")


def test_the_stress_search_space_reads_the_entrys_knobs(example):
    space = search_space("PE")
    assert space.names == tuple(families.KNOB_RANGES["PE"])
    knobs = {"hazard_speed": (1.25, 1.75)}
    registry.register_family(dataclasses.replace(example.RECORD, code="JWKK", knobs=knobs))
    space = search_space("JWKK")
    assert space.names == ("hazard_speed",)
    assert np.allclose([space.lo[0], space.hi[0]], [1.25, 1.75])
    registry.register_family(dataclasses.replace(example.RECORD, code="JWKN", knobs={}))
    with pytest.raises(ValueError, match="no stress-testing knobs"):
        search_space("JWKN")


def test_a_registry_refuses_what_is_not_an_entry_and_a_second_entry_under_a_code():
    fresh = FamilyRegistry()
    pe = FAMILY_REGISTRY.entry("PE")
    assert fresh.register(pe) is pe and fresh.register(pe) is pe and fresh.codes() == ("PE",)
    with pytest.raises(TypeError, match="FamilyEntry"):
        fresh.register({"code": "PE"})
    with pytest.raises(ValueError, match="already registered as another family"):
        fresh.register(dataclasses.replace(pe, d_safe=9.0))
    with pytest.raises(ValueError, match="not registered yet"):
        fresh.entry("VC")
    with pytest.raises(ValueError, match="not one of"):
        fresh.entry("NOPE")


def test_the_family_and_sensor_tables_are_one_kind_of_registry():
    """Both extension points keep their entries the same way
    (:mod:`lantern_jax.core.named_registry`):
    an equal entry registered again is the one held, a snapshot restores what was there."""
    from lantern_jax.core.named_registry import NamedRegistry
    from lantern_jax.sensors.registry import SENSOR_REGISTRY, SensorRegistry

    assert isinstance(FAMILY_REGISTRY, NamedRegistry) and isinstance(SENSOR_REGISTRY, NamedRegistry)
    table = SensorRegistry()
    front = SENSOR_REGISTRY.get("front_camera")
    state = table.snapshot()
    assert table.register(front) is front and table.names() == ("front_camera",)
    table.restore(state)
    assert table.names() == () and "front_camera" not in table


def test_a_registration_left_behind_by_a_test_part_one():
    """Registers the JWK family on import and leaves it registered (no clean-up of its own):
    the next test checks that the test session forgets it (``tests/conftest.py``)."""
    sys.path.insert(0, str(TESTS))
    try:
        import family_example
    finally:
        sys.path.remove(str(TESTS))
    assert family_example.FAMILY.code in FAMILY_REGISTRY.codes()


def test_a_registration_left_behind_by_a_test_part_two():
    """The previous test's family is forgotten: the six families, the built-in bank, and the
    module gone so that importing it again registers again (the two run in this order in one
    process: pytest keeps a file's order, and the test command's workers take whole files)."""
    from lantern_jax.scenarios.warning_texts import DEFAULT_BANK
    from lantern_jax.sim.settings import default_settings

    assert list(FAMILY_REGISTRY.codes()) == list(FAMILIES)
    assert default_settings().bank == DEFAULT_BANK
    assert "family_example" not in sys.modules
