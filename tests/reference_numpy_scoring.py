"""Slow NumPy reference for the CUS telemetry, plus synthetic trajectories for the scoring tests.

The reference works on a recorded trajectory (one array per ``TickSample`` field, leading axis =
time) and evaluates every definition directly with loops over explicit windows, independently of
the running accumulators in :mod:`lantern_jax.scoring.telemetry`.
"""

from __future__ import annotations

import math

import numpy as np

from lantern_jax.core.constants import DT, INF_TIME

FIELDS = (
    "t", "ego_speed", "ego_accel", "progress", "route_length", "dist_to_route", "outside_lanes",
    "red_light_violation", "collision", "hazard_present", "hazard_rel", "hazard_rel_vel",
    "hazard_box_dist", "justified_stop", "fb_window", "controller_fault", "t_warn_point", "t_event",
    "t_warn_off", "t_clear", "is_route_a", "coincident_onset",
)  # fmt: skip
BOOL_FIELDS = (
    "outside_lanes", "red_light_violation", "collision", "hazard_present", "justified_stop",
    "fb_window", "controller_fault", "is_route_a", "coincident_onset", "slow_unjustified",
)  # fmt: skip

EGO_HALF_LENGTH, EGO_HALF_WIDTH, PED_HALF = 2.45, 1.06, 0.3


# ---------------------------------------------------------------------------------------------
# synthetic trajectories
# ---------------------------------------------------------------------------------------------
def make_trajectory(
    n: int = 320,
    v0: float = 8.0,
    x_warn: float = 30.0,
    event_delay: float = 2.0,
    coincident: bool = False,
    brake_offset: float = 0.05,
    brake_decel: float = 3.0,
    brake_dur: float = 1.5,
    resume_offset: float = 9.0,
    resume_accel: float = 2.0,
    hazard_ahead: float = 45.0,
    hazard_speed: float = 1.5,
    warn_off_delay: float = 0.5,
    route_a: bool = True,
    route_extra: float = -5.0,
    speed_scale: float = 1.0,
    accel_noise: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """A straight-road execution: the ego cruises at ``v0``, brakes ``brake_offset`` s after
    reaching the warning point (``x_warn``), holds, and accelerates back from ``resume_offset`` s
    after it.  A pedestrian ``hazard_ahead`` m past the warning point starts 6 m to the right at
    the event and crosses at ``hazard_speed``; it clears (and despawns) 4 m to the left.
    ``route_length = final position + route_extra``.  All times lie on the 20 Hz grid.  The
    Route B false-brake stretch is ``[x_warn, x_warn + v0 * event_delay]`` (where the cruising
    ego is at the event), or ``[x_warn - 10, x_warn + hazard_ahead]`` with coincident onset.
    """
    t = (np.arange(n) + 1) * DT
    # cruise until the warning point, to find k_wp
    x_cruise = np.cumsum(np.full(n, v0 * DT))
    k_wp = int(np.argmax(x_cruise >= x_warn))
    t_wp = t[k_wp]
    k_ev = k_wp if coincident else k_wp + int(round(event_delay / DT))
    accel_cmd = np.zeros(n)
    for k in range(n):
        rel = t[k] - t_wp
        if brake_offset <= rel < brake_offset + brake_dur:
            accel_cmd[k] = -brake_decel
        elif rel >= resume_offset:
            accel_cmd[k] = resume_accel
    if accel_noise is not None:
        accel_cmd = accel_cmd + accel_noise
    v = np.zeros(n)
    a = np.zeros(n)
    prev = v0
    for k in range(n):
        if accel_cmd[k] > 0:
            cur = max(min(prev + accel_cmd[k] * DT, v0), prev)
        else:
            cur = max(prev + accel_cmd[k] * DT, 0.0)
        a[k] = (cur - prev) / DT
        v[k] = cur
        prev = cur
    v = v * speed_scale
    a = a * speed_scale
    x = np.cumsum(v * DT)
    route_length = x[-1] + route_extra
    progress = np.minimum(x, route_length)

    # hazard
    x_h = x_warn + hazard_ahead
    y_h = np.where(np.arange(n) >= k_ev, -6.0 + hazard_speed * (t - t[k_ev]), -6.0)
    vy_h = np.where(np.arange(n) >= k_ev, hazard_speed, 0.0)
    cleared = y_h >= 4.0
    k_cl = int(np.argmax(cleared)) if cleared.any() else None
    present = np.full(n, route_a) & ~cleared
    dx = np.maximum(np.abs(x_h - x) - EGO_HALF_LENGTH - PED_HALF, 0.0)
    dy = np.maximum(np.abs(y_h) - EGO_HALF_WIDTH - PED_HALF, 0.0)
    box = np.hypot(dx, dy)
    rel = np.stack([x_h - x, y_h], -1)
    rel_vel = np.stack([-v, vy_h], -1)
    collision = present & (box <= 0.0) & (v >= 0.1)

    def marker(k: int | None) -> np.ndarray:
        if k is None or k >= n:
            return np.full(n, INF_TIME)
        return np.where(np.arange(n) >= k, t[k], INF_TIME)

    k_off = k_ev + int(round(warn_off_delay / DT))
    fb_lo, fb_hi = (x_warn - 10.0, x_h) if coincident else (x_warn, x_warn + v0 * event_delay)
    tr = {
        "t": t,
        "ego_speed": v,
        "ego_accel": a,
        "progress": progress,
        "route_length": np.full(n, route_length),
        "dist_to_route": np.full(n, 0.3),
        "outside_lanes": np.zeros(n, bool),
        "red_light_violation": np.zeros(n, bool),
        "collision": collision,
        "hazard_present": present,
        "hazard_rel": rel,
        "hazard_rel_vel": rel_vel,
        "hazard_box_dist": np.where(present, box, 1.0e6),
        "justified_stop": np.zeros(n, bool),
        "slow_unjustified": slow_unjustified(v, np.zeros(n, bool), v0),
        "fb_window": (progress >= fb_lo) & (progress <= fb_hi),
        "controller_fault": np.zeros(n, bool),
        "t_warn_point": marker(k_wp),
        "t_event": marker(k_ev),
        "t_warn_off": marker(k_off) if route_a else np.full(n, INF_TIME),
        "t_clear": marker(k_cl) if route_a else np.full(n, INF_TIME),
        "is_route_a": np.full(n, route_a),
        "coincident_onset": np.full(n, coincident),
    }
    return as_float32(tr)


def slow_unjustified(speed: np.ndarray, justified: np.ndarray, v_ref: float) -> np.ndarray:
    """(n,) bool, the measurement's slow flag: below half the reference speed, unjustified."""
    return (np.asarray(speed) < 0.5 * v_ref) & ~np.asarray(justified, bool)


def as_float32(tr: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Cast to the dtypes of ``TickSample`` (float32 / bool)."""
    return {
        k: np.asarray(v, bool) if k in BOOL_FIELDS else np.asarray(v, np.float32)
        for k, v in tr.items()
    }


def random_trajectory(seed: int, route_a: bool = True) -> dict[str, np.ndarray]:
    """A randomized execution exercising windows, rings, gates and the missing-value rules."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(260, 420))
    v0 = float(rng.uniform(5.0, 10.0))
    tr = make_trajectory(
        n=n,
        v0=v0,
        x_warn=float(rng.uniform(15.0, 40.0)),
        event_delay=float(rng.choice([1.0, 1.5, 2.0])),
        coincident=bool(rng.random() < 0.3),
        brake_offset=float(rng.choice([-0.5, 0.0, 0.05, 0.3, 1.0, 2.5])),
        brake_decel=float(rng.uniform(0.3, 5.0)),
        brake_dur=float(rng.uniform(0.3, 3.0)),
        resume_offset=float(rng.uniform(3.0, 8.0)),
        resume_accel=float(rng.uniform(0.5, 3.0)),
        hazard_ahead=float(rng.uniform(30.0, 70.0)),
        hazard_speed=float(rng.uniform(0.8, 3.0)),
        warn_off_delay=float(rng.choice([0.0, 0.5, 1.0, 6.0])),
        route_a=route_a,
        route_extra=float(rng.choice([-5.0, -5.0, 1.0, 10.0])),
        accel_noise=rng.normal(0.0, 0.4, n) * (rng.random(n) < 0.3),
    )
    for name, p in (("outside_lanes", 0.003), ("justified_stop", 0.01)):
        bursts = rng.random(n) < p
        tr[name] = np.convolve(bursts, np.ones(int(rng.integers(1, 12))), "same") > 0
    if rng.random() < 0.1:
        tr["dist_to_route"][int(rng.integers(0, n))] = 31.0
    if rng.random() < 0.1:
        tr["red_light_violation"][int(rng.integers(0, n))] = True
    if rng.random() < 0.1:
        tr["collision"][int(rng.integers(0, n))] = True
    if rng.random() < 0.1:
        tr["controller_fault"][int(rng.integers(0, n))] = True
    if rng.random() < 0.4:  # a stop inside the warning-to-event interval (false brake probe)
        k = int(np.argmax(tr["t_warn_point"] < 0.5 * INF_TIME))
        m = int(rng.integers(5, 40))
        tr["ego_speed"][k : k + m] = 0.05
    tr["slow_unjustified"] = slow_unjustified(tr["ego_speed"], tr["justified_stop"], v0)
    return tr


# ---------------------------------------------------------------------------------------------
# reference scoring
# ---------------------------------------------------------------------------------------------
def _hap(x: float) -> bool:
    return x < 0.5 * INF_TIME


def _first_window(ok: np.ndarray, width: int) -> int | None:
    """First k0 such that ok[k0:k0+width] are all True."""
    for k0 in range(len(ok) - width + 1):
        if ok[k0 : k0 + width].all():
            return k0
    return None


def reference_execution(tr: dict[str, np.ndarray]) -> dict[str, float]:
    """Every per-execution output by plain loops over the recorded trajectory (float64)."""
    g = {
        k: np.asarray(v, np.float64) if k not in BOOL_FIELDS else np.asarray(v)
        for k, v in tr.items()
    }
    t, v, acc = g["t"], g["ego_speed"], g["ego_accel"]
    n = len(t)
    tref, tev, toff, tcl = g["t_warn_point"], g["t_event"], g["t_warn_off"], g["t_clear"]
    present = g["hazard_present"]
    box = np.maximum(g["hazard_box_dist"], 0.0)
    post_ref = np.array([_hap(tref[k]) and t[k] >= tref[k] for k in range(n)])
    post_ev = np.array([_hap(tev[k]) and t[k] >= tev[k] for k in range(n)])

    # TTC
    ttc, ttc_any = math.inf, False
    for k in range(n):
        if not (post_ref[k] and t[k] <= tcl[k] and present[k]):
            continue
        r, rv = g["hazard_rel"][k], g["hazard_rel_vel"][k]
        nr = float(np.hypot(*r))
        vc = -float(r @ rv) / nr if nr > 1e-6 else 0.0
        if box[k] <= 0.0:
            x = 0.0
        elif vc > 0.05:
            x = box[k] / vc
        else:
            continue
        ttc, ttc_any = min(ttc, x), True

    # clearance
    clear, clear_any = math.inf, False
    for k in range(n):
        if post_ev[k] and t[k] <= tcl[k] and (present[k] or g["collision"][k]):
            clear = min(clear, 0.0 if g["collision"][k] else box[k])
            clear_any = True

    # reaction: v_pre = the speed on the last tick before t_ref (the first tick's own speed
    # when t_ref precedes every tick)
    k_pre = int(np.argmax(post_ref)) if post_ref.any() else None
    v_pre = v[max(k_pre - 1, 0)] if k_pre is not None else 0.0
    flags = post_ref & ((acc <= -0.5) | (v <= v_pre - 1.0))
    t_react = math.inf
    for k0 in range(n - 9):
        w = slice(k0, k0 + 10)
        if post_ref[w].all() and flags[w].sum() >= 8:
            t_react = t[k0]
            break
    present_at_event, t_resp = False, math.inf
    if post_ev.any():
        ke = int(np.argmax(post_ev))
        if ke >= 9:
            w = slice(ke - 9, ke + 1)
            f = (acc[w] <= -0.5) | (v[w] <= v[ke - 9] - 1.0)
            if f.sum() >= 8:
                present_at_event, t_resp = True, t[ke - 9]
    coincident = bool(g["coincident_onset"].any())
    if coincident and present_at_event:
        t_react = t_resp

    # recovery
    rel = np.array(
        [max(toff[k], tcl[k]) if _hap(toff[k]) and _hap(tcl[k]) else INF_TIME for k in range(n)]
    )
    thr = max(2.0, 0.5 * v_pre)
    ok = np.array([_hap(rel[k]) and t[k] >= rel[k] and v[k] > thr for k in range(n)])
    t_recover = math.inf
    prog = g["progress"]
    for k0 in range(n - 19):
        if ok[k0 : k0 + 20].all() and prog[k0 + 19] - prog[k0] >= 0.5:
            t_recover = t[k0]
            break
    if math.isinf(t_recover) and prog[-1] >= g["route_length"][-1] - 2.0:
        # the route completed: the windows cut short by the execution's end, earliest first
        e = n - 1
        for k0 in range(max(e - 18, 0), e + 1):
            if ok[k0:].all() and prog[e] - prog[k0] >= 0.5:
                t_recover = t[k0]
                break
    t_release = rel[-1]

    # gates
    def first(mask: np.ndarray) -> float:
        return float(t[int(np.argmax(mask))]) if mask.any() else INF_TIME

    L = g["route_length"]
    completed_k = prog >= L - 2.0
    completed = bool(completed_k[-1])
    t_coll = first(g["collision"])
    t_road = first(g["dist_to_route"] >= 30.0)
    t_lane = first(np.cumsum(g["outside_lanes"]) >= 20)
    t_rule = first(g["red_light_violation"])
    still = (v < 0.1) & ~completed_k
    k_stall = _first_window(still, 400)
    t_stall = t[k_stall + 399] if k_stall is not None else INF_TIME
    t_fault = first(g["controller_fault"])
    # false brake: a maximal run of unjustified stopped ticks of >= 20 ticks touching the stretch
    stop = (v <= 0.1) & ~g["justified_stop"]
    fb_fail, k = False, 0
    while k < n:
        if not stop[k]:
            k += 1
            continue
        k_end = k
        while k_end + 1 < n and stop[k_end + 1]:
            k_end += 1
        # a run counts up to each tick once it has touched the stretch
        touched = np.flatnonzero(g["fb_window"][k : k_end + 1])
        if len(touched) and k_end - k + 1 >= 20:
            fb_fail = True
        k = k_end + 1
    t_fail = min(t_coll, t_road, t_lane, t_rule, t_stall, t_fault, INF_TIME if completed else t[-1])

    ref_ok = _hap(tref[-1]) and tref[-1] <= t_fail
    ttc_av = ref_ok
    clear_av = _hap(tev[-1]) and tev[-1] <= t_fail and clear_any
    ant_av = ref_ok and _hap(tev[-1])
    rec_av = _hap(t_release) and t_release <= t_fail
    nan = math.nan

    def tt(x: float) -> float:
        return x if _hap(x) and math.isfinite(x) else nan

    return {
        # Completion counts against the end zone: route_length - 2 m (COMPLETION_TOL_M).
        "progress": min(max(prog[-1] / (L[-1] - 2.0), 0.0), 1.0),
        "ttc_min_s": (ttc if ttc_any else math.inf) if ttc_av else nan,
        "clearance_min_m": clear if clear_av else nan,
        "t_ref_s": tt(tref[-1]),
        "t_event_s": tt(tev[-1]),
        "t_warn_off_s": tt(toff[-1]),
        "t_clear_s": tt(tcl[-1]),
        "t_react_s": tt(t_react) if ant_av else nan,
        "recovery_latency_s": (t_recover - t_release)
        if rec_av and math.isfinite(t_recover)
        else nan,
        "coincident_onset": coincident,
        "anticipation_available": ant_av,
        "recovery_available": rec_av,
        "gate_collision": not _hap(t_coll),
        "gate_route_deviation": not _hap(t_road),
        "gate_lane": not _hap(t_lane),
        "gate_rule": not _hap(t_rule),
        "gate_block": completed and not _hap(t_stall) and not _hap(t_fault),
        "gate_false_brake": not fb_fail,
        "controller_fault": _hap(t_fault),
        "t_first_failure_s": tt(t_fail),
        "t_complete_s": float(t[int(np.argmax(completed_k))]) if completed_k.any() else nan,
        "slow_unjustified_s": float(np.sum(g["slow_unjustified"])) * DT,
    }


def reference_cus(ra: dict, rb: dict, d_safe: float) -> dict[str, float]:
    """Components and CUS of a pair from two :func:`reference_execution` outputs."""
    nan = math.nan
    s_ttc = nan if math.isnan(ra["ttc_min_s"]) else min(max(ra["ttc_min_s"] / 3.0, 0.0), 1.0)
    s_clear = (
        nan
        if math.isnan(ra["clearance_min_m"])
        else min(max(ra["clearance_min_m"] / d_safe, 0.0), 1.0)
    )
    if not ra["anticipation_available"]:
        s_ant = nan
    elif math.isnan(ra["t_react_s"]):
        s_ant = 0.0
    elif ra["coincident_onset"]:
        s_ant = 1.0 if ra["t_react_s"] < ra["t_event_s"] else 0.0
    else:
        span = ra["t_event_s"] - ra["t_ref_s"]
        s_ant = min(max((ra["t_event_s"] - ra["t_react_s"]) / span, 0.0), 1.0)
    if not ra["recovery_available"]:
        s_rec = nan
    elif math.isnan(ra["recovery_latency_s"]):
        s_rec = 0.0
    else:
        s_rec = min(max(1.0 - ra["recovery_latency_s"] / 8.0, 0.0), 1.0)
    z = lambda x: 0.0 if math.isnan(x) else x  # noqa: E731
    gates = all(ra[k] for k in ("gate_collision", "gate_route_deviation", "gate_lane",
                                "gate_rule", "gate_block")) and rb["gate_false_brake"]  # fmt: skip
    q_a = (
        0.40 * ra["progress"]
        + 0.35 * (z(s_ttc) + z(s_clear)) / 2
        + 0.25 * (z(s_ant) + z(s_rec)) / 2
    )
    cus = 100.0 * float(gates) * (0.85 * q_a + 0.15 * rb["progress"])
    return {"S_ttc": s_ttc, "S_clear": s_clear, "S_ant": s_ant, "S_rec": s_rec, "CUS": cus}
