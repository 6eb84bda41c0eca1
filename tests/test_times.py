"""Seconds to ticks (:mod:`lantern_jax.core.times`): the one conversion every module uses."""

from __future__ import annotations

import numpy as np

from lantern_jax.core.constants import DT
from lantern_jax.core.times import ticks, ticks_covering


def test_ticks_is_the_nearest_count():
    assert DT == 0.05
    assert ticks(0.05) == 1 and ticks(1.0) == 20 and ticks(30.0) == 600
    assert ticks(0.074) == 1 and ticks(0.076) == 2 and ticks(0.0) == 0


def test_ticks_covering_reaches_the_time():
    assert ticks_covering(30.0) == 600 and ticks_covering(30.001) == 601
    assert ticks_covering(0.0) == 0 and ticks_covering(0.001) == 1
    # 3 * DT is 0.15000000000000002 in float: 3.0000000000000004 ticks, ceil 4 without slack
    assert ticks_covering(3 * DT) == 4
    assert all(ticks_covering(n * DT, slack=1e-6) == n for n in range(2000))


def test_float32_times_give_the_same_counts_as_float64():
    t = np.float32(12.35)
    assert ticks(t) == ticks(float(t)) == 247
