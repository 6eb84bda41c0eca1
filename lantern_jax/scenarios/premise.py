"""The benchmark's premise as a static validation rule: the warning must carry what the camera
cannot see.

For Pedestrian Emergence, Obstacle Reveal and both wrong-way families the hazard must be hidden
from the ego's 110-degree front camera when the ego reaches the warning point (Vehicle Cut-In's
vehicle is meant to be visible — its warning adds the intent — and Right-Turn Yield's cross
traffic is often visible, as the paper says).  :func:`hazard_visible_at_warning` places the ego
on its route at the warning point, heading along the route, and the actors where their scripts
put them before the event, and runs the very sensor code the simulator runs
(:func:`lantern_jax.sensors.visibility.visible_actors`, with the map's occluders) on the built
Route A scenario.

When the ego reaches the warning point depends on the policy, so a family names the times at
which the pre-event world can look like that (``meta["canonical"]["premise_times"]``): one time
where nothing that could hide the hazard moves before the event (PE, LWW, RWW: the hazard and
the occluders stand still), several for Obstacle Reveal (the lead van anywhere between touching
the ego and its reveal point).  The hazard must be hidden at all of them.  IDM traffic stands at
its start (it never shares the ego's lane in these families).

Where the hazard and everything that could hide it stand still until the event (PE, LWW, RWW)
the rule also asks the hazard to be hidden from every route point before the warning point
(every ``APPROACH_STEP_M``): the paper's premise is that the warning arrives before the camera
has seen the hazard at all.  For Obstacle Reveal that part depends on how closely the policy
follows the van, so it is measured in the rollout (``hazard_hidden_before_warning``) instead.

A family registered from user code names its rule in its record (:data:`PREMISE_RULES`:
``"whole_approach"`` as PE, ``"at_warning_point"`` as OR, or ``"none"`` as VC and RTY).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lantern_jax.core.constants import FRONT_CAMERA_FOV, MOTION_IDM
from lantern_jax.core.times import NEVER
from lantern_jax.dynamics.actors import scripted_states, start_state
from lantern_jax.maths import polyline
from lantern_jax.scenarios.family_registry import FAMILY_REGISTRY
from lantern_jax.sensors.visibility import camera_pose, visible_actors
from lantern_jax.types.world import Scenario

APPROACH_STEP_M = 2.0  # m between checked ego positions on the approach

#: The premise rules a family can have: none (the hazard may be visible), hidden at the warning
#: point (at every premise time), or hidden at the warning point and from every route point
#: before it (for scenes where nothing that could hide the hazard moves before the event).
PREMISE_NONE = "none"
PREMISE_AT_WARNING = "at_warning_point"
PREMISE_WHOLE_APPROACH = "whole_approach"
PREMISE_RULES = (PREMISE_NONE, PREMISE_AT_WARNING, PREMISE_WHOLE_APPROACH)


def premise_rule(code: str) -> str:
    """The premise rule of a family (one of :data:`PREMISE_RULES`): its registry entry's
    (:data:`lantern_jax.scenarios.family_registry.FAMILY_REGISTRY`)."""
    return FAMILY_REGISTRY.entry(code).premise


def _visible_at(scenario: Scenario, arc: jax.Array, t: jax.Array) -> jax.Array:
    """() bool: the hazard is visible from the ego at route arc ``arc`` with the actors as their
    scripts place them at time ``t`` before the event."""
    r, script = scenario.route, scenario.actors
    xy, yaw = polyline.interpolate(r.xy, r.s, r.valid, arc)
    _, _, _, sc_xy, sc_yaw, active = scripted_states(script, t, jnp.asarray(NEVER, jnp.float32))
    start = start_state(script)
    is_idm = script.motion == MOTION_IDM
    a_xy = jnp.where(is_idm[:, None], start.xy, sc_xy)
    a_yaw = jnp.where(is_idm, start.yaw, sc_yaw)
    on = script.valid & (active | is_idm)
    cam_xy, cam_yaw = camera_pose(xy, yaw)
    vis = visible_actors(
        cam_xy, cam_yaw, a_xy, a_yaw, script.extent, on, FRONT_CAMERA_FOV,
        scenario.config.sensing_range, scenario.occluders,
    )  # fmt: skip
    return vis[scenario.config.hazard_index]


_visible_batch = jax.jit(jax.vmap(_visible_at, in_axes=(None, 0, 0)))
QUERY_BLOCK = 64  # queries are padded to a multiple of this: one compilation serves every call


def hazard_visibility(scenario: Scenario, arcs, times) -> np.ndarray:
    """Front-camera visibility of the hazard for ego positions and actor times.

    Args:
        scenario: a built Route A scenario.
        arcs: (n,) float, m, ego route arcs.
        times: (n,) float, s, times before the event at which the actors are placed.

    Returns:
        (n,) bool, True where the camera sees the hazard.
    """
    arcs = np.asarray(arcs, np.float32).reshape(-1)
    times = np.asarray(times, np.float32).reshape(-1)
    n = arcs.shape[0]
    pad = -n % QUERY_BLOCK
    arcs = np.concatenate([arcs, np.full(pad, arcs[-1], np.float32)])
    times = np.concatenate([times, np.full(pad, times[-1], np.float32)])
    return np.asarray(_visible_batch(scenario, jnp.asarray(arcs), jnp.asarray(times)))[:n]


def hazard_visible_at_warning(scenario: Scenario, meta: dict) -> np.ndarray:
    """(k,) bool: visibility of the hazard at the warning point for each of the family's
    premise times (``meta["canonical"]["premise_times"]``, default ``[0.0]``)."""
    times = np.asarray(meta["canonical"].get("premise_times", [0.0]), np.float32)
    arcs = np.full_like(times, float(scenario.config.s_warn))
    return hazard_visibility(scenario, arcs, times)


def premise_error(scenario: Scenario, meta: dict) -> str | None:
    """The premise rule: None when it holds (or does not apply to the family), else a message
    naming the family and the first time at which the hazard is visible."""
    fam = meta["family"]
    rule = premise_rule(fam)
    if rule == PREMISE_NONE:
        return None
    seen = hazard_visible_at_warning(scenario, meta)
    if seen.any():
        t = float(np.asarray(meta["canonical"].get("premise_times", [0.0]))[np.argmax(seen)])
        return (f"{fam}: premise violated: the hazard is visible to the front camera at the "
                f"warning point (actors at t = {t:.2f} s before the event)")  # fmt: skip
    if rule == PREMISE_WHOLE_APPROACH:
        arcs = np.arange(0.0, float(scenario.config.s_warn), APPROACH_STEP_M)
        seen = hazard_visibility(scenario, arcs, np.zeros_like(arcs))
        if seen.any():
            return (f"{fam}: premise violated: the hazard is visible to the front camera from "
                    f"route arc {arcs[np.argmax(seen)]:.0f} m, before the warning point at "
                    f"{float(scenario.config.s_warn):.1f} m")  # fmt: skip
    return None
