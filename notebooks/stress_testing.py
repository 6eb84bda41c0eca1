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
# # Stress testing a driving policy
#
# The simulator is differentiable, so we can search the **scenario** for the hazards that break
# a policy: how fast the pedestrian walks, how late the cut-in car starts, where the wrong-way
# car appears. Every family exposes a few continuous **knobs** with documented ranges
# (`lantern_jax.scenarios.families.KNOB_RANGES`); a search works on an unconstrained vector that
# a sigmoid maps inside the ranges, so every candidate is a valid scene.
#
# Three searches run at the **same wall-clock budget** on the same restarts and are verified the
# same way (the exact CUS and gates; a failure counts only if the privileged expert can still
# drive the scene):
#
# * **gradient** — Adam on a smooth surrogate (soft minimum clearance to the hazard) rolled out
#   through the simulator, with randomized smoothing and a bias test that falls back from the
#   pathwise gradient to a zeroth-order estimate where the closed loop is discontinuous;
# * **random** search inside the ranges;
# * **CMA-ES**.
#
# Set `LANTERN_NOTEBOOK_SMALL=1` for a few-second budget (the test does); the default gives
# every method 30 s.

# %%
# %matplotlib inline
import os

import numpy as np
from IPython.display import display

from lantern_jax.scenarios.families import KNOB_RANGES
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.stress.report import StressConfig, comparison_table, stress_test
from lantern_jax.viz.stress import convergence_plot

SMALL = os.environ.get("LANTERN_NOTEBOOK_SMALL") == "1"
print(f"SMALL = {SMALL}")
for family, knobs in KNOB_RANGES.items():
    print(family, {k: tuple(round(x, 2) for x in r) for k, r in knobs.items()})

# %% [markdown]
# ## A pedestrian that the camera-only policy cannot handle
#
# `ego` plans only with what its front camera sees. In Pedestrian Emergence the pedestrian is
# hidden behind a parked truck until it steps out, so some crossing speeds and trigger delays
# leave `ego` no room at all. Which ones, and how fast does each method find them?

# %%
suite = load_suite()
pair = next(p for p in suite.pairs if p.family == "PE")
cfg = StressConfig(
    budget_s=3.0 if SMALL else 30.0,
    restarts=2 if SMALL else 8,
    samples=2 if SMALL else 8,
)
problem, traces = stress_test(pair, "ego", cfg, suite=suite, progress=True)
table = comparison_table(traces)
display(table)

# %% [markdown]
# The convergence plot: the lowest exact CUS found so far, against evaluations (closed-loop
# rollouts of Route A) and against seconds. The dotted line is the failure threshold.

# %%
display(convergence_plot(traces, f"{pair.pair_id}: ego, warning condition"))

# %% [markdown]
# What was found: the knob values of each restart's first verified failure.

# %%
for t in traces:
    for f in t.found:
        values = problem.space.as_dict(np.asarray(f["values"]))
        print(
            f"{t.method:>8} restart {f['restart']}: CUS {f['cus']:.1f} at",
            {k: round(v, 2) for k, v in values.items()},
        )
