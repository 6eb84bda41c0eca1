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
import numpy as np
import pandas as pd

try:
    from IPython.display import display
except ImportError:  # run as a plain script (python notebooks/...py): print what a cell shows
    display = print

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.policies.registry import get_policy
from lantern_jax.report import format_decomposition, format_family_table, ordered_tables
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.knobs import get_knobs, set_knobs
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.cus import soft_pair_cus
from lantern_jax.sim.rollout import rollout
from lantern_jax.sim.settings import DEFAULT_SETTINGS
from lantern_jax.viz import bev_plot, num_valid_ticks, plot_pair, record_pair

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
# three policies run in one compiled program (a policy switch), so the simulator compiles once.

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
# A pedestrian hidden behind a parked truck steps into the ego lane. `record_pair` rolls out
# the pair's three executions under `coop` (Route A with and without the warning, Route B) in
# one jitted call, recording every tick.

# %%
pair = next(p for p in small.pairs if p.family == "PE")
recorded = record_pair("coop", pair.pair_id)
warned = recorded.warning

print(f"pair {pair.pair_id} ({pair.weather}), horizon {warned.record.t.shape[0]} ticks")
for ex in (warned, recorded.no_warning):
    print(
        f"{ex.condition:>10}: ends after {num_valid_ticks(ex.record)} ticks, "
        f"event onset t = {float(ex.final.protocol.t_event):.2f} s, collision: {ex.collided}"
    )

# %% [markdown]
# Bird's-eye view at the first tick with an active warning: the pedestrian (red, ringed) is
# still hidden behind the parked truck (a dark grey occluder of the map), the warning text and
# its grounded position (pink x) are shown, and the planned waypoints (purple dots) already slow
# down.

# %%
i_warn = int(np.argmax(warned.record.warning_active))
display(bev_plot(warned.scenario, warned.record, i_warn, title="PE, warning first active"))

# %% [markdown]
# `plot_pair` shows one execution at its most telling tick (its first collision, else the
# closest approach to the hazard) next to the speed and acceleration of both conditions: the
# warning's delivery shaded, vertical lines at event onset, warning termination and clearance
# (solid: warning run, dashed: no warning), collisions in red and each execution's first failed
# gate. Without the warning, `coop` meets the pedestrian only when it steps out:

# %%
display(plot_pair(recorded, condition="no-warning"))

# %% [markdown]
# With the warning it slows down early and lets the pedestrian cross:

# %%
display(plot_pair(recorded, condition="warning"))

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
world_a, world_b, _ = build_pair(pair.params)
coop = get_policy("coop")
coop_params = coop.init(jax.random.PRNGKey(0))

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
