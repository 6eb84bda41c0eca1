"""Adversarial tracks as part of a pair's parameters: the ``adversary`` field, checked and built.

A pair's parameter dict may carry an optional ``adversary`` object::

    "adversary": {
        "knot_s": 0.5,
        "tracks": [
            {"slot": 0, "accel": [0.1, -0.4, ...], "lateral": [0.0, 0.3, ...]},
            ...
        ]
    }

Each track gives one actor slot ``N`` normalised actions per channel, every one in ``[-1, 1]``
(acceleration ``1 = a_max``, ``-1 = -b_max``; lateral rate ``+-1 = +-lat_rate`` of the actor's
kind, :data:`lantern_jax.dynamics.adversary.KINEMATIC_LIMITS`), all tracks the same ``N``
(``1 <= N <= MAX_KNOTS``) and knot length ``knot_s`` (``KNOT_S_RANGE``).  The field is checked
with the rest of the parameters (:func:`adversary_errors`; the slot must hold a vehicle or a
walker, checked on the built pair by :func:`slot_errors`), is covered by the pair's content hash
like every other field, and is applied by the world builder
(:func:`lantern_jax.scenarios.families.build_pair` calls :func:`apply_adversary`): Route A gets
the tracks, Route B an all-zero track of the same shape, so the control route stays the
benchmark's and both routes batch together.

:func:`adversary_slots` names the actors a search may drive: ``hazard`` (the family's hazard
actor; in Obstacle Reveal, whose hazard is a static object, the lead van that reveals it) and
``background`` (the background vehicles whose paths pass nearest the ego's route).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import (
    KIND_STATIC,
    KNOT_S_RANGE,
    MAX_ACTORS,
    MAX_KNOTS,
    ROLE_BACKGROUND,
)
from lantern_jax.dynamics.adversary import CLASS_OF_KIND, set_track, zero_track
from lantern_jax.scenarios.families_common import SCENE_SLOT
from lantern_jax.types.world import Scenario

ADVERSARY_FIELD = "adversary"
TRACK_KEYS = ("slot", "accel", "lateral")
ACTOR_GROUPS = ("hazard", "background")
NEAR_ROUTE_M = 20.0  # m, a background vehicle's path must come this close to the ego route
BACKGROUND_LOOKAHEAD_S = 20.0  # s of its path (at its desired speed) a background car may drive
ROUTE_BEYOND_CONFLICT_M = 30.0  # m of ego route past the conflict point that counts as "near"


def _number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and bool(np.isfinite(v))


def adversary_errors(params: dict) -> list[str]:
    """Problems of a parameter dict's optional ``adversary`` field (static checks: types, sizes,
    ranges, distinct slots), each naming the field, e.g. ``"PE.adversary.tracks[0].accel[3]:
    1.5 outside [-1, 1]"``."""
    if ADVERSARY_FIELD not in params:
        return []
    fam, adv = params.get("family"), params[ADVERSARY_FIELD]
    where = f"{fam}.{ADVERSARY_FIELD}"
    if not isinstance(adv, dict):
        return [f"{where}: expected a JSON object, got {adv!r}"]
    errors = [
        f"{where}.{k}: unknown field (known: knot_s, tracks)"
        for k in adv
        if k not in ("knot_s", "tracks")
    ]
    h = adv.get("knot_s")
    lo, hi = KNOT_S_RANGE
    if not _number(h) or not lo <= float(h) <= hi:
        errors.append(f"{where}.knot_s: expected a number in [{lo:g}, {hi:g}], got {h!r}")
    tracks = adv.get("tracks")
    if not isinstance(tracks, list) or not tracks:
        return errors + [f"{where}.tracks: expected a non-empty JSON array, got {tracks!r}"]
    knots, slots = set(), []
    for i, tr in enumerate(tracks):
        at = f"{where}.tracks[{i}]"
        if not isinstance(tr, dict):
            errors.append(f"{at}: expected a JSON object, got {tr!r}")
            continue
        errors += [
            f"{at}.{k}: unknown field (known: {', '.join(TRACK_KEYS)})"
            for k in tr
            if k not in TRACK_KEYS
        ]
        errors += [f"{at}.{k}: missing" for k in TRACK_KEYS if k not in tr]
        slot = tr.get("slot")
        if "slot" in tr:
            if isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < MAX_ACTORS:
                errors.append(
                    f"{at}.slot: expected an integer in [0, {MAX_ACTORS - 1}], got {slot!r}"
                )
            elif slot in slots:
                errors.append(f"{at}.slot: slot {slot} has a track already")
            else:
                slots.append(slot)
        for ch in ("accel", "lateral"):
            seq = tr.get(ch)
            if ch not in tr:
                continue
            if not isinstance(seq, list) or not 1 <= len(seq) <= MAX_KNOTS:
                errors.append(
                    f"{at}.{ch}: expected an array of 1 to {MAX_KNOTS} numbers, "
                    f"got {type(seq).__name__}"
                )
                continue
            knots.add(len(seq))
            for k, v in enumerate(seq):
                if not _number(v) or not -1.0 <= float(v) <= 1.0:
                    errors.append(f"{at}.{ch}[{k}]: {v!r} outside [-1, 1]")
    if len(knots) > 1:
        errors.append(
            f"{where}.tracks: every channel needs the same number of knots, got {sorted(knots)}"
        )
    return errors


def slot_errors(scenario: Scenario, adversary: dict, family: str) -> list[str]:
    """Tracks whose slot holds no actor that can move in the built Route A ``scenario``."""
    errors = []
    valid = np.asarray(scenario.actors.valid, bool)
    kind = np.asarray(scenario.actors.kind)
    for i, tr in enumerate(adversary["tracks"]):
        s = int(tr["slot"])
        if not valid[s]:
            errors.append(f"{family}.{ADVERSARY_FIELD}.tracks[{i}].slot: slot {s} holds no actor")
        elif int(kind[s]) not in CLASS_OF_KIND:
            errors.append(
                f"{family}.{ADVERSARY_FIELD}.tracks[{i}].slot: slot {s} holds a "
                "static object, which takes no track"
            )
    return errors


def with_tracks(
    scenario: Scenario,
    slots: Sequence[int],
    kinds: Sequence[int],
    u_accel: jax.Array,
    u_lateral: jax.Array,
    knot_s: float,
) -> Scenario:
    """``scenario`` with tracks on ``slots`` (differentiable in the actions; jittable).

    Args:
        scenario: a Route A scenario.
        slots: static slot indices (T,).
        kinds: static KIND_* of those slots (T,), which pick their limits.
        u_accel, u_lateral: (T, N) float32 normalised actions in ``[-1, 1]``.
        knot_s: static knot length, s.
    """
    script = scenario.actors
    u_accel, u_lateral = jnp.asarray(u_accel), jnp.asarray(u_lateral)
    track = zero_track(script.num, u_accel.shape[-1], knot_s)
    for i, (s, k) in enumerate(zip(slots, kinds, strict=True)):
        track = set_track(
            track, int(s), int(k), script.v_post[int(s)], u_accel[i], u_lateral[i], knot_s
        )
    return scenario.replace(actors=script.replace(track=track))


def without_effect(scenario: Scenario, knots: int, knot_s: float = 0.5) -> Scenario:
    """``scenario`` with an all-zero track of ``knots`` knots (the same motion, another shape)."""
    track = zero_track(scenario.actors.num, knots, knot_s)
    return scenario.replace(actors=scenario.actors.replace(track=track))


def apply_adversary(a: Scenario, b: Scenario, adversary: dict) -> tuple[Scenario, Scenario]:
    """The pair with an ``adversary`` field applied: tracks on Route A, zeros on Route B."""
    tracks = adversary["tracks"]
    slots = [int(t["slot"]) for t in tracks]
    u_acc = np.asarray([t["accel"] for t in tracks], np.float32)
    u_lat = np.asarray([t["lateral"] for t in tracks], np.float32)
    kinds = [int(np.asarray(a.actors.kind)[s]) for s in slots]
    a = jax.tree.map(jnp.asarray, a)
    a = with_tracks(a, slots, kinds, u_acc, u_lat, float(adversary["knot_s"]))
    return a, without_effect(b, u_acc.shape[1], float(adversary["knot_s"]))


def _path_points(scenario: Scenario, slot: int, seconds: float) -> np.ndarray:
    """Points of a slot's path from its start arc to ``seconds`` of driving at its desired
    speed (or to its end), (n, 2) float64."""
    sc = scenario.actors
    pv = np.asarray(sc.path_valid[slot], bool)
    path = np.asarray(sc.path[slot], np.float64)[pv]
    ps = np.asarray(sc.path_s[slot], np.float64)[pv]
    s0 = float(sc.s_init[slot])
    s1 = min(float(sc.s_end[slot]), s0 + max(float(sc.v_pre[slot]), 1.0) * seconds)
    s = np.linspace(s0, max(s1, s0 + 1e-3), 41)
    return np.stack([np.interp(s, ps, path[:, 0]), np.interp(s, ps, path[:, 1])], axis=1)


def route_distance(scenario: Scenario, points: np.ndarray) -> float:
    """m, the smallest distance of ``points`` (n, 2) to the ego route up to the conflict
    point + :data:`ROUTE_BEYOND_CONFLICT_M`."""
    r = scenario.route
    valid = np.asarray(r.valid, bool)
    keep = valid & (np.asarray(r.s) <= float(scenario.config.s_conflict) + ROUTE_BEYOND_CONFLICT_M)
    route = np.asarray(r.xy, np.float64)[keep]
    return float(np.min(np.linalg.norm(points[:, None, :] - route[None, :, :], axis=-1)))


def adversary_slots(scenario: Scenario, groups: Sequence[str], background: int = 1) -> list[int]:
    """Slots a search may drive, in the order of ``groups``.

    Args:
        scenario: the built Route A scenario (concrete).
        groups: names from :data:`ACTOR_GROUPS`: ``hazard`` — the hazard actor, or, where it is
            a static object (Obstacle Reveal), the scene actor that reveals it; ``background``
            — the ``background`` background vehicles whose next
            :data:`BACKGROUND_LOOKAHEAD_S` seconds of path pass nearest the ego route (within
            :data:`NEAR_ROUTE_M`), nearest first.
        background: how many background vehicles ``background`` names.

    Raises:
        ValueError: for an unknown group, or a group that names no actor in this scenario.
    """
    sc = scenario.actors
    kind, valid = np.asarray(sc.kind), np.asarray(sc.valid, bool)
    out: list[int] = []
    for g in groups:
        if g not in ACTOR_GROUPS:
            raise ValueError(f"actors: {g!r} not one of {', '.join(ACTOR_GROUPS)}")
        if g == "hazard":
            h = int(scenario.config.hazard_index)
            if int(kind[h]) == KIND_STATIC:
                h = SCENE_SLOT
            if not valid[h] or int(kind[h]) == KIND_STATIC:
                raise ValueError("actors: hazard names no moving actor in this scenario")
            out.append(h)
            continue
        role = np.asarray(sc.role)
        cands = [
            i
            for i in range(sc.num)
            if valid[i]
            and role[i] == ROLE_BACKGROUND
            and int(kind[i]) in CLASS_OF_KIND
            and i not in out
        ]
        dist = {
            i: route_distance(scenario, _path_points(scenario, i, BACKGROUND_LOOKAHEAD_S))
            for i in cands
        }
        near = sorted((i for i in cands if dist[i] <= NEAR_ROUTE_M), key=lambda i: dist[i])
        if not near:
            raise ValueError(
                f"actors: no background vehicle's path passes within {NEAR_ROUTE_M:g} m of the "
                "ego route in this scenario"
            )
        out += near[:background]
    return out


def uniform_tracks(scenarios: list[Scenario]) -> list[Scenario]:
    """Scenarios of one batch with tracks of one shape: where any has a track, the others get
    all-zero tracks, and every track is padded to the most knots (zero actions: the commanded
    acceleration of an IDM actor is 0 after its last knot anyway) and its profile to the
    longest one (holding its last state: the actor is back on its script by then)."""
    tracks = [s.actors.track for s in scenarios]
    if all(t is None for t in tracks):
        return scenarios
    n = max(int(t.accel.shape[-1]) for t in tracks if t is not None)
    p = max(int(t.dv.shape[-1]) for t in tracks if t is not None)
    out = []
    for s, t in zip(scenarios, tracks, strict=True):
        t = zero_track(s.actors.num, n) if t is None else t
        out.append(s.replace(actors=s.actors.replace(track=_pad_track(t, n, p))))
    return out


def _pad_track(track: Any, knots: int, points: int) -> Any:
    """A track with zero actions appended up to ``knots`` and its profile held up to
    ``points`` knot times (the arc and lateral offsets continue at the last speeds)."""
    pad_n = knots - int(track.accel.shape[-1])
    pad_p = points - int(track.dv.shape[-1])
    if pad_n == 0 and pad_p == 0:
        return track

    def zeros(x):
        x = np.asarray(x)
        return np.concatenate([x, np.zeros((x.shape[0], pad_n), x.dtype)], axis=1)

    def hold(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[:, -1:], pad_p, axis=1)], axis=1)

    dv, g, q = np.asarray(track.dv), np.asarray(track.g), np.asarray(track.q)
    steps = np.arange(1, pad_p + 1, dtype=np.float32)
    elapsed = np.asarray(track.knot_s, np.float32)[:, None] * steps
    ds = np.concatenate(
        [np.asarray(track.ds), np.asarray(track.ds)[:, -1:] + dv[:, -1:] * elapsed], 1
    )
    dlat = np.asarray(track.dlat)
    dlat = np.concatenate([dlat, dlat[:, -1:] + g[:, -1:] * q[:, -1:] * elapsed], 1)
    return track.replace(
        accel=zeros(track.accel),
        lateral=zeros(track.lateral),
        dv=hold(dv),
        q=hold(q),
        g=hold(g),
        ds=ds,
        dlat=dlat,
    )
