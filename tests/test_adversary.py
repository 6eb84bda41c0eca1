"""Adversarial actor tracks: the closed form, its limits, the exact no-op of zero actions, and the
``adversary`` field of a pair's parameters (checked, hashed, built)."""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from lantern_jax.core.constants import DT, KIND_PEDESTRIAN, KIND_VEHICLE, MAX_KNOTS
from lantern_jax.dynamics import adversary as adv
from lantern_jax.dynamics.scripted import ScriptedMotion, scripted_arc
from lantern_jax.scenarios import adversary as spec
from lantern_jax.scenarios.families import build_pair, param_errors
from lantern_jax.scenarios.spec import content_hash
from lantern_jax.scenarios.suite import load_suite

N = 16
H = 0.5


@pytest.fixture(scope="module")
def suite():
    return load_suite()


def _pair(suite, family):
    return next(p for p in suite.pairs if p.family == family)


def _profile(u_acc, u_lat, kind, v0, h=H):
    lim = adv.limits_of_kind(kind)
    acc, lat = adv.scale_actions(jnp.asarray(u_acc), jnp.asarray(u_lat), lim)
    prof = adv.track_profile(acc, lat, h, jnp.float32(v0), lim)
    return lim, {k: np.asarray(v, np.float64) for k, v in prof.items()}


# ---------------------------------------------------------------------------------------------
# the closed form
# ---------------------------------------------------------------------------------------------
# float32 values without subnormals: XLA's CPU kernels may flush a subnormal to zero in one
# expression and not in another, which is not what this test is about
def _f32(lo: float, hi: float):
    return st.floats(lo, hi, width=32, allow_subnormal=False)


_scripted_arc = jax.jit(scripted_arc)  # one compilation for every example


@settings(max_examples=40, deadline=None)
@given(t=_f32(0.0, 30.0), tau=_f32(0.0, 10.0), v_post=_f32(0.0, 12.0), lat_shift=_f32(-4.0, 4.0))
def test_zero_actions_reproduce_the_scripted_motion_exactly(t, tau, v_post, lat_shift):
    """A track of zero actions adds exact zeros: every output of the closed form equals the
    script's own exactly (as numbers: ``-0.0 + 0.0`` is ``+0.0``)."""
    motion = ScriptedMotion(
        s_init=jnp.float32(2.0), v_pre=jnp.float32(0.0), v_post=jnp.float32(v_post),
        s_hold=jnp.float32(1e6), s_end=jnp.float32(60.0), lat_shift=jnp.float32(lat_shift),
        lat_duration=jnp.float32(2.0), despawn_at_end=jnp.asarray(True),
    )  # fmt: skip
    args = [motion, jnp.float32(t), jnp.float32(tau)]
    _, prof = _profile(np.zeros(N), np.zeros(N), KIND_VEHICLE, v_post)
    track = tuple(jnp.asarray(prof[k], jnp.float32) for k in ("dv", "ds", "q", "g", "dlat"))
    plain = _scripted_arc(*args)
    tracked = _scripted_arc(*args, (*track, jnp.float32(H)))
    for a, b in zip(plain, tracked, strict=True):
        assert np.asarray(a) == np.asarray(b)


@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from([KIND_PEDESTRIAN, KIND_VEHICLE]),
    v0=st.floats(0.0, 16.0),
    seed=st.integers(0, 2**31 - 1),
    extreme=st.booleans(),
)
@example(kind=KIND_PEDESTRIAN, v0=16.0, seed=83917044, extreme=True)  # braked from 16 m/s
def test_kinematic_limits_hold_for_any_action(kind, v0, seed, extreme):
    """Whatever the actions, the realised speed stays in [max(0, v0 - v_max), max(v_max, v0)]
    (so that an actor scripted faster than its kind's v_max still gets back), its change per
    knot within the acceleration and braking limits, the lateral channel within its bound and
    rate, a vehicle's lateral speed within its heading bound times its speed, and after the last
    knot the actor is back to its scripted speed and heading."""
    rng = np.random.default_rng(seed)
    draw = (lambda: rng.choice([-1.0, 1.0], N)) if extreme else (lambda: rng.uniform(-1, 1, N))
    lim, p = _profile(draw(), draw(), kind, v0)
    v = v0 + p["dv"]
    tol = 1e-4
    assert np.all(v >= max(0.0, v0 - lim.v_max) - tol) and np.all(v <= max(lim.v_max, v0) + tol)
    dv = np.diff(v) / H
    assert np.all(dv <= lim.a_max + tol) and np.all(-dv <= lim.b_max + tol)
    assert np.all(np.abs(p["q"]) <= lim.lat_max + tol)
    assert np.all(np.abs(np.diff(p["q"])) / H <= lim.lat_rate + tol)
    # after the last knot the actor returns to its script: scripted speed, zero lateral channel
    assert abs(p["dv"][-1]) < tol and abs(p["q"][-1]) < tol
    # dense samples of the closed form between the knots
    prof = {k: jnp.asarray(x, jnp.float32) for k, x in p.items()}
    us = jnp.linspace(0.0, N * H + adv.RETURN_S + 2.0, 401)
    off = jax.vmap(
        lambda u: adv.scripted_offsets(
            prof["dv"], prof["ds"], prof["q"], prof["g"], prof["dlat"], jnp.float32(H), u
        )
    )(us)
    speed = v0 + np.asarray(off[1], np.float64)
    w = np.asarray(off[3], np.float64)
    assert np.all(speed >= -tol) and np.all(speed <= max(lim.v_max, v0) + tol)
    bound = lim.lat_max * (1.0 if lim.holonomic else np.maximum(speed, 0.0))
    assert np.all(np.abs(w) <= bound + 1e-3)


# knots of 0.5 s; per-tick controls over the same 8 s; the most knots a track may hold
@pytest.mark.parametrize("n, h", [(N, H), (160, DT), (MAX_KNOTS, DT)])
def test_closed_form_integrates_its_own_speeds(n, h):
    """The arc and lateral offsets are the integrals of the speed and lateral speed deviations
    (checked against a fine trapezoid rule), continuous at the knots."""
    rng = np.random.default_rng(3)
    _, p = _profile(rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), KIND_VEHICLE, 7.0, h)
    prof = {k: jnp.asarray(x, jnp.float32) for k, x in p.items()}
    us = np.linspace(0.0, n * h + 1.0, int(400 * (n * h + 1.0)) + 1)  # 2.5 ms apart
    off = jax.vmap(
        lambda u: adv.scripted_offsets(
            prof["dv"], prof["ds"], prof["q"], prof["g"], prof["dlat"], jnp.float32(h), u
        )
    )(jnp.asarray(us, jnp.float32))
    ds, dv, dlat, w = (np.asarray(x, np.float64) for x in off)
    trap = lambda y: np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(us))])  # noqa: E731
    np.testing.assert_allclose(ds, trap(dv), atol=2e-3)
    np.testing.assert_allclose(dlat, trap(w), atol=2e-3)
    assert np.max(np.abs(np.diff(ds))) < 0.025  # continuous (steps of 2.5 ms at <= 10 m/s)


def test_commanded_holds_after_the_last_knot():
    acc = jnp.arange(1.0, N + 1.0)
    q = jnp.linspace(0.0, 0.2, N + 1)
    a, qn = adv.commanded(acc, q, jnp.float32(H), jnp.float32(3 * H + 0.25))
    assert float(a) == 4.0 and float(qn) == pytest.approx(float(q[3] + (q[4] - q[3]) * 0.5))
    a, qn = adv.commanded(acc, q, jnp.float32(H), jnp.float32(N * H + 5.0))
    assert float(a) == 0.0 and float(qn) == pytest.approx(0.2)
    a, qn = adv.commanded(acc, q, jnp.float32(H), jnp.float32(-0.1))
    assert float(a) == 0.0 and float(qn) == 0.0


def test_a_static_object_takes_no_track():
    with pytest.raises(ValueError, match="takes no track"):
        adv.limits_of_kind(2)


# ---------------------------------------------------------------------------------------------
# the adversary field of a pair's parameters
# ---------------------------------------------------------------------------------------------
def _with_adversary(params, tracks, knot_s=H):
    return dict(params, adversary=dict(knot_s=knot_s, tracks=tracks))


@pytest.mark.parametrize(
    "adversary, message",
    [
        ([], r"PE.adversary: expected a JSON object"),
        (dict(knot_s=0.5, tracks=[]), r"PE.adversary.tracks: expected a non-empty JSON array"),
        (
            dict(knot_s=5.0, tracks=[dict(slot=0, accel=[0.0], lateral=[0.0])]),
            r"PE.adversary.knot_s: expected a number in \[0.05, 2\]",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=0, accel=[0.0, 1.5], lateral=[0.0, 0.0])]),
            r"PE.adversary.tracks\[0\].accel\[1\]: 1.5 outside \[-1, 1\]",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=0, accel=[0.0], lateral=[0.0, 0.0])]),
            r"PE.adversary.tracks: every channel needs the same number of knots",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=16, accel=[0.0], lateral=[0.0])]),
            r"PE.adversary.tracks\[0\].slot: expected an integer in \[0, 15\]",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=0, accel=[0.0], lateral=[0.0], jerk=[1])]),
            r"PE.adversary.tracks\[0\].jerk: unknown field",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=9, accel=[0.0], lateral=[0.0])]),
            r"PE.adversary.tracks\[0\].slot: slot 9 holds no actor",
        ),
        (
            dict(knot_s=0.5, tracks=[dict(slot=0, accel=[0.0], lateral=[0.0])] * 2),
            r"PE.adversary.tracks\[1\].slot: slot 0 has a track already",
        ),
    ],
)
def test_bad_adversary_fields_are_named(suite, adversary, message):
    params = dict(_pair(suite, "PE").params, adversary=adversary)
    errors = param_errors(params)
    assert errors and any(__import__("re").search(message, e) for e in errors), errors


def test_a_static_slot_is_refused(suite):
    params = _with_adversary(_pair(suite, "OR").params, [dict(slot=0, accel=[0.0], lateral=[0.0])])
    assert param_errors(params) == [
        "OR.adversary.tracks[0].slot: slot 0 holds a static object, which takes no track"
    ]


def test_the_track_is_hashed_and_built(suite):
    """The content hash covers every action; the builder puts the track on Route A (with the
    kind's limits) and an all-zero track of the same shape on Route B."""
    pair = _pair(suite, "PE")
    tracks = [dict(slot=0, accel=[0.5] * N, lateral=[0.0] * N)]
    params = _with_adversary(pair.params, tracks)
    other = copy.deepcopy(params)
    other["adversary"]["tracks"][0]["accel"][7] = 0.25
    assert param_errors(params) == []
    assert len({content_hash(pair.params), content_hash(params), content_hash(other)}) == 3
    a, b, meta = build_pair(params)
    lim = adv.KINEMATIC_LIMITS["pedestrian"]
    np.testing.assert_allclose(np.asarray(a.actors.track.accel[0]), 0.5 * lim.a_max)
    assert np.all(np.asarray(a.actors.track.accel[1:]) == 0.0)
    assert float(a.actors.track.v_max[0]) == pytest.approx(lim.v_max)
    assert b.actors.track.accel.shape == a.actors.track.accel.shape
    assert np.all(np.asarray(b.actors.track.accel) == 0.0)
    assert meta["adversary_slots"] == [0] and meta["content_hash"] == content_hash(params)
    a.validate()
    b.validate()


def test_per_tick_tracks_of_the_most_knots_are_accepted_and_nothing_longer_or_finer(suite):
    """A track may hold an action per tick (knots of one tick, ``DT``) up to ``MAX_KNOTS`` knots:
    the field and the search space accept it, the built Route A holds every action and its
    profile runs to the end of the return window; one knot more, or a knot shorter than a
    tick, is named."""
    from lantern_jax.apps.stress.space import adversary_space

    pair = _pair(suite, "PE")
    rng = np.random.default_rng(0)
    acc = [round(float(x), 3) for x in rng.uniform(-1, 1, MAX_KNOTS)]
    params = _with_adversary(pair.params, [dict(slot=0, accel=acc, lateral=[0.0] * MAX_KNOTS)],
                             knot_s=DT)  # fmt: skip
    assert param_errors(params) == []
    a, _, _ = build_pair(params)
    assert a.actors.track.knots == MAX_KNOTS
    assert a.actors.track.dv.shape[-1] == MAX_KNOTS + adv.return_knots(DT) + 1
    a.validate()
    space = adversary_space(a, "PE", ("hazard",), knots=MAX_KNOTS, knot_s=DT)
    assert space.dim == 2 * MAX_KNOTS
    zeros = [0.0] * (MAX_KNOTS + 1)
    longer = _with_adversary(pair.params, [dict(slot=0, accel=zeros, lateral=zeros)], knot_s=DT)
    assert any(f"expected an array of 1 to {MAX_KNOTS} numbers" in e for e in param_errors(longer))
    finer = _with_adversary(pair.params, [dict(slot=0, accel=[0.0], lateral=[0.0])], knot_s=0.04)
    assert any("knot_s: expected a number in [0.05, 2]" in e for e in param_errors(finer))
    with pytest.raises(ValueError, match=rf"knots: expected a whole number in \[1, {MAX_KNOTS}\]"):
        adversary_space(a, "PE", ("hazard",), knots=MAX_KNOTS + 1, knot_s=DT)
    with pytest.raises(ValueError, match=r"knot_s: expected seconds in \[0.05, 2\]"):
        adversary_space(a, "PE", ("hazard",), knots=4, knot_s=0.04)


def test_the_shipped_suite_is_unchanged(suite):
    """No shipped pair carries a track: the suite's pairs and hash are those it shipped with."""
    assert all(spec.ADVERSARY_FIELD not in p.params for p in suite.pairs)
    a, b, _ = build_pair(suite.pairs[0].params)
    assert a.actors.track is None and b.actors.track is None


def test_actor_groups_name_moving_actors(suite):
    """``hazard`` is the hazard actor, or in Obstacle Reveal (a static hazard) the van that
    reveals it; ``background`` the background vehicle whose path passes nearest the route."""
    for fam, hazard in (("PE", 0), ("VC", 0), ("OR", 1), ("LWW", 0), ("RWW", 0), ("RTY", 0)):
        a, _, _ = build_pair(_pair(suite, fam).params)
        slots = spec.adversary_slots(a, ["hazard", "background"])
        assert slots[0] == hazard and len(slots) == 2, (fam, slots)
        assert int(a.actors.role[slots[1]]) == 3 and int(a.actors.kind[slots[1]]) == KIND_VEHICLE
    with pytest.raises(ValueError, match="actors: 'crowd' not one of hazard, background"):
        spec.adversary_slots(a, ["crowd"])


def test_batches_mix_pairs_with_and_without_tracks(suite):
    """A batch of pairs with and without tracks (and with different knot counts) stacks: the
    others get zero tracks, shorter tracks zero actions and a profile that holds its last
    state, which changes none of their motion."""
    from lantern_jax.scenarios.suite import build_suite_batches

    pe = _pair(suite, "PE")
    rng = np.random.default_rng(0)
    long_ = _with_adversary(
        pe.params,
        [
            dict(
                slot=0, accel=rng.uniform(-1, 1, 8).tolist(), lateral=rng.uniform(-1, 1, 8).tolist()
            )
        ],
    )
    short = _with_adversary(pe.params, [dict(slot=0, accel=[0.3, -0.2], lateral=[0.1, 0.0])])
    pairs = (
        suite.pairs[0],
        *(
            type(pe)(f"x{i}", "PE", pe.weather, p, content_hash(p))
            for i, p in enumerate((long_, short))
        ),
    )
    a, b = build_suite_batches(suite.__class__(suite.suite_id, pairs, "0" * 64, 0, {}))
    assert a.actors.track.accel.shape == (3, 16, 8)
    assert a.actors.track.dv.shape == (3, 16, 8 + adv.return_knots(H) + 1)
    assert np.all(np.asarray(a.actors.track.accel[0]) == 0.0)
    # the short track's padded profile equals its own closed form beyond its last knot
    built, _, _ = build_pair(short)
    tr = built.actors.track
    for u in (0.3, 1.0, 2.5, 3.9, 9.0):
        own = adv.scripted_offsets(
            tr.dv[0], tr.ds[0], tr.q[0], tr.g[0], tr.dlat[0], tr.knot_s[0], jnp.float32(u)
        )
        t2 = a.actors.track
        padded = adv.scripted_offsets(
            *(jnp.asarray(getattr(t2, k)[2, 0]) for k in ("dv", "ds", "q", "g", "dlat", "knot_s")),
            jnp.float32(u),
        )
        np.testing.assert_allclose(np.asarray(padded), np.asarray(own), atol=1e-5)
    assert b.actors.track.accel.shape == (3, 16, 8)


# ---------------------------------------------------------------------------------------------
# in the simulator
# ---------------------------------------------------------------------------------------------
def _actor_states(scenario, ticks):
    """Every tick's actor states of one execution driven by a constant-speed ego."""
    from lantern_jax.core.times import NEVER
    from lantern_jax.dynamics.actors import step_actors
    from lantern_jax.dynamics.lights import light_states

    def body(actors, k):
        t = (k + 1).astype(jnp.float32) * DT
        ego_xy = jnp.stack([t * 8.0, 0.0])
        t_event = jnp.where(t >= 1.0, 1.0, NEVER).astype(jnp.float32)
        new = step_actors(
            actors,
            scenario.actors,
            t,
            t_event,
            light_states(scenario.lights, t),
            ego_xy,
            jnp.float32(0.0),
            jnp.float32(8.0),
        )
        return new, (new.s, new.speed, new.lat, new.xy)

    return jax.jit(lambda: jax.lax.scan(body, scenario.actors0, jnp.arange(ticks))[1])()


def test_idm_actors_follow_their_tracks_within_limits(suite):
    """A background car's track (IDM) changes its motion from the event on, keeps its
    realised acceleration within the car's limits, and zero actions change nothing."""
    pair = _pair(suite, "VC")
    a0, _, _ = build_pair(pair.params)
    slot = spec.adversary_slots(a0, ["background"])[0]
    zero = _with_adversary(pair.params, [dict(slot=slot, accel=[0.0] * N, lateral=[0.0] * N)])
    hard = _with_adversary(
        pair.params, [dict(slot=slot, accel=[-1.0] * 4 + [1.0] * 12, lateral=[1.0] * N)]
    )
    base = [np.asarray(x) for x in _actor_states(a0, 200)]
    same = [np.asarray(x) for x in _actor_states(build_pair(zero)[0], 200)]
    for x, y in zip(base, same, strict=True):
        np.testing.assert_array_equal(x, y)
    s, v, lat, _ = (np.asarray(x) for x in _actor_states(build_pair(hard)[0], 200))
    lim = adv.KINEMATIC_LIMITS["car"]
    before = slice(0, 19)  # the event is at t = 1 s: no change before it
    np.testing.assert_array_equal(v[before, slot], base[1][before, slot])
    acc = np.diff(v[:, slot]) / DT
    assert acc.min() >= -lim.b_max - 1e-3 and acc.max() <= lim.a_max + 1e-3
    assert v[:, slot].max() <= lim.v_max + 1e-3
    assert v[40, slot] < base[1][40, slot] - 3.0  # braked hard for 2 s
    assert lat[-1, slot] > 1.0  # drifted left (a heading offset, never a slide at standstill)
