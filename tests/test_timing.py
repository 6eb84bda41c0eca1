"""The wall-clock breakdown behind ``lantern-jax evaluate --profile``."""

from __future__ import annotations

import time

from lantern_jax.core.timing import Breakdown, seconds_since_process_start


def test_phases_in_order_with_details_and_shares():
    bd = Breakdown()
    with bd.phase("first"):
        time.sleep(0.02)
    bd.add("second", 0.5)
    bd.add("a detail of second", 0.25, indent=1)
    assert [p.label for p in bd.phases] == ["first", "second", "a detail of second"]
    assert 0.02 <= bd.phases[0].seconds < 1.0
    assert bd.total() >= 0.02  # measured from process start where known
    text = bd.format("Where")
    lines = text.splitlines()
    assert lines[0].startswith("Where")
    assert lines[3].startswith("  a detail of second")  # details are indented
    assert lines[-1].startswith("total") and lines[-1].endswith("100.0 %")
    share = float(lines[2].split()[-2])
    assert abs(share - 100 * 0.5 / bd.total()) < 0.1 + 100 * 0.5 / bd.total() * 0.05


def test_process_start_is_known_here_and_counted_first():
    since = seconds_since_process_start()
    assert since is None or 0.0 <= since < 24 * 3600
    bd = Breakdown()
    bd.before_creation("start-up")
    if since is not None:
        assert bd.phases[0].label == "start-up" and bd.phases[0].seconds >= 0.0
        assert bd.total() >= bd.phases[0].seconds
    else:
        assert bd.phases == []
