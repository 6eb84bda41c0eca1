"""CUS formula, component clip boundaries and the paper's worked example."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from lantern_jax.core.constants import FAMILIES
from lantern_jax.scenarios.families import family
from lantern_jax.scoring.cus import (
    components_from_values,
    cus_from_values,
    d_safe_for_family,
    s_ant,
    s_clear,
    s_rec,
    s_ttc,
)


def test_worked_example_closed_occluded_pedestrian_0001():
    # Paper table "Worked CUS example": P_A = P_B = 1, TTC_min 2.082 s, d_min 10.794 m,
    # d_safe 2 m, (t_ref, t_event, t_react) = (3.30, 5.30, 3.35) s, RL 0.60 s, gates pass.
    # S_TTC = 0.694, S_clear = 1, S_ant = 1.95 / 2 = 0.975, S_rec = 1 - 0.6 / 8 = 0.925
    # contributions 0.34 + 0.10323 + 0.14875 + 0.10359 + 0.09828 + 0.15 = 0.94386 -> 94.39
    cus = cus_from_values(1.0, 1.0, 2.082, 10.794, 2.0, 3.30, 5.30, 3.35, 0.60)
    assert abs(float(cus) - 94.386) < 0.01
    c = components_from_values(1.0, 1.0, 2.082, 10.794, 2.0, 3.30, 5.30, 3.35, 0.60)
    assert float(c["S_ttc"]) == pytest.approx(0.694, abs=1e-6)
    assert float(c["S_clear"]) == 1.0
    assert float(c["S_ant"]) == pytest.approx(0.975, abs=1e-6)
    assert float(c["S_rec"]) == pytest.approx(0.925, abs=1e-6)
    # the same under jit
    jitted = jax.jit(cus_from_values)(1.0, 1.0, 2.082, 10.794, 2.0, 3.30, 5.30, 3.35, 0.60)
    assert abs(float(jitted) - 94.386) < 0.01


@pytest.mark.parametrize("gate", ["gate_collision", "gate_route_deviation", "gate_lane",
                                  "gate_rule", "gate_block", "gate_false_brake"])  # fmt: skip
def test_any_failed_gate_zeroes_the_worked_example(gate):
    c = components_from_values(
        1.0, 1.0, 2.082, 10.794, 2.0, 3.30, 5.30, 3.35, 0.60, **{gate: False}
    )
    assert float(c["CUS"]) == 0.0
    assert float(c["gate_product"]) == 0.0


def test_ttc_clip_boundaries():
    assert float(s_ttc(3.0)) == 1.0
    assert float(s_ttc(7.5)) == 1.0
    assert float(s_ttc(math.inf)) == 1.0  # no closing trend
    assert float(s_ttc(0.0)) == 0.0  # overlap
    assert float(s_ttc(1.5)) == pytest.approx(0.5)
    assert math.isnan(float(s_ttc(math.nan)))


def test_clearance_clip_boundaries():
    assert float(s_clear(2.0, 2.0)) == 1.0
    assert float(s_clear(5.0, 3.0)) == 1.0
    assert float(s_clear(1.5, 3.0)) == pytest.approx(0.5)
    assert float(s_clear(0.0, 2.0)) == 0.0
    assert math.isnan(float(s_clear(math.nan, 2.0)))


def test_the_family_registry_holds_d_safe_and_the_deprecated_lookup_agrees():
    """The paper's 2 m for PE and OR, 3 m otherwise: in each family's registry entry, in every
    scene it builds, and in the deprecated lookup by family (kept for one release)."""
    assert [family(f).d_safe for f in FAMILIES] == [2.0, 3.0, 2.0, 3.0, 3.0, 3.0]
    with pytest.warns(DeprecationWarning, match="d_safe_for_family is deprecated"):
        old = [float(d_safe_for_family(f)) for f in FAMILIES]
    assert old == [family(f).d_safe for f in FAMILIES]
    with pytest.warns(DeprecationWarning):
        assert np.allclose(d_safe_for_family(np.arange(6)), [2, 3, 2, 3, 3, 3])


def test_anticipation_clip_boundaries():
    assert float(s_ant(3.0, 5.0, 3.0)) == 1.0  # response at warning onset
    assert float(s_ant(3.0, 5.0, 4.0)) == pytest.approx(0.5)
    assert float(s_ant(3.0, 5.0, 5.0)) == 0.0  # response at the event
    assert float(s_ant(3.0, 5.0, 6.5)) == 0.0  # after the event
    assert float(s_ant(3.0, 5.0, math.nan)) == 0.0  # no response
    assert float(s_ant(3.0, 5.0, math.inf)) == 0.0
    assert math.isnan(float(s_ant(3.0, 5.0, 3.5, available=False)))
    assert math.isnan(float(s_ant(math.nan, 5.0, 3.5)))
    # coincident onset: a response must already be present at the event
    assert float(s_ant(5.0, 5.0, 4.55)) == 1.0
    assert float(s_ant(5.0, 5.0, 5.0)) == 0.0
    assert float(s_ant(5.0, 5.0, 5.3)) == 0.0
    assert float(s_ant(5.0, 5.0, math.nan)) == 0.0
    assert float(s_ant(5.0, 5.05, 4.6, coincident=True)) == 1.0


def test_recovery_clip_boundaries():
    assert float(s_rec(0.0)) == 1.0
    assert float(s_rec(4.0)) == pytest.approx(0.5)
    assert float(s_rec(8.0)) == 0.0
    assert float(s_rec(12.0)) == 0.0
    assert float(s_rec(math.nan)) == 0.0  # never recovered
    assert math.isnan(float(s_rec(0.5, available=False)))


def test_nan_component_counts_zero_but_stays_nan():
    c = components_from_values(1.0, 1.0, math.nan, math.nan, 2.0, 3.3, 5.3, math.nan, math.nan,
                               anticipation_available=False, recovery_available=False)  # fmt: skip
    for k in ("S_ttc", "S_clear", "S_ant", "S_rec"):
        assert math.isnan(float(c[k]))
    # only progress terms remain: 100 (0.85 * 0.40 + 0.15) = 49
    assert float(c["CUS"]) == pytest.approx(49.0, abs=1e-4)


def test_batched_values_broadcast():
    cus = cus_from_values(
        np.array([1.0, 0.5]), 1.0, np.array([2.082, math.inf]), 10.794, 2.0, 3.30, 5.30,
        np.array([3.35, math.nan]), np.array([0.60, 8.0]),
        gate_collision=np.array([True, True]),
    )  # fmt: skip
    # second: 0.85 (0.4 * 0.5 + 0.35 * 1 + 0) + 0.15 = 0.6175
    assert np.allclose(np.asarray(cus), [94.386, 61.75], atol=0.01)
