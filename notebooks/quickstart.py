# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # LANTERN in JAX: quickstart
#
# LANTERN measures whether a driving policy makes good use of a **cooperative warning**: a
# short text message from the infrastructure about a hazard that the ego's own camera cannot
# see yet (a pedestrian behind a parked truck, a wrong-way car, ...). Its score, the Cooperative
# Unified Score (CUS, 0-100), rewards safe and early reactions to the hazard and penalises
# collisions, rule violations and braking when there is nothing to brake for.
#
# Every scenario is a matched **pair** of routes, and every pair is run **three times**:
#
# | execution | hazard | warning |
# |---|---|---|
# | Route A, warning | yes | yes |
# | Route A, no warning | yes | no |
# | Route B | no (same road, same traffic) | no |
#
# The CUS of a condition combines its Route A run with Route B (progress, no false braking);
# the **warning gain** is CUS(warning) - CUS(no warning).
#
# Set `LANTERN_NOTEBOOK_SMALL=1` before starting the kernel for a 6-pair run; the default uses
# 24 pairs (about a minute on a 2-core CPU).

# %%
# %matplotlib inline
import os

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
from IPython.display import display

from lantern_jax.evaluation import evaluate
from lantern_jax.policies.registry import get_policy
from lantern_jax.report import format_decomposition, format_family_table, ordered_tables
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.knobs import get_knobs, set_knobs
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.cus import soft_pair_cus
from lantern_jax.sim.rollout import horizon_ticks, rollout
from lantern_jax.sim.settings import DEFAULT_SETTINGS
from lantern_jax.viz import bev_plot, num_valid_ticks, timeline_plot

SMALL = os.environ.get("LANTERN_NOTEBOOK_SMALL", "0") == "1"
print("jax", jax.__version__, "on", jax.default_backend(), "| SMALL =", SMALL)

# %% [markdown]
# ## 1. The built-in suite
#
# `lantern-v3` has 120 pairs (20 per family). Loading it checks every pair against its SHA-256
# content hash. The generation report records how often the privileged `expert` passed the
# dynamic validation of a candidate pair before the suite was filtered.

# %%
suite = load_suite()
report = suite.report
tried = report["dynamic_tried"]
pass_rate = report["expert_pass_rate"]
overall_pass = sum(pass_rate[f] * tried[f] for f in tried) / sum(tried.values())

print(f"suite {suite.suite_id}: {len(suite)} pairs, seed {suite.seed}")
print(f"suite sha256: {suite.suite_sha256}")
print(f"expert pass rate before filtering: {overall_pass:.1%} overall")
rates = {f: round(100 * r, 1) for f, r in pass_rate.items()}
display(pd.DataFrame({"candidates tried": tried, "expert pass rate (%)": rates}).T)

small = suite.subset(1 if SMALL else 4)
print(f"this notebook uses {len(small)} pairs:", ", ".join(p.pair_id for p in small.pairs))

# %% [markdown]
# ## 2. Evaluate the reference policies
#
# * `expert`: a planner that sees every actor, hidden ones included (privileged);
# * `ego`: the same planner limited to what its front camera sees; ignores warnings;
# * `coop`: `ego` plus warning handling (the warned hazard becomes a virtual obstacle or a
#   yield point at the position the warning names).
#
# One call runs all `3 x pairs` executions of each policy in one jitted, vmapped rollout. The
# three policies share their `act` function, so the rollout compiles once.

# %%
result = evaluate(["expert", "ego", "coop"], suite=small, progress=False)
for p in result.manifest["policies"]:
    print(f"{p['name']:>6}: compile {p['seconds_compile']:5.1f} s, run {p['seconds_run']:4.1f} s")

family, decomposition = ordered_tables(result)
display(family.round(1))

# %% [markdown]
# The CUS decomposition: components are means x 100 over the pairs where they apply; `Gate Pass`
# and the gate columns (`-A`: Route A, `-B`: Route B) are percentages of pairs.

# %%
display(decomposition.round(1))

# %% [markdown]
# The same tables as text (what `lantern-jax evaluate` prints):

# %%
print(format_family_table(family))
print()
print(format_decomposition(decomposition))

# %% [markdown]
# `ego` and `expert` ignore the warning, so their warning gain is exactly zero. The full
# per-execution results are in `result.route_table`.

# %%
result.route_table.head()

# %% [markdown]
# ## 3. One pair up close: Pedestrian Emergence
#
# A pedestrian hidden behind a parked truck steps into the ego lane. We roll out `coop` on
# Route A with and without the warning, recording every tick. `rollout` is a plain function of
# the scenario, so one jitted function serves both conditions: only `config.warning_enabled`
# differs.

# %%
pair = next(p for p in small.pairs if p.family == "PE")
world_a, world_b, _ = build_pair(pair.params)
world_a_nowarn = world_a.replace(config=world_a.config.replace(warning_enabled=jnp.asarray(False)))

coop = get_policy("coop")
coop_params = coop.init(jax.random.PRNGKey(0))
num_ticks = horizon_ticks(float(world_a.config.timeout_s))  # the route's timeout
run = jax.jit(lambda w: rollout(w, coop, coop_params, num_ticks, record=True))

final_w, rec_w = jax.device_get(run(world_a))
final_nw, rec_nw = jax.device_get(run(world_a_nowarn))
proto_w, proto_nw = final_w.protocol, final_nw.protocol

print(f"pair {pair.pair_id} ({pair.weather}), horizon {num_ticks} ticks")
for name, final, rec in (("warning", final_w, rec_w), ("no warning", final_nw, rec_nw)):
    print(
        f"{name:>10}: ends after {num_valid_ticks(rec)} ticks, "
        f"event onset t = {float(final.protocol.t_event):.2f} s, "
        f"collision: {bool(final.telemetry.collision.collided)}"
    )

# %% [markdown]
# Bird's-eye view at the first tick with an active warning: the pedestrian (red, ringed) is
# still hidden behind the parked truck (a dark grey occluder of the map), the warning text and
# its grounded position (pink x) are shown, and the planned waypoints (purple dots) already slow
# down.

# %%
i_warn = int(np.argmax(rec_w.warning_active))
display(bev_plot(world_a, rec_w, i_warn, title="PE, warning first active"))

# %% [markdown]
# At the event onset the pedestrian starts to cross.

# %%
i_event = int(np.searchsorted(rec_w.t, float(proto_w.t_event)))
display(bev_plot(world_a, rec_w, i_event, title="PE, event onset"))

# %% [markdown]
# Speed and acceleration of both conditions; the warning's delivery is shaded, vertical lines
# mark event onset, warning termination and clearance (solid: warning run, dashed: no warning).

# %%
display(timeline_plot(rec_w, rec_nw, proto_w, proto_nw, title=f"{pair.pair_id}: coop"))

# %% [markdown]
# ## 4. Gradients through the simulator
#
# The soft CUS replaces hard gates and minima by smooth ones, so the whole rollout can be
# differentiated. Here: the derivative of one pair's soft CUS with respect to the pedestrian's
# crossing speed (the `hazard_speed` knob of `lantern_jax.scenarios.knobs`). Both routes are
# rolled out for a fixed 400 ticks (20 s, enough for both executions of this pair to end; an
# unfinished route fails the completion gate and scores 0). Compiling the reverse pass takes
# longer than the forward one.

# %%
GRAD_TICKS = 400
TEMPERATURE = 0.05
SOFT_SETTINGS = DEFAULT_SETTINGS.with_temperature(TEMPERATURE)


def soft_cus(crossing_speed):
    w_a = set_knobs(world_a, hazard_speed=crossing_speed)
    final_a, _ = rollout(w_a, coop, coop_params, GRAD_TICKS, settings=SOFT_SETTINGS)
    final_b, _ = rollout(world_b, coop, coop_params, GRAD_TICKS, settings=SOFT_SETTINGS)
    cus = soft_pair_cus(final_a.telemetry, final_b.telemetry, world_a.config.d_safe, TEMPERATURE)
    return cus, (final_a.done, final_b.done)


grad_fn = jax.jit(jax.value_and_grad(soft_cus, has_aux=True))
speed = get_knobs(world_a)["hazard_speed"]
(cus, (done_a, done_b)), dcus = grad_fn(speed)
print(f"crossing speed {float(speed):.2f} m/s, routes ended: A {bool(done_a)}, B {bool(done_b)}")
print(f"soft CUS = {float(cus):.2f}")
print(f"d soft CUS / d crossing speed = {float(dcus):+.3f} per m/s")

# %% [markdown]
# A faster crossing lowers the score here. This is the derivative of the smoothed score along
# the simulated trajectory; the discrete switches of the simulator (the event trigger, protocol
# transitions) are not differentiated, so it can differ from a finite difference of the score.
#
# ## 5. An ablation in one line
#
# `late_onset` delivers the warning only from the physical event on, instead of from the
# warning point. The batch shapes are unchanged, so the compiled rollout is reused.

# %%
late = evaluate(["coop"], suite=small, ablation="late_onset", progress=False)

standard_coop = family[family["model"] == "coop"].assign(ablation="none")
late_coop = ordered_tables(late)[0].assign(ablation="late_onset")
comparison = pd.concat([standard_coop, late_coop], ignore_index=True)
display(comparison.set_index(["ablation", "condition"]).drop(columns="model").round(1))
