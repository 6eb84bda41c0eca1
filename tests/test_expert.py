"""The privileged forecast (what only the ``expert`` reads) and the expert's own rules.

Hand-built scenes with expected values derived in comments; the forecast of a scripted actor is
compared with the actor's actual future (the simulator's own actor stepping).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lantern_jax.core.constants import (
    DT,
    KIND_PEDESTRIAN,
    MOTION_IDM,
    ROLE_HAZARD,
    TRIGGER_CLOCK,
    TRIGGER_EVENT,
)
from lantern_jax.core.times import NEVER
from lantern_jax.dynamics.actors import scripted_states, step_actors
from lantern_jax.dynamics.forecast import earliest_event_time, forecast_actors
from lantern_jax.dynamics.lights import light_states
from lantern_jax.policies import expert as E
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.handmade import ActorSpec, straight_scene
from lantern_jax.sim.observe import observe, privileged_view
from lantern_jax.sim.state import init_state
from lantern_jax.types.observation import FORECAST_DT, FORECAST_STEPS
from lantern_jax.types.world import present

K = FORECAST_STEPS


def scripted_scene():
    """Three actors with known futures:

    0. a car 30 m ahead in the left lane (y = 3.5, westbound lane) driving east at 2 m/s that,
       on a clock trigger at 1.0 s, speeds up to 6 m/s and shifts 1.5 m to its left over 2 s;
    1. a pedestrian 40 m ahead, 6 m to the right, crossing at 3 m/s on the protocol's event;
    2. an IDM car 20 m ahead in the right lane at its desired speed 7 m/s (no leader, no light,
       no stop at its path end: it keeps 7 m/s exactly).
    """
    car = ActorSpec(
        path=np.array([[30.0, 3.5], [130.0, 3.5]]), v_pre=2.0, v_post=6.0,
        trigger=TRIGGER_CLOCK, trigger_delay=1.0, lat_shift=1.5, lat_duration=2.0,
    )  # fmt: skip
    ped = ActorSpec(
        path=np.array([[40.0, -6.0], [40.0, 16.0]]), extent=(0.3, 0.3), kind=KIND_PEDESTRIAN,
        role=ROLE_HAZARD, v_post=3.0, trigger=TRIGGER_EVENT, despawn_at_end=True,
    )  # fmt: skip
    idm = ActorSpec(path=np.array([[20.0, -3.5], [220.0, -3.5]]), motion=MOTION_IDM, v_pre=7.0,
                    despawn_at_end=True)  # fmt: skip
    return straight_scene(
        [car, ped, idm], length=150.0, speed=8.0, s_warn=20.0, s_event=29.0, s_conflict=40.0,
        hazard_index=1,
    )  # fmt: skip


def actual_future(world, t_event=NEVER):
    """The actors' states at t = k DT, k = 1..K, stepped by the simulator's own actor update
    (the ego stands at its start; the IDM car's leader search finds nothing ahead of it)."""
    actors, script, out = world.actors0, world.actors, []
    step = jax.jit(step_actors)
    for k in range(1, K + 1):
        t = jnp.float32(k * DT)
        actors = step(actors, script, t, jnp.float32(t_event), light_states(world.lights, t),
                      world.ego0.xy, world.ego0.yaw, world.ego0.speed)  # fmt: skip
        out.append(jax.device_get(actors))
    return out


def test_forecast_of_scripted_and_idm_actors_matches_their_future():
    world = scripted_scene()
    on = present(world.actors, world.actors0)
    never = jnp.float32(NEVER)
    fc = jax.jit(forecast_actors, static_argnums=(6, 7))(
        world.actors, world.actors0, on, jnp.float32(0.0), never, never, K, FORECAST_DT
    )
    future = actual_future(world)
    for i in (0, 2):  # the clock-triggered car (exact closed form), the IDM car
        want = np.stack([np.asarray(a.xy[i]) for a in future])
        got = np.stack([np.asarray(fc.x[i]), np.asarray(fc.y[i])], -1)
        np.testing.assert_allclose(got, want, atol=2e-4, err_msg=f"actor {i}")
        heading = np.stack([np.asarray(fc.ux[i]), np.asarray(fc.uy[i])], -1)
        yaw = np.stack([np.asarray(a.yaw[i]) for a in future])
        np.testing.assert_allclose(heading, np.stack([np.cos(yaw), np.sin(yaw)], -1), atol=2e-4)
        # an exact forecast is the actor's own box
        np.testing.assert_allclose(fc.half_length[i], world.actors.extent[i, 0], atol=1e-5)
        np.testing.assert_allclose(fc.half_width[i], world.actors.extent[i, 1], atol=1e-5)
    # The car at 2 s: 1 s at 2 m/s, then 1 s at 6 m/s -> x = 30 + 2 + 6 = 38; half of its
    # smoothstep shift -> y = 3.5 + 0.75
    np.testing.assert_allclose([fc.x[0, 39], fc.y[0, 39]], [38.0, 4.25], atol=1e-4)
    # The waiting pedestrian (event pending, warning point not reached): stays where it is.
    np.testing.assert_allclose(fc.x[1], 40.0, atol=1e-5)
    np.testing.assert_allclose(fc.y[1], -6.0, atol=1e-5)
    assert np.asarray(fc.valid[:3]).all() and not np.asarray(fc.valid[3:]).any()


@pytest.mark.parametrize("delay", [0.0, 0.35, 1.2, None])
def test_pending_event_forecast_covers_every_start(delay):
    # Past the warning point the event may begin any moment: the forecast box at each step
    # must contain the pedestrian's actual box whenever the event starts (or never).
    world = scripted_scene()
    on = present(world.actors, world.actors0)
    t_now = jnp.float32(0.0)
    t_early = earliest_event_time(t_now, t_now, jnp.float32(NEVER))  # warning point reached
    assert float(t_early) == 0.0
    fc = forecast_actors(world.actors, world.actors0, on, t_now, jnp.float32(NEVER), t_early, K,
                         FORECAST_DT)  # fmt: skip
    t_event = NEVER if delay is None else delay
    times = jnp.arange(1, K + 1, dtype=jnp.float32) * DT
    _, _, _, xy, _, _ = jax.vmap(lambda t: scripted_states(world.actors, t, t_event))(times)
    ped = np.asarray(xy[:, 1])  # (K, 2)
    cx, cy = np.asarray(fc.x[1]), np.asarray(fc.y[1])
    ux, uy = np.asarray(fc.ux[1]), np.asarray(fc.uy[1])
    along = (ped[:, 0] - cx) * ux + (ped[:, 1] - cy) * uy
    across = (ped[:, 1] - cy) * ux - (ped[:, 0] - cx) * uy
    # the pedestrian's own half extent 0.3 must fit inside the forecast box
    assert np.all(np.abs(along) + 0.3 <= np.asarray(fc.half_length[1]) + 1e-4)
    assert np.all(np.abs(across) + 0.3 <= np.asarray(fc.half_width[1]) + 1e-4)
    # At 2 s, started at once, it would be 6 m into its crossing: the box spans y -6.3 .. 0.3
    np.testing.assert_allclose(fc.half_length[1, -1], 3.3, atol=1e-4)


def test_earliest_event_time():
    never = jnp.float32(NEVER)
    assert float(earliest_event_time(jnp.float32(5.0), never, never)) == NEVER
    assert float(earliest_event_time(jnp.float32(5.0), jnp.float32(4.2), never)) == 5.0
    # without the anti-deadlock rule only the ego's own arrival starts the event
    no_force = jnp.bool_(False)
    assert float(earliest_event_time(jnp.float32(5.0), jnp.float32(4.2), never, no_force)) == NEVER
    assert float(earliest_event_time(jnp.float32(5.0), jnp.float32(4.2), jnp.float32(4.6),
                                     no_force)) == pytest.approx(4.6)  # fmt: skip
    t_ev = float(earliest_event_time(jnp.float32(5.0), jnp.float32(4.2), jnp.float32(4.9)))
    assert t_ev == pytest.approx(4.9)


def test_privileged_view_is_the_forecast_in_the_ego_frame():
    world = scripted_scene()
    state = init_state(world)
    view = jax.jit(privileged_view)(world, state)
    obs = jax.jit(lambda w, s: observe(w, s, ("privileged",)))(world, state)
    assert obs.privileged is not None
    np.testing.assert_array_equal(obs.privileged.forecast_x, view.forecast_x)
    # The ego stands at the origin facing +x: the ego frame is the world frame with y mirrored.
    on = present(world.actors, world.actors0)
    never = jnp.float32(NEVER)
    fc = forecast_actors(world.actors, world.actors0, on, jnp.float32(0.0), never, never, K,
                         FORECAST_DT)  # fmt: skip
    np.testing.assert_allclose(view.forecast_x[:3], fc.x[:3], atol=1e-4)
    np.testing.assert_allclose(view.forecast_y[:3], -np.asarray(fc.y[:3]), atol=1e-4)
    np.testing.assert_allclose(view.forecast_uy[:3], -np.asarray(fc.uy[:3]), atol=1e-5)
    shapes = {f: getattr(view, f).shape for f in ("forecast_x", "forecast_valid")}
    assert shapes == {"forecast_x": (16, K), "forecast_valid": (16, K)}


# ---------------------------------------------------------------------------------------------
# the expert's rules
# ---------------------------------------------------------------------------------------------
def test_boxes_overlap_goldens():
    # two 2 x 1 boxes (half extents 1, 0.5) along x: centres 1.9 apart overlap, 2.1 do not;
    # rotated 90 deg, the second spans 0.5 along x: centres 1.4 apart overlap, 1.6 do not
    def box(x, y, ux, uy):
        return tuple(jnp.float32(v) for v in (x, y, ux, uy, 1.0, 0.5))

    a = box(0, 0, 1, 0)
    assert bool(E.boxes_overlap(a, box(1.9, 0, 1, 0)))
    assert not bool(E.boxes_overlap(a, box(2.1, 0, 1, 0)))
    assert bool(E.boxes_overlap(a, box(1.4, 0, 0, 1)))
    assert not bool(E.boxes_overlap(a, box(1.6, 0, 0, 1)))
    # 45 deg: the rotated box reaches (1 + 0.5) / sqrt(2) = 1.06 along x
    r = float(np.sqrt(0.5))
    assert bool(E.boxes_overlap(a, box(2.0, 0, r, r)))
    assert not bool(E.boxes_overlap(a, box(2.1, 0, r, r)))


def test_ramp_arcs():
    # 5 m/s ramping up at 2 m/s^2 to 8 m/s (reached at 1.5 s): 1 s -> 5 + 1 = 6 m;
    # 2 s -> 5 * 1.5 + 2.25 + 8 * 0.5 = 13.75 m; braking 8 m/s at 8 m/s^2 stops after 4 m
    t = jnp.asarray([1.0, 2.0], jnp.float32)
    np.testing.assert_allclose(E.ramp_arcs(5.0, 8.0, 2.0, 3.0, t), [6.0, 13.75], atol=1e-5)
    np.testing.assert_allclose(E.ramp_arcs(8.0, 0.0, 2.0, 8.0, t), [4.0, 4.0], atol=1e-5)


def _expert_observation(world):
    return jax.jit(lambda w: observe(w, init_state(w), ("privileged",)))(world)


def test_expert_cruises_on_an_empty_road_and_brakes_for_a_crossing_car():
    expert = get_policy("expert")
    pp = expert.init(jax.random.PRNGKey(0))
    act = jax.jit(expert.act)
    empty = straight_scene([], speed=8.0)
    wps = np.asarray(act(pp, _expert_observation(empty)))
    # at its reference speed: 10 waypoints 2 m apart straight ahead
    np.testing.assert_allclose(wps[:, 0], 2.0 * np.arange(1, 11), atol=0.05)
    np.testing.assert_allclose(wps[:, 1], 0.0, atol=1e-4)
    # a car crossing 14 m ahead from the right at 6 m/s reaches the ego lane within 2 s
    crossing = ActorSpec(path=np.array([[16.0, -9.0], [16.0, 30.0]]), v_pre=6.0)
    wps = np.asarray(act(pp, _expert_observation(straight_scene([crossing], speed=8.0))))
    assert wps[-1, 0] < 8.0  # full braking: 8 m/s at 8 m/s^2 stops within 4 m
    # a walker doing the same gets IDM, not full braking: the plan still slows down
    walker = ActorSpec(path=np.array([[16.0, -9.0], [16.0, 30.0]]), v_pre=3.0, extent=(0.3, 0.3),
                       kind=KIND_PEDESTRIAN)  # fmt: skip
    wps_w = np.asarray(act(pp, _expert_observation(straight_scene([walker], speed=8.0))))
    assert 8.0 < wps_w[-1, 0] < 19.0


def test_expert_does_not_brake_for_a_vehicle_that_braking_cannot_avoid():
    # A car 7 m behind in the ego lane at 12 m/s (scripted, it does not yield): stopping
    # would only let it hit the ego, so the expert keeps its speed (a trailer, PDM-Lite).
    behind = ActorSpec(path=np.array([[-7.0, 0.0], [200.0, 0.0]]), v_pre=12.0)
    expert = get_policy("expert")
    pp = expert.init(jax.random.PRNGKey(0))
    wps = np.asarray(
        jax.jit(expert.act)(pp, _expert_observation(straight_scene([behind], speed=8.0)))
    )
    assert wps[-1, 0] > 19.0


def test_expert_waits_for_a_vehicle_that_driving_on_cannot_escape_either():
    # A waiting ego; a car from the left turns into the ego lane 6 m ahead and comes down it
    # (a wrong-way car on the ego's own path).  Stopped, the ego is reached within 2 s, but
    # driving on meets the car sooner: braking does not escape it, driving on does not either,
    # so the expert stays (it meets the car at rest, or not at all where the script ends).
    wrong_way = ActorSpec(path=np.array([[6.0, 8.0], [6.0, 0.0], [-40.0, 0.0]]), v_pre=8.0)
    scene = straight_scene([wrong_way], speed=8.0)
    scene = scene.replace(ego0=scene.ego0.replace(speed=jnp.float32(0.0)))
    expert = get_policy("expert")
    pp = expert.init(jax.random.PRNGKey(0))
    obs = _expert_observation(scene)
    _, stop, go_tight = jax.jit(E.overlaps)(pp, obs, jnp.float32(8.0))
    assert bool(stop[0]) and bool(go_tight[0])  # neither stopping nor driving on escapes
    wps = np.asarray(jax.jit(expert.act)(pp, obs))
    assert wps[-1, 0] < 0.5
