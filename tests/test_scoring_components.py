"""Each CUS component unit on tiny hand-built trajectories (expected values derived in comments),
and soft -> hard as the temperature goes to 0 for every unit."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import DT
from lantern_jax.core.times import NEVER
from lantern_jax.scoring.components import (
    anticipation,
    block,
    clearance,
    collision,
    context,
    false_brake,
    lane,
    progress,
    recovery,
    route_deviation,
    rule,
    ttc,
)
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.thresholds import DEFAULT_SCORING as S

N = 60  # ticks of every tiny trajectory (3 s); t[k] = (k + 1) * DT
BOOLS = ("outside_lanes", "red_light_violation", "collision", "hazard_present", "justified_stop",
         "fb_window", "controller_fault", "is_route_a", "coincident_onset",
         "slow_unjustified")  # fmt: skip


def quiet(n: int = N, speed: float = 5.0) -> dict[str, np.ndarray]:
    """Cruise at ``speed`` on a long route, no hazard, no protocol time, no infraction."""
    t = (np.arange(n) + 1) * DT
    tr = {
        "t": t,
        "ego_speed": np.full(n, speed),
        "ego_accel": np.zeros(n),
        "progress": speed * t,
        "route_length": np.full(n, 1000.0),
        "dist_to_route": np.zeros(n),
        "hazard_rel": np.tile([50.0, 0.0], (n, 1)),
        "hazard_rel_vel": np.zeros((n, 2)),
        "hazard_box_dist": np.full(n, 45.0),
        **{k: np.full(n, NEVER) for k in ("t_warn_point", "t_event", "t_warn_off", "t_clear")},
        **{k: np.zeros(n, bool) for k in BOOLS},
    }
    tr["is_route_a"][:] = True
    return tr


def at(k: int) -> float:
    """Time stamp (s) of tick ``k`` as the fold sees it (float32)."""
    return float(np.float32((k + 1) * DT))


@functools.partial(jax.jit, static_argnums=0)
def _fold(unit, stacked: TickSample, temperature):
    settings = S.replace(temperature=temperature)

    def body(carry, s):
        ctx, state = carry
        ctx, tick = context.update(ctx, s, settings)
        return (ctx, unit.update(state, s, tick, settings)), None

    init = (context.init(settings), unit.init(settings))
    (ctx, state), _ = jax.lax.scan(body, init, stacked)
    return ctx, state


def samples(tr) -> TickSample:
    """The trajectory as stacked float32 / bool samples (leading axis = time)."""
    return TickSample(
        **{k: jnp.asarray(v, bool if k in BOOLS else jnp.float32) for k, v in tr.items()}
    )


def fold(unit, tr, temperature=0.01):
    """``(final context, final unit state)`` of one unit folded alone over ``tr``."""
    return _fold(unit, samples(tr), jnp.float32(temperature))


def f(x) -> float:
    return float(np.asarray(x))


# -------------------------------------------------------------------------------- shared context
def test_context_v_pre_rings_and_window_masks():
    # speed 6 m/s rising by 0.1 m/s per tick; t_ref at tick 3 -> v_pre = the speed before
    # warning onset, on tick 2: 6.2 m/s
    tr = quiet()
    tr["ego_speed"] = 6.0 + 0.1 * np.arange(N)
    tr["t_warn_point"][:], tr["t_event"][:] = at(3), at(8)
    ticks = samples(tr)
    ctx = context.init(S)
    for k in range(6):  # fold ticks 0..5
        row = jax.tree.map(lambda x, k=k: x[k], ticks)
        ctx, tick = context.update(ctx, row, S.replace(temperature=jnp.float32(0.01)))
    assert f(ctx.v_pre) == pytest.approx(6.2) and bool(ctx.v_pre_set)
    assert int(ctx.n_ticks) == 6 and f(ctx.t_last) == at(5)
    assert f(ctx.time_ring[-1]) == at(5) and f(ctx.time_ring[-7]) == 0.0  # 6 ticks, zero-filled
    # tick 5 lies after t_ref and before t_event and clearance
    assert bool(tick.post_ref) and not bool(tick.post_event) and bool(tick.before_clear)


UNITS_WITH_STATE = (ttc, clearance, anticipation, recovery, collision, route_deviation, lane,
                    rule, block, false_brake)  # fmt: skip


def test_telemetry_fold_equals_each_unit_folded_alone():
    from lantern_jax.scoring.telemetry import fold_telemetry

    tr = braking_case(14)
    tr["hazard_present"][:] = True
    tr["hazard_box_dist"][:] = np.linspace(20.0, 2.0, N)
    tr["hazard_rel_vel"][:, 0] = -2.0
    # same program shape as the single-unit fold (traced temperature); two separately compiled
    # programs may still round a division differently, hence the 1e-6 relative tolerance
    tel = jax.jit(fold_telemetry)(samples(tr), S.replace(temperature=jnp.float32(0.01)))
    for unit in UNITS_WITH_STATE:
        name = unit.__name__.rsplit(".", 1)[-1]
        ctx, st = fold(unit, tr)
        for x, y in zip(jax.tree.leaves(getattr(tel, name)), jax.tree.leaves(st), strict=True):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6, err_msg=name)
    for x, y in zip(jax.tree.leaves(tel.context), jax.tree.leaves(ctx), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6)


# ------------------------------------------------------------------------------------------ TTC
def ttc_case(closing_speed: float = 2.0) -> dict:
    # a hazard 6 m ahead (box surfaces) closes at 2 m/s: 0.1 m per tick, present on ticks 0..4;
    # the window [t_ref, t_clear] holds ticks 0..2, so TTC_min = 5.8 m / 2 m/s = 2.9 s
    tr = quiet()
    d = 6.0 - closing_speed * DT * np.arange(5)
    tr["hazard_present"][:5] = True
    tr["hazard_box_dist"][:5] = d
    tr["hazard_rel"][:5, 0] = d + 2.0
    tr["hazard_rel_vel"][:5, 0] = -closing_speed
    tr["t_warn_point"][:], tr["t_clear"][:] = at(0), at(2)
    return tr


def ttc_min(tr) -> float:
    ctx, st = fold(ttc, tr)
    return f(ttc.hard(st, ctx, NEVER)[0])


def test_ttc_of_a_closing_hazard():
    ctx, st = fold(ttc, ttc_case())
    value, valid = ttc.hard(st, ctx, NEVER)
    assert bool(valid)
    assert f(value) == pytest.approx(2.9, abs=1e-5)
    assert f(ttc.score(value, S)) == pytest.approx(2.9 / 3.0, abs=1e-6)
    # closing at 2 m/s from 6 m, the first tick alone in the window: TTC 3 s -> S_TTC 1.0
    tr = ttc_case()
    tr["t_clear"][:] = at(0)
    assert ttc_min(tr) == pytest.approx(3.0) and f(ttc.score(ttc_min(tr), S)) == 1.0


def test_ttc_no_closing_trend_overlap_and_window():
    # moving apart at 2 m/s: no sample -> TTC inf -> S_TTC 1
    tr = ttc_case(closing_speed=-2.0)
    assert math.isinf(ttc_min(tr)) and f(ttc.score(ttc_min(tr), S)) == 1.0
    # an overlap (box distance 0) inside the window is a sample of 0 even without closing
    tr["hazard_box_dist"][1] = 0.0
    assert ttc_min(tr) == 0.0 and f(ttc.score(ttc_min(tr), S)) == 0.0
    # the same overlap before t_ref does not count
    tr["t_warn_point"][:] = at(2)
    assert math.isinf(ttc_min(tr))
    # a gate failure before t_ref makes the component unavailable
    ctx, st = fold(ttc, ttc_case())
    assert not bool(ttc.hard(st, ctx, jnp.float32(at(0) - DT))[1])


# ------------------------------------------------------------------------------------ clearance
def clearance_case() -> dict:
    # hazard present throughout; the window [t_event, t_clear] = ticks 2..6 sees
    # 3.0, 2.5, 1.5, 2.0, 2.2 -> d_min = 1.5 m -> S_clear = 1.5 / 2 = 0.75 (d_safe 2 m);
    # 0.5 m before the event and 0.2 m after clearance are outside the window
    tr = quiet()
    tr["hazard_present"][:] = True
    tr["hazard_box_dist"][:8] = [1.0, 0.5, 3.0, 2.5, 1.5, 2.0, 2.2, 0.2]
    tr["t_event"][:], tr["t_clear"][:] = at(2), at(6)
    return tr


def test_clearance_minimum_inside_the_window():
    ctx, st = fold(clearance, clearance_case())
    value, valid = clearance.hard(st, ctx, NEVER)
    assert bool(valid) and f(value) == pytest.approx(1.5)
    assert f(clearance.score(value, 2.0)) == pytest.approx(0.75)
    assert f(clearance.score(value, 3.0)) == pytest.approx(0.5)


def test_clearance_collision_counts_as_zero_and_empty_window_is_unavailable():
    tr = clearance_case()
    tr["collision"][4] = True  # a collision inside the window sets d_min = 0
    ctx, st = fold(clearance, tr)
    assert f(clearance.hard(st, ctx, NEVER)[0]) == 0.0
    tr = clearance_case()
    tr["hazard_present"][2:7] = False  # no sample in the window
    ctx, st = fold(clearance, tr)
    assert not bool(clearance.hard(st, ctx, NEVER)[1])


# --------------------------------------------------------------------------------- anticipation
def braking_case(brake_from: int, t_ref: int = 10, t_event: int = 30) -> dict:
    # cruise at 8 m/s; brake at -3 m/s^2 from tick `brake_from` on
    tr = quiet(speed=8.0)
    k = np.arange(N)
    tr["ego_accel"][k >= brake_from] = -3.0
    tr["ego_speed"] = np.where(k >= brake_from, 8.0 - 3.0 * DT * (k - brake_from + 1), 8.0)
    tr["t_warn_point"][:], tr["t_event"][:] = at(t_ref), at(t_event)
    return tr


def test_anticipation_first_sustained_response():
    # flags from tick 14: the window starting at tick 12 holds 8 flags (14..21), the one starting
    # at 11 only 7 -> t_react = t[12] = 0.65 s; S_ant = (1.55 - 0.65) / (1.55 - 0.55) = 0.9
    ctx, st = fold(anticipation, braking_case(14))
    t_react, valid = anticipation.hard(st, ctx, NEVER)
    assert bool(valid) and f(t_react) == pytest.approx(0.65, abs=1e-6)
    s = anticipation.score(ctx.t_warn_point, ctx.t_event, t_react, valid, ctx.coincident_onset)
    assert f(s) == pytest.approx(0.9, abs=1e-5)
    # no braking at all: no response -> NaN -> S_ant 0
    ctx, st = fold(anticipation, braking_case(brake_from=N))
    t_react, valid = anticipation.hard(st, ctx, NEVER)
    assert math.isnan(f(t_react)) and f(anticipation.score(at(10), at(30), t_react)) == 0.0


def test_anticipation_coincident_onset_needs_response_already_present():
    # warning and event at tick 20; braking from tick 12: the 10 ticks ending at the event tick
    # (11..20) hold 9 flags -> response present, t_react = t[11] < t_event -> S_ant 1
    tr = braking_case(12, t_ref=20, t_event=20)
    tr["coincident_onset"][:] = True
    ctx, st = fold(anticipation, tr)
    assert bool(st.response_at_event)
    t_react, valid = anticipation.hard(st, ctx, NEVER)
    assert f(t_react) == pytest.approx(at(11))
    assert f(anticipation.score(at(20), at(20), t_react, valid, True)) == 1.0
    # braking from tick 19: 2 flags at the event -> the response comes later -> S_ant 0
    tr = braking_case(19, t_ref=20, t_event=20)
    tr["coincident_onset"][:] = True
    ctx, st = fold(anticipation, tr)
    t_react, valid = anticipation.hard(st, ctx, NEVER)
    assert not bool(st.response_at_event) and f(t_react) >= at(20)
    assert f(anticipation.score(at(20), at(20), t_react, valid, True)) == 0.0


# ------------------------------------------------------------------------------------- recovery
def recovery_case(progress_frozen: bool = False) -> dict:
    # v_pre = 6 m/s at t_ref (tick 0) -> v_thr = max(2, 0.5 * 6) = 3 m/s; release at
    # max(t_warn_off = t[5], t_clear = t[10]) = 0.55 s; 1 m/s until tick 19, 4 m/s from tick 20:
    # the window 20..39 gains 19 * 4 * 0.05 = 3.8 m >= 0.5 m -> t_recover = t[20] = 1.05 s,
    # RL = 0.5 s, S_rec = 1 - 0.5 / 8 = 0.9375
    tr = quiet()
    k = np.arange(N)
    tr["ego_speed"] = np.select([k < 5, k < 20], [6.0, 1.0], 4.0)
    tr["progress"] = np.cumsum(tr["ego_speed"] * DT)
    if progress_frozen:  # speed without progress (e.g. sliding sideways): no recovery
        tr["progress"][20:] = tr["progress"][19]
    tr["t_warn_point"][:], tr["t_warn_off"][:], tr["t_clear"][:] = at(0), at(5), at(10)
    return tr


def test_recovery_latency():
    ctx, st = fold(recovery, recovery_case())
    rl, valid = recovery.hard(st, ctx, NEVER)
    assert bool(valid) and f(rl) == pytest.approx(0.5, abs=1e-6)
    assert f(recovery.score(rl, S)) == pytest.approx(0.9375, abs=1e-6)
    ctx, st = fold(recovery, recovery_case(progress_frozen=True))
    rl, valid = recovery.hard(st, ctx, NEVER)
    assert bool(valid) and math.isnan(f(rl)) and f(recovery.score(rl, S)) == 0.0


# ------------------------------------------------------------------------------------- progress
def test_progress_counts_the_end_zone_as_complete():
    # route 42 m: completion is measured against 40 m; 30 m -> 0.75, 41 m -> 1 (end zone)
    tr = quiet()
    tr["route_length"][:] = 42.0
    tr["progress"][:] = 30.0
    ctx, _ = fold(rule, tr)  # progress is stateless: any unit's fold carries the context
    assert f(progress.hard(ctx, S)[0]) == pytest.approx(0.75)
    tr["progress"][:] = 41.0
    ctx, _ = fold(rule, tr)
    assert f(progress.hard(ctx, S)[0]) == 1.0
    assert bool(progress.is_completed(ctx.progress_m, ctx.route_length_m, S))
    # the recovery's end-of-route windows use the same rule with the end zone as a value: the
    # zone's first metre counts, the metre before it does not
    lengths = jnp.full(3, 42.0)
    reached = jnp.asarray([39.9, 40.0, 41.0])
    want = [False, True, True]
    assert progress.is_completed(reached, lengths, S).tolist() == want
    assert progress.reached_end_zone(reached, lengths, S.completion_tol_m).tolist() == want


# ---------------------------------------------------------------------------------------- gates
def test_collision_gate_and_failure_time():
    tr = quiet()
    tr["collision"][7] = True
    ctx, st = fold(collision, tr)
    assert not bool(collision.hard(st, ctx, S)[0])
    assert f(collision.failure_times(st, ctx, S)[0]) == at(7)
    ctx, st = fold(collision, quiet())
    assert (
        bool(collision.hard(st, ctx, S)[0]) and f(collision.failure_times(st, ctx, S)[0]) == NEVER
    )


def test_route_deviation_gate_at_30_m():
    tr = quiet()
    tr["dist_to_route"][12] = 29.9  # below 30 m: passes
    ctx, st = fold(route_deviation, tr)
    assert bool(route_deviation.hard(st, ctx, S)[0])
    tr["dist_to_route"][12] = 30.0  # 30 m fails
    ctx, st = fold(route_deviation, tr)
    assert not bool(route_deviation.hard(st, ctx, S)[0])
    assert f(route_deviation.failure_times(st, ctx, S)[0]) == at(12)


def test_lane_gate_debounce_over_the_whole_execution():
    # 10 + 9 ticks outside = 0.95 s in total: passes; one more tick (tick 40) makes 1 s: fails there
    tr = quiet()
    tr["outside_lanes"][5:15] = True
    tr["outside_lanes"][30:39] = True
    ctx, st = fold(lane, tr)
    assert bool(lane.hard(st, ctx, S)[0]) and f(lane.outside_s(st)) == pytest.approx(0.95)
    tr["outside_lanes"][40] = True
    ctx, st = fold(lane, tr)
    assert not bool(lane.hard(st, ctx, S)[0])
    assert f(lane.failure_times(st, ctx, S)[0]) == at(40)


def test_rule_gate():
    tr = quiet()
    tr["red_light_violation"][3] = True
    ctx, st = fold(rule, tr)
    assert not bool(rule.hard(st, ctx, S)[0]) and f(rule.failure_times(st, ctx, S)[0]) == at(3)


def test_block_gate_stall_timeout_and_fault():
    # 400 still ticks (20 s) with the route unfinished: stalled at the 400th (tick 409)
    n = 420
    tr = quiet(n=n)
    tr["ego_speed"][10:410] = 0.0
    ctx, st = fold(block, tr)
    assert bool(block.stalled(st, S)) and f(block.max_still_s(st)) == pytest.approx(20.0)
    t_stall, t_fault, t_timeout = block.failure_times(st, ctx, S)
    assert f(t_stall) == at(409) and f(t_fault) == NEVER and f(t_timeout) == at(n - 1)
    tr["ego_speed"][409] = 5.0  # 399 ticks: no stall (the route is still unfinished: timeout)
    ctx, st = fold(block, tr)
    assert not bool(block.stalled(st, S)) and not bool(block.hard(st, ctx, S)[0])
    # standing at the route's end zone is no stall, and a completed route passes
    tr["ego_speed"][409] = 0.0
    tr["route_length"][:] = tr["progress"][-1] + 1.0
    tr["progress"][:] = tr["progress"][-1]
    ctx, st = fold(block, tr)
    assert not bool(block.stalled(st, S)) and bool(block.hard(st, ctx, S)[0])
    tr["controller_fault"][7] = True  # a controller fault fails the gate at its tick
    ctx, st = fold(block, tr)
    assert not bool(block.hard(st, ctx, S)[0]) and f(block.failure_times(st, ctx, S)[1]) == at(7)


def stop_case(first: int, last: int) -> dict:
    # Route B: the ego's progress lies in the matched stretch on ticks 5..45 (fb_window);
    # stopped (0.05 m/s) on first..last
    tr = quiet()
    tr["is_route_a"][:] = False
    tr["ego_speed"][first : last + 1] = 0.05
    tr["fb_window"][5:46] = True
    tr["t_warn_point"][:], tr["t_event"][:] = at(5), at(45)
    return tr


@pytest.mark.parametrize(
    "first, last, justified, passed",
    [
        (10, 28, False, True),  # 19 ticks = 0.95 s: passes
        (10, 30, False, False),  # 21 ticks inside the window: fails
        (10, 30, True, True),  # the same stop, justified (light, lead vehicle, ...): passes
        (46, 59, False, True),  # beyond the matched stretch
        (0, 24, False, False),  # began before the stretch; 20 ticks (5..24) inside: fails
        (0, 16, False, True),  # 17 ticks in all (12 inside): passes
        (0, 19, False, False),  # 20 ticks in all, only 15 inside: the whole stop counts, fails
        (40, 59, False, False),  # began inside, lasts 20 ticks (15 beyond the stretch): fails
        (0, 4, False, True),  # ends before the stretch: passes
    ],
)
def test_false_brake_gate(first, last, justified, passed):
    tr = stop_case(first, last)
    tr["justified_stop"][first : last + 1] = justified
    ctx, st = fold(false_brake, tr)
    assert bool(false_brake.hard(st, ctx, S)[0]) == passed


# ----------------------------------------------------------------------- soft -> hard as T -> 0
def _gate_case(unit):
    """A smooth example per gate: margins well away from the switching point."""
    tr = quiet()
    if unit is collision:  # hazard passes within 1 m at 5 m/s: margin 1 m -> passes
        tr["hazard_present"][:] = True
        tr["hazard_box_dist"][:] = np.abs(np.linspace(-4.0, 4.0, N)) + 1.0
    elif unit is route_deviation:  # up to 29.5 m from the route: passes, margin 0.5 m
        tr["dist_to_route"][:] = np.linspace(0.0, 29.5, N)
    elif unit is lane:  # 30 ticks outside: fails, margin -0.525 s
        tr["outside_lanes"][10:40] = True
    elif unit is rule:
        tr["red_light_violation"][20] = True
    elif unit is block:  # route completed 1 m inside the end zone, no standstill: passes
        tr["route_length"][:] = tr["progress"][-1] + 1.0
    elif unit is false_brake:  # 10-tick stop in the matched interval: passes, margin 0.475 s
        tr = stop_case(10, 19)
    return tr


def _hard_and_soft(name: str, temperature: float) -> tuple[float, float]:
    """``(hard score, soft value)`` of one unit on its smooth example."""
    temp = jnp.float32(temperature)
    if name == "ttc":
        ctx, st = fold(ttc, ttc_case(), temperature)
        return f(ttc.score(ttc.hard(st, ctx, NEVER)[0], S)), f(ttc.soft(st, ctx, NEVER, temp, S)[0])
    if name == "clearance":
        ctx, st = fold(clearance, clearance_case(), temperature)
        d_safe = jnp.float32(2.0)
        hard = clearance.score(clearance.hard(st, ctx, NEVER)[0], d_safe)
        return f(hard), f(clearance.soft(st, ctx, NEVER, temp, S, d_safe)[0])
    if name == "anticipation":
        ctx, st = fold(anticipation, braking_case(14), temperature)
        t_react, valid = anticipation.hard(st, ctx, NEVER)
        hard = anticipation.score(ctx.t_warn_point, ctx.t_event, t_react, valid, False)
        return f(hard), f(anticipation.soft(st, ctx, NEVER, temp, S)[0])
    if name == "recovery":
        ctx, st = fold(recovery, recovery_case(), temperature)
        hard = recovery.score(recovery.hard(st, ctx, NEVER)[0], S)
        return f(hard), f(recovery.soft(st, ctx, NEVER, temp, S)[0])
    if name == "progress":
        tr = quiet()
        tr["route_length"][:] = 402.0  # 0.6 of 400 m
        tr["progress"][:] = 240.0
        ctx, _ = fold(rule, tr, temperature)
        return f(progress.hard(ctx, S)[0]), f(progress.soft(ctx, temp, S)[0])
    unit = globals()[name]
    ctx, st = fold(unit, _gate_case(unit), temperature)
    return float(bool(unit.hard(st, ctx, S)[0])), f(unit.soft(st, ctx, temp, S)[0])


UNITS = ("ttc", "clearance", "anticipation", "recovery", "progress", "collision",
         "route_deviation", "lane", "rule", "block", "false_brake")  # fmt: skip


@pytest.mark.parametrize("name", UNITS)
def test_soft_tends_to_hard(name):
    hard_values, errors = set(), []
    for temperature in (0.1, 0.01, 0.001):
        hard, soft = _hard_and_soft(name, temperature)
        assert 0.0 <= soft <= 1.0 + 1e-6
        hard_values.add(hard)
        errors.append(abs(soft - hard))
    assert len(hard_values) == 1  # the hard value does not depend on the temperature
    assert errors[2] <= errors[1] + 1e-6 and errors[1] <= errors[0] + 1e-6, errors
    assert errors[2] < 5e-3, errors


#: The parameters of each function a role provides (the module docstring of
#: ``lantern_jax.scoring.components``): one signature per function of a role.
ROLE_CONTRACT = {
    "hazard": {"valid": ("state", "ctx", "t_fail"), "hard": ("state", "ctx", "t_fail"),
               "soft": ("state", "ctx", "t_fail", "temperature", "settings", "d_safe"),
               "score_of": ("metrics", "d_safe", "settings")},
    "route_a_gate": {"failure_times": ("state", "ctx", "settings"),
                     "hard": ("state", "ctx", "settings"),
                     "soft": ("state", "ctx", "temperature", "settings")},
    "route_b_gate": {"hard": ("state", "ctx", "settings"),
                     "soft": ("state", "ctx", "temperature", "settings")},
    "diagnostic": {},
}  # fmt: skip


def test_every_component_of_the_table_keeps_its_role_s_contract_and_its_telemetry_field():
    """One table (``COMPONENTS``): the telemetry's fields are its entries in order (between the
    shared context and the user metrics), and every module has the functions of its role with
    the role's parameters."""
    import dataclasses
    import inspect

    from lantern_jax.scoring.components import COMPONENTS, ROLES
    from lantern_jax.scoring.telemetry import Telemetry

    fields = [f.name for f in dataclasses.fields(Telemetry)]
    assert fields == ["context", *(c.field for c in COMPONENTS), "metrics"]
    assert {c.role for c in COMPONENTS} == set(ROLES)
    for c in COMPONENTS:
        assert c.module.__name__.rsplit(".", 1)[1] == c.field
        wanted = {"init": ("settings",), "update": ("state", "sample", "tick", "settings"),
                  "outputs": ("state", "ctx", "t_fail", "settings"),
                  **ROLE_CONTRACT[c.role]}  # fmt: skip
        for name, params in wanted.items():
            got = tuple(inspect.signature(getattr(c.module, name)).parameters)
            assert got == params, (c.field, name, got)
        assert isinstance(c.module.COLUMNS, dict), c.field
        if c.role == "hazard":
            assert callable(c.module.score) and c.module.SCORE.startswith("S_")


def test_the_route_table_s_measured_columns_come_from_the_component_table():
    """Each measured column of the route table is declared once, by the context or by the
    component giving its field (``COLUMNS``), or is a pair component (each hazard term's
    ``SCORE``, the gates, ``CUS``); with the table's own argument columns they are the schema's
    columns. The hazard scores of the table are each term's ``score_of`` of its row."""
    from lantern_jax.core.constants import GATE_COLUMNS
    from lantern_jax.scoring import table
    from lantern_jax.scoring.components import COMPONENTS, HAZARD_COMPONENTS
    from lantern_jax.scoring.metrics import FIELD_OWNERS, ROUTE_COLUMNS

    schema = [c for c, _ in table.schema_columns()]
    assert sorted(schema) == sorted([*table.ARGUMENT_COLUMNS, *table.MEASURED_COLUMNS])
    for c in COMPONENTS:
        for name, (route, field) in c.module.COLUMNS.items():
            assert ROUTE_COLUMNS[name] == (route, field) and FIELD_OWNERS[field] == c.field
    pair = {k for s, k in table.MEASURED_COLUMNS.values() if s == "pair"}
    assert pair == {*(m.SCORE for m in HAZARD_COMPONENTS.values()), *GATE_COLUMNS, "CUS"}
    # the scores in a table built from hand-made metrics are score_of of the rows
    tr = braking_case(14)
    one = _finalized(tr)
    df = table.build_route_table(one, one, model="m", condition="warning", pair_ids=["p"],
                                 families=["PE"], weathers=["clear"], d_safe=[2.0])  # fmt: skip
    for m in HAZARD_COMPONENTS.values():
        want = float(m.score_of(one, jnp.float32(2.0), S)[0])
        got = float(df[m.SCORE].iloc[0])
        assert (np.isnan(want) and np.isnan(got)) or abs(want - got) < 1e-6, m.SCORE
    assert float(df["S_ant"].iloc[0]) == pytest.approx(0.9, abs=1e-5)  # as derived above
    assert float(df["t_react_s"].iloc[0]) == pytest.approx(0.65, abs=1e-6)
    assert df["B_time_s"].isna().all() and (df["no_collision"] == 1).all()


def _finalized(tr):
    """The per-execution metrics of ``tr`` folded through the whole telemetry, batch of one."""
    from lantern_jax.scoring.metrics import finalize
    from lantern_jax.scoring.telemetry import fold_telemetry

    tel = jax.jit(fold_telemetry)(samples(tr), S.replace(temperature=jnp.float32(0.01)))
    return jax.tree.map(lambda x: np.asarray(x)[None], finalize(tel, S))


def test_a_column_declared_twice_or_missing_from_the_schema_is_refused(monkeypatch):
    """The import-time checks name the column: one declared by two owners, one the schema does
    not hold."""
    from lantern_jax.scoring import metrics, table
    from lantern_jax.scoring.components import efficiency

    own = dict(efficiency.COLUMNS)
    monkeypatch.setattr(efficiency, "COLUMNS", {**own, "t_ref_s": ("A", "t_ref_s")})
    with pytest.raises(AssertionError, match="t_ref_s"):
        metrics._route_columns()
    monkeypatch.setattr(efficiency, "COLUMNS", {**own, "B_new_s": ("B", "slow_unjustified_s")})
    monkeypatch.setattr(table, "ROUTE_COLUMNS", metrics._route_columns())
    with pytest.raises(AssertionError, match="B_new_s"):
        table._measured_column_sources()
    monkeypatch.setattr(efficiency, "COLUMNS", {"B_bad_s": ("B", "t_ref_s")})
    with pytest.raises(AssertionError, match="B_bad_s"):
        metrics._route_columns()


def test_each_component_gives_the_metrics_fields_its_outputs_declare():
    """``finalize`` folds the table's ``outputs``: each gives exactly the fields its module's
    ``OUTPUTS`` names, with the dtype the metrics hold, and every field of ``ExecutionMetrics``
    has one owner (the shared context or one component)."""
    import dataclasses

    from lantern_jax.scoring.components import COMPONENTS
    from lantern_jax.scoring.metrics import CONTEXT_FIELDS, FIELD_OWNERS, ExecutionMetrics

    tr = braking_case(14)
    for c in COMPONENTS:
        ctx, state = fold(c.module, tr)
        got = c.module.outputs(state, ctx, jnp.float32(NEVER), S)
        assert tuple(got) == c.module.OUTPUTS, c.field
        assert all(np.ndim(v) == 0 for v in got.values()), c.field
        assert all(FIELD_OWNERS[k] == c.field for k in got), c.field
    fields = {f.name for f in dataclasses.fields(ExecutionMetrics)}
    assert set(FIELD_OWNERS) == fields
    assert {k for k, o in FIELD_OWNERS.items() if o == "context"} == set(CONTEXT_FIELDS)
