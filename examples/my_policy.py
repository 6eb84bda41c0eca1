"""A policy of your own, in one file: the template to copy.

Evaluate it on the built-in suite, with the result files, schema and manifest of any run::

    lantern-jax evaluate --policy examples/my_policy.py:POLICY --out results-mine

(``--policy examples/my_policy.py:POLICY,coop`` puts it beside a reference policy.)  The
manifest records this file's path and SHA-256, so a result folder names the code behind its
rows.  From Python, ``lantern_jax.evaluate([POLICY])`` does the same.

What a policy is (:class:`lantern_jax.Policy`):

* ``init(key) -> params`` — any pytree of arrays (weights, thresholds), built once;
* ``act(params, obs) -> waypoints`` — ONE scenario's observation in, a ``(10, 2)`` float32
  array out: the ego's next ten positions, 0.25 s apart, in metres in the ego frame (x ahead,
  y to the right).  It is traced by JAX, so write it with ``jax.numpy`` and no Python branching
  on array values; the simulator ``vmap``s it over the batch and a controller tracks the
  waypoints;
* ``sensors`` — what ``obs`` holds.  ``"front_camera"`` (always): ego state, the route and the
  actors the front camera sees (``obs.visible``; unseen actors' fields are zero);
  ``"warning"``: the delivered warning as ``obs.warning_tokens`` (token ids, padded with
  ``lantern_jax.types.language.PAD_ID``) and ``obs.warning_values`` (the numbers in the text);
  without it every token is padding.  ``"surround_rig"`` adds the six-camera view.  The fields,
  their shapes and units are listed in :mod:`lantern_jax.types.observation`;
* ``init_carry(params) -> carry`` (optional) — a policy with memory: ``act(params, carry,
  obs)`` then returns ``(waypoints, new_carry)``.

This example drives with the reference camera planner (the ``ego`` policy's) and, while any
warning text is delivered, follows its waypoints at half their speed.  It reads the warning
only as text (here: whether there is any), as the benchmark's premise asks.
"""

from __future__ import annotations

import jax.numpy as jnp

from lantern_jax.policies.base import Policy
from lantern_jax.policies.reference import reference_act, reference_params
from lantern_jax.types.observation import FRONT_CAMERA, WARNING, warning_delivered

#: Fraction of the planner's speed kept while a warning is delivered.
CAUTION = 0.5


def init(key):
    """The planner's parameters (its thresholds and limits; nothing is learned here)."""
    return reference_params(key)


def act(params, obs):
    """(10, 2) ego-frame waypoints, m: the planner's, shortened while a warning is delivered."""
    waypoints = reference_act(params, obs)  # plans on the camera's view only
    warned = warning_delivered(obs)  # () bool: a text is being delivered
    return jnp.where(warned, CAUTION * waypoints, waypoints)


POLICY = Policy(
    "cautious-when-warned",
    init,
    act,
    "the camera planner at half speed while any warning text is delivered",
    sensors=(FRONT_CAMERA, WARNING),
)
