"""Running telemetry accumulators of ONE execution, folded tick by tick inside ``lax.scan``.

Implements the measurement side of the paper appendix "Complete Cooperative Unified Score"
(TTC, clearance, anticipation, recovery, hard gates, Route B false brake).  No trajectory is
stored: every quantity is a running minimum, a first-crossing time, a counter or a short ring
buffer of the last few ticks.  :func:`lantern_jax.scoring.metrics.finalize` turns the final
:class:`Telemetry` into per-execution outputs.

Conventions
-----------
* Times are seconds from execution start; a protocol time or first-crossing time that has not
  happened is ``INF_TIME``.  ``sample.t`` is the time stamp of the tick, and a window "starts" at
  the time stamp of its first tick.
* Durations on the tick grid are counted in ticks (``duration = ticks * DT``): the reaction
  window is 10 ticks (0.5 s), the recovery window 20 ticks (1 s), the lane debounce 20 ticks
  (1 s in total), the Route B false brake 20 consecutive ticks (1 s), blocking 400 consecutive
  ticks (20 s).
* Window membership uses the protocol times of the current sample: ``t_ref <= t <= t_clear`` for
  TTC, ``t_event <= t <= t_clear`` for clearance, ``t_ref <= t <= t_event`` for the false brake.

Definitions (hard)
------------------
* TTC: ``v_close = -r.(v_hazard - v_ego) / |r|``; a tick of the TTC window with the hazard present
  is a sample if the boxes overlap (TTC 0) or ``v_close > 0.05 m/s`` (TTC = box distance /
  ``v_close``).  Running minimum plus an "any sample" flag.
* Clearance: minimum box distance over the clearance window while the hazard is present; a
  collision tick inside the window is a sample of 0.
* Reaction: ``v_pre`` is the ego speed at the first tick with ``t >= t_ref``.  Every tick at/after
  ``t_ref`` gets a flag ``accel <= -0.5 m/s^2 or speed <= v_pre - 1 m/s``; ``t_react`` is the start
  of the first 10-tick window, all of whose ticks lie at/after ``t_ref``, with >= 8 flags set
  (any time, also after the event; the score clips it).
* Coincident onset (RTY, no pre-warning interval): at the first tick with ``t >= t_event`` the last
  10 ticks (ending at that tick, regardless of ``t_ref``) are examined with flags
  ``accel <= -0.5 or speed <= v_start - 1`` where ``v_start`` is the speed on the window's first
  tick; ``response_at_event`` records whether >= 8 are set (False with fewer than 10 ticks so
  far) and ``t_response_start`` the window's start.  This check runs on every execution; it is
  used where ``coincident_onset`` is set.
* Recovery: ``t_release = max(t_warn_off, t_clear)`` once both happened, threshold
  ``max(2 m/s, 0.5 v_pre)``; ``t_recover`` is the start of the first 20-tick window whose ticks all
  lie at/after ``t_release`` with speed above the threshold and whose progress gain (last tick
  minus first tick of the window) is >= 0.5 m.
* Gates: collision on any tick; route deviation when ``dist_to_route >= 30 m`` on any tick; lane
  when the total time outside the driving lanes reaches 1 s (a debounce over the whole execution,
  not necessarily contiguous); rule on any red-light violation; block on a standstill
  (``speed < 0.1 m/s``, counted only while the route is unfinished) lasting 400 consecutive ticks
  (20 s), on an unfinished route at the end (``progress < route_length - 2 m``: timeout), or on any
  controller fault; false brake (Route B) when ``speed <= 0.1 m/s`` without ``justified_stop`` on
  20 consecutive ticks inside ``[t_ref, t_event]``.

Soft accumulators (for the differentiable score) are updated with the ``temperature`` given to
:func:`update_telemetry` (stored in ``Telemetry.temperature``):

* TTC and clearance: weighted log-sum-exp soft minima (:func:`~lantern_jax.scoring.smooth.lse_add`);
  a TTC sample is weighted by ``sigmoid((v_close - 0.05) / T)`` instead of the hard inclusion test.
* Reaction and recovery: a soft first crossing.  Each complete window gets a soft pass
  probability ``sigma_k`` (reaction: ``sigmoid((sum of soft flags - 7.5) / T)`` with soft flags
  ``1 - (1 - sigmoid((-0.5 - a) / T)) (1 - sigmoid((v_pre - 1 - v) / T))``; recovery: the
  product of ``sigmoid((v - v_thr) / T)`` over the window times
  ``sigmoid((progress gain - 0.5) / T)``).  The probability that window ``k`` is the first passing
  one is ``p_k = sigma_k prod_{j<k} (1 - sigma_j)``; the accumulators hold ``sum p_k`` and
  ``sum p_k t_k``, from which the score uses the expected first-crossing time.
* Gates: signed margins (closest approach for collisions, largest route distance, counters).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from lantern_jax.constants import BIG, INF_TIME
from lantern_jax.scoring import thresholds as th
from lantern_jax.scoring.sample import TickSample
from lantern_jax.scoring.smooth import LSE_EMPTY, lse_add

Array = jax.Array

RING = max(th.REACT_WINDOW, th.RECOVER_WINDOW)  # length of the shared time / progress rings
_COUNT_CAP = 2**30  # saturation of tick counters


@struct.dataclass
class Telemetry:
    """Running accumulators of one execution (all scalars unless a shape is given)."""

    # --- bookkeeping ---
    n_ticks: Array  # () int32, ticks folded so far
    t_last: Array  # () float32, s, time stamp of the last folded tick (0 before any)
    temperature: Array  # () float32, temperature the soft accumulators were built with
    is_route_a: Array  # () bool
    coincident_onset: Array  # () bool, warning and event points coincide (seen on any tick)
    # --- protocol times (latest sample; INF_TIME = not happened) ---
    t_warn_point: Array  # () float32, s, t_ref
    t_event: Array  # () float32, s
    t_warn_off: Array  # () float32, s
    t_clear: Array  # () float32, s
    # --- progress ---
    progress_m: Array  # () float32, m, furthest route arc reached (last tick)
    route_length_m: Array  # () float32, m
    # --- shared rings over the last RING ticks (oldest first) ---
    time_ring: Array  # (RING,) float32, s
    progress_ring: Array  # (RING,) float32, m
    speed_ring: Array  # (REACT_WINDOW,) float32, m/s
    accel_ring: Array  # (REACT_WINDOW,) float32, m/s^2
    # --- time-to-collision over [t_ref, t_clear] ---
    ttc_min: Array  # () float32, s, hard minimum (BIG before any sample)
    ttc_any: Array  # () bool, at least one TTC sample (closing or overlapping)
    ttc_lse: Array  # () float32, soft-min accumulator
    # --- clearance over [t_event, t_clear] ---
    clear_min: Array  # () float32, m, hard minimum box distance (BIG before any sample)
    clear_any: Array  # () bool, at least one sample (hazard present or collision)
    clear_lse: Array  # () float32, soft-min accumulator
    # --- anticipation ---
    v_pre: Array  # () float32, m/s, ego speed at the first tick with t >= t_ref
    v_pre_set: Array  # () bool
    n_post_ref: Array  # () int32, ticks with t >= t_ref
    react_flags: Array  # (REACT_WINDOW,) bool, response flags of the last ticks (t >= t_ref)
    t_react: Array  # () float32, s, start of the first sustained-response window (INF_TIME)
    event_checked: Array  # () bool, the pre-event window (coincident onset) was examined
    response_at_event: Array  # () bool, the window ending at the event tick met the criterion
    t_response_start: Array  # () float32, s, start of that window (INF_TIME if not met)
    soft_react_flags: Array  # (REACT_WINDOW,) float32, soft response flags
    react_surv: Array  # () float32, soft probability that no window has passed yet
    react_p: Array  # () float32, soft probability that some window passed
    react_pt: Array  # () float32, s, sum_k p_k t_k
    soft_response_at_event: Array  # () float32
    # --- recovery after t_release = max(t_warn_off, t_clear) ---
    rec_run: Array  # () int32, consecutive ticks after release with speed above threshold
    t_recover: Array  # () float32, s, start of the first recovery window (INF_TIME)
    rec_logok: Array  # (RING,) float32, log sigmoid((v - v_thr) / T) of the last ticks
    rec_surv: Array  # () float32
    rec_p: Array  # () float32
    rec_pt: Array  # () float32, s
    # --- gates ---
    collided: Array  # () bool
    t_collision: Array  # () float32, s, first collision (INF_TIME)
    coll_margin: Array  # () float32, m, min over hazard ticks of max(box dist, 0.1 - speed)
    max_route_dist: Array  # () float32, m
    t_route_dev: Array  # () float32, s, first tick with dist_to_route >= 30 m
    n_outside: Array  # () int32, ticks outside the driving lanes (total)
    t_lane_fail: Array  # () float32, s, tick at which the total reached 1 s
    red_light: Array  # () bool
    t_rule: Array  # () float32, s, first red-light violation
    still_run: Array  # () int32, consecutive ticks below 0.1 m/s with the route unfinished
    max_still_run: Array  # () int32
    t_stall: Array  # () float32, s, tick at which a standstill reached 20 s
    fault: Array  # () bool, controller fault on any tick
    t_fault: Array  # () float32, s
    fb_run: Array  # () int32, consecutive unjustified stopped ticks in [t_ref, t_event]
    fb_max_run: Array  # () int32
    t_false_brake: Array  # () float32, s, tick at which such a stop reached 1 s


def init_telemetry() -> Telemetry:
    """Accumulators before the first tick."""
    f = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    i = lambda v: jnp.asarray(v, jnp.int32)  # noqa: E731
    b = lambda v: jnp.asarray(v, bool)  # noqa: E731
    inf, big, empty = f(INF_TIME), f(BIG), f(LSE_EMPTY)
    return Telemetry(
        n_ticks=i(0), t_last=f(0.0), temperature=f(1.0), is_route_a=b(True),
        coincident_onset=b(False),
        t_warn_point=inf, t_event=inf, t_warn_off=inf, t_clear=inf,
        progress_m=f(0.0), route_length_m=f(0.0),
        time_ring=jnp.zeros(RING, jnp.float32), progress_ring=jnp.zeros(RING, jnp.float32),
        speed_ring=jnp.zeros(th.REACT_WINDOW, jnp.float32),
        accel_ring=jnp.zeros(th.REACT_WINDOW, jnp.float32),
        ttc_min=big, ttc_any=b(False), ttc_lse=empty,
        clear_min=big, clear_any=b(False), clear_lse=empty,
        v_pre=f(0.0), v_pre_set=b(False), n_post_ref=i(0),
        react_flags=jnp.zeros(th.REACT_WINDOW, bool), t_react=inf,
        event_checked=b(False), response_at_event=b(False), t_response_start=inf,
        soft_react_flags=jnp.zeros(th.REACT_WINDOW, jnp.float32),
        react_surv=f(1.0), react_p=f(0.0), react_pt=f(0.0), soft_response_at_event=f(0.0),
        rec_run=i(0), t_recover=inf, rec_logok=jnp.zeros(RING, jnp.float32),
        rec_surv=f(1.0), rec_p=f(0.0), rec_pt=f(0.0),
        collided=b(False), t_collision=inf, coll_margin=big,
        max_route_dist=f(0.0), t_route_dev=inf,
        n_outside=i(0), t_lane_fail=inf,
        red_light=b(False), t_rule=inf,
        still_run=i(0), max_still_run=i(0), t_stall=inf,
        fault=b(False), t_fault=inf,
        fb_run=i(0), fb_max_run=i(0), t_false_brake=inf,
    )  # fmt: skip


def _push(ring: Array, x: Array) -> Array:
    """Append ``x`` at the end of a ring (oldest first), dropping the oldest entry."""
    return jnp.concatenate([ring[1:], jnp.asarray(x, ring.dtype)[None]])


def _happened(t: Array) -> Array:
    return t < th.HAPPENED_BELOW


def _first_time(already: Array, now: Array, t: Array, t_old: Array) -> Array:
    """Record ``t`` the first tick ``now`` holds (``already`` = it held before)."""
    return jnp.where(now & ~already, t, t_old)


def _count(n: Array, inc: Array) -> Array:
    return jnp.minimum(n + inc.astype(jnp.int32), _COUNT_CAP)


def _run(n: Array, cond: Array) -> Array:
    return jnp.where(cond, jnp.minimum(n + 1, _COUNT_CAP), 0)


def _step(tel: Telemetry, s: TickSample, temp: Array) -> Telemetry:
    f32 = jnp.float32
    t = jnp.asarray(s.t, f32)
    speed = jnp.asarray(s.ego_speed, f32)
    accel = jnp.asarray(s.ego_accel, f32)
    progress = jnp.asarray(s.progress, f32)
    route_length = jnp.asarray(s.route_length, f32)
    present = jnp.asarray(s.hazard_present, bool)
    collision = jnp.asarray(s.collision, bool)
    t_ref, t_event = s.t_warn_point, s.t_event
    t_warn_off, t_clear = s.t_warn_off, s.t_clear
    n_ticks = _count(tel.n_ticks, jnp.asarray(True))

    time_ring = _push(tel.time_ring, t)
    progress_ring = _push(tel.progress_ring, progress)
    speed_ring = _push(tel.speed_ring, speed)
    accel_ring = _push(tel.accel_ring, accel)

    post_ref = _happened(t_ref) & (t >= t_ref)
    post_event = _happened(t_event) & (t >= t_event)
    before_clear = t <= t_clear

    # --- time-to-collision (controlled hazard, [t_ref, t_clear]) ---
    r = jnp.asarray(s.hazard_rel, f32)
    rv = jnp.asarray(s.hazard_rel_vel, f32)
    rr = jnp.sum(r * r)
    r_ok = rr > 1e-12
    r_norm = jnp.sqrt(jnp.where(r_ok, rr, 1.0))
    v_close = jnp.where(r_ok, -jnp.sum(r * rv) / r_norm, 0.0)
    d_box = jnp.maximum(jnp.asarray(s.hazard_box_dist, f32), 0.0)
    overlap = d_box <= 0.0
    closing = v_close > th.CLOSING_MIN_MPS
    in_ttc = post_ref & before_clear & present
    ttc = jnp.where(overlap, 0.0, d_box / jnp.where(closing, v_close, 1.0))
    ttc_sample = in_ttc & (overlap | closing)
    ttc_min = jnp.where(ttc_sample, jnp.minimum(tel.ttc_min, ttc), tel.ttc_min)
    ttc_soft = jnp.where(overlap, 0.0, d_box / jnp.maximum(v_close, th.CLOSING_MIN_MPS))
    ttc_logw = jnp.where(overlap, 0.0, jax.nn.log_sigmoid((v_close - th.CLOSING_MIN_MPS) / temp))
    ttc_lse = jnp.where(in_ttc, lse_add(tel.ttc_lse, ttc_soft, temp, ttc_logw), tel.ttc_lse)

    # --- clearance ([t_event, t_clear]; a collision there counts as distance 0) ---
    in_clear = post_event & before_clear
    clear_sample = in_clear & (present | collision)
    d_clear = jnp.where(collision, 0.0, d_box)
    clear_min = jnp.where(clear_sample, jnp.minimum(tel.clear_min, d_clear), tel.clear_min)
    clear_lse = jnp.where(clear_sample, lse_add(tel.clear_lse, d_clear, temp), tel.clear_lse)

    # --- anticipation: sustained response at/after t_ref ---
    first_post = post_ref & ~tel.v_pre_set
    v_pre = jnp.where(first_post, speed, tel.v_pre)
    v_pre_set = tel.v_pre_set | post_ref
    flag = post_ref & ((accel <= th.REACT_ACCEL_MPS2) | (speed <= v_pre - th.REACT_SPEED_DROP_MPS))
    react_flags = _push(tel.react_flags, flag)
    n_post_ref = _count(tel.n_post_ref, post_ref)
    full_react = n_post_ref >= th.REACT_WINDOW
    window_start = time_ring[RING - th.REACT_WINDOW]
    react_ok = full_react & (jnp.sum(react_flags) >= th.REACT_MIN_COUNT)
    t_react = _first_time(_happened(tel.t_react), react_ok, window_start, tel.t_react)

    soft_a = jax.nn.sigmoid((th.REACT_ACCEL_MPS2 - accel) / temp)
    soft_b = jax.nn.sigmoid((v_pre - th.REACT_SPEED_DROP_MPS - speed) / temp)
    soft_flag = jnp.where(post_ref, 1.0 - (1.0 - soft_a) * (1.0 - soft_b), 0.0)
    soft_react_flags = _push(tel.soft_react_flags, soft_flag)
    react_sigma = jnp.where(
        full_react,
        jax.nn.sigmoid((jnp.sum(soft_react_flags) - (th.REACT_MIN_COUNT - 0.5)) / temp),
        0.0,
    )
    react_pk = tel.react_surv * react_sigma

    # coincident onset: the REACT_WINDOW ticks ending at the event tick, flags against the speed
    # at the start of that window (computed on every execution, used where onsets coincide)
    event_now = post_event & ~tel.event_checked
    full_any = n_ticks >= th.REACT_WINDOW
    v_start = speed_ring[0]
    pre_flags = (accel_ring <= th.REACT_ACCEL_MPS2) | (
        speed_ring <= v_start - th.REACT_SPEED_DROP_MPS
    )
    present_now = full_any & (jnp.sum(pre_flags) >= th.REACT_MIN_COUNT)
    pre_soft = 1.0 - (1.0 - jax.nn.sigmoid((th.REACT_ACCEL_MPS2 - accel_ring) / temp)) * (
        1.0 - jax.nn.sigmoid((v_start - th.REACT_SPEED_DROP_MPS - speed_ring) / temp)
    )
    soft_present_now = jnp.where(
        full_any,
        jax.nn.sigmoid((jnp.sum(pre_soft) - (th.REACT_MIN_COUNT - 0.5)) / temp),
        0.0,
    )

    # --- recovery after t_release = max(t_warn_off, t_clear) ---
    released = _happened(t_warn_off) & _happened(t_clear)
    t_release = jnp.where(released, jnp.maximum(t_warn_off, t_clear), INF_TIME)
    post_rel = released & (t >= t_release)
    v_thr = jnp.maximum(th.RECOVER_MIN_SPEED_MPS, th.RECOVER_PRE_FRACTION * v_pre)
    rec_run = _run(tel.rec_run, post_rel & (speed > v_thr))
    gain = progress - progress_ring[0]
    rec_ok = (rec_run >= th.RECOVER_WINDOW) & (gain >= th.RECOVER_MIN_PROGRESS_M)
    t_recover = _first_time(_happened(tel.t_recover), rec_ok, time_ring[0], tel.t_recover)

    rec_logok = _push(tel.rec_logok, jax.nn.log_sigmoid((speed - v_thr) / temp))
    rec_window = post_rel & (n_ticks >= th.RECOVER_WINDOW) & (time_ring[0] >= t_release)
    rec_sigma = jnp.where(
        rec_window,
        jnp.exp(jnp.sum(rec_logok)) * jax.nn.sigmoid((gain - th.RECOVER_MIN_PROGRESS_M) / temp),
        0.0,
    )
    rec_pk = tel.rec_surv * rec_sigma

    # --- gates ---
    coll_tick = jnp.where(present, jnp.maximum(d_box, th.COLLISION_MIN_SPEED_MPS - speed), BIG)
    dist = jnp.asarray(s.dist_to_route, f32)
    deviated = dist >= th.ROUTE_DEVIATION_M
    n_outside = _count(tel.n_outside, jnp.asarray(s.outside_lanes, bool))
    lane_failed = n_outside >= th.LANE_DEBOUNCE
    red = jnp.asarray(s.red_light_violation, bool)
    completed = progress >= route_length - th.COMPLETION_TOL_M
    still_run = _run(tel.still_run, (speed < th.STILL_SPEED_MPS) & ~completed)
    stalled = still_run >= th.BLOCK_STILL
    fault = jnp.asarray(s.controller_fault, bool)
    in_fb = post_ref & (t <= t_event)
    fb_run = _run(
        tel.fb_run,
        in_fb & (speed <= th.FALSE_BRAKE_SPEED_MPS) & ~jnp.asarray(s.justified_stop, bool),
    )
    fb_failed = fb_run >= th.FALSE_BRAKE

    return Telemetry(
        n_ticks=n_ticks,
        t_last=t,
        temperature=jnp.asarray(temp, f32),
        is_route_a=jnp.asarray(s.is_route_a, bool),
        coincident_onset=tel.coincident_onset | jnp.asarray(s.coincident_onset, bool),
        t_warn_point=jnp.asarray(t_ref, f32),
        t_event=jnp.asarray(t_event, f32),
        t_warn_off=jnp.asarray(t_warn_off, f32),
        t_clear=jnp.asarray(t_clear, f32),
        progress_m=progress,
        route_length_m=route_length,
        time_ring=time_ring,
        progress_ring=progress_ring,
        speed_ring=speed_ring,
        accel_ring=accel_ring,
        ttc_min=ttc_min,
        ttc_any=tel.ttc_any | ttc_sample,
        ttc_lse=ttc_lse,
        clear_min=clear_min,
        clear_any=tel.clear_any | clear_sample,
        clear_lse=clear_lse,
        v_pre=v_pre,
        v_pre_set=v_pre_set,
        n_post_ref=n_post_ref,
        react_flags=react_flags,
        t_react=t_react,
        event_checked=tel.event_checked | post_event,
        response_at_event=jnp.where(event_now, present_now, tel.response_at_event),
        t_response_start=jnp.where(
            event_now & present_now, time_ring[RING - th.REACT_WINDOW], tel.t_response_start
        ),
        soft_react_flags=soft_react_flags,
        react_surv=tel.react_surv * (1.0 - react_sigma),
        react_p=tel.react_p + react_pk,
        react_pt=tel.react_pt + react_pk * window_start,
        soft_response_at_event=jnp.where(event_now, soft_present_now, tel.soft_response_at_event),
        rec_run=rec_run,
        t_recover=t_recover,
        rec_logok=rec_logok,
        rec_surv=tel.rec_surv * (1.0 - rec_sigma),
        rec_p=tel.rec_p + rec_pk,
        rec_pt=tel.rec_pt + rec_pk * time_ring[0],
        collided=tel.collided | collision,
        t_collision=_first_time(tel.collided, collision, t, tel.t_collision),
        coll_margin=jnp.minimum(tel.coll_margin, coll_tick),
        max_route_dist=jnp.maximum(tel.max_route_dist, dist),
        t_route_dev=_first_time(_happened(tel.t_route_dev), deviated, t, tel.t_route_dev),
        n_outside=n_outside,
        t_lane_fail=_first_time(_happened(tel.t_lane_fail), lane_failed, t, tel.t_lane_fail),
        red_light=tel.red_light | red,
        t_rule=_first_time(tel.red_light, red, t, tel.t_rule),
        still_run=still_run,
        max_still_run=jnp.maximum(tel.max_still_run, still_run),
        t_stall=_first_time(_happened(tel.t_stall), stalled, t, tel.t_stall),
        fault=tel.fault | fault,
        t_fault=_first_time(tel.fault, fault, t, tel.t_fault),
        fb_run=fb_run,
        fb_max_run=jnp.maximum(tel.fb_max_run, fb_run),
        t_false_brake=_first_time(_happened(tel.t_false_brake), fb_failed, t, tel.t_false_brake),
    )


def update_telemetry(
    tel: Telemetry, sample: TickSample, temperature: Array | float = 0.05, active: Array = True
) -> Telemetry:
    """Fold one 20 Hz tick into the accumulators (jittable; one execution, ``vmap`` outside).

    Args:
        tel: accumulators before the tick.
        sample: the tick's measurement (see :class:`~lantern_jax.scoring.sample.TickSample`).
        temperature: () float32, temperature of the soft accumulators (in the unit of each
            relaxed quantity: s, m, m/s, m/s^2, samples); must be > 0.
        active: () bool, ``False`` leaves ``tel`` unchanged (ticks after an execution has ended
            — route completed, timed out — in a fixed-length batched scan).

    Returns:
        The updated :class:`Telemetry`.
    """
    temp = jnp.asarray(temperature, jnp.float32)
    new = _step(tel, sample, temp)
    on = jnp.asarray(active, bool)
    return jax.tree.map(lambda n, o: jnp.where(on, n, o), new, tel)


def fold_telemetry(
    samples: TickSample, temperature: Array | float = 0.05, active: Array | None = None
) -> Telemetry:
    """Fold a whole stacked sequence of ticks (leading axis = time) with ``lax.scan``.

    Convenience for tests and offline scoring; the rollout calls :func:`update_telemetry` inside
    its own scan instead.
    """
    n = jax.tree.leaves(samples)[0].shape[0]
    act = jnp.ones(n, bool) if active is None else jnp.asarray(active, bool)

    def body(tel, xs):
        s, a = xs
        return update_telemetry(tel, s, temperature, a), None

    tel, _ = jax.lax.scan(body, init_telemetry(), (samples, act))
    return tel
