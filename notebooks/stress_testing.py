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
# # Stress testing a driving policy with adversarial actors
#
# The simulator is differentiable, so we can search the **scenario** for the hazards that break
# a policy. Two search spaces share one interface (`lantern_jax.apps.stress.space`):
#
# * the family's few continuous **knobs** (the pedestrian's speed, the cut-in's delay, ...;
#   `lantern_jax.scenarios.families.KNOB_RANGES`);
# * **adversarial tracks** of the scenario's actors (`--space adversary`): after its trigger an
#   actor gets, per knot of `knot_s` seconds, a bounded longitudinal acceleration and a lateral
#   target (sideways speed for a walker, heading offset for a vehicle) through a kinematic model
#   in closed form (`lantern_jax.dynamics.adversary`), within limits per kind taken from real
#   values; zero actions are the benchmark's own scene. With 16 knots an actor adds 32
#   dimensions.
#
# A failure counts only when it is **plausible** (`lantern_jax.apps.stress.plausibility`): the
# policy fails a gate or scores below 50 while the privileged expert drives the same scene with
# margin (every gate, 0.5 m from every watched actor), and no actor with a track freezes in the
# ego's path for more than 2 s, leaves the road or exceeds its limits. Three searches run
# interleaved at the same budget and are verified the same way:
#
# * **gradient** — Adam on a smooth surrogate (the policy's soft collision margin, a hinge on
#   the expert's soft distance, soft plausibility penalties) rolled out through the simulator,
#   each iterate verified;
# * **random** search (uniform draws in the space);
# * **CMA-ES** on the same surrogate's hard expression.
#
# Set `LANTERN_NOTEBOOK_SMALL=1` for a small setting (the test does): 8 knots, 2 restarts,
# 8 rollouts per restart and method.

# %%
# %matplotlib inline
import os

import numpy as np
import pandas as pd

try:
    from IPython.display import display
except ImportError:  # run as a plain script (python notebooks/...py): print what a cell shows
    display = print

from lantern_jax.apps.stress import catalogue
from lantern_jax.apps.stress.report import (
    SUMMARY_COLUMNS,
    StressConfig,
    comparison_table,
    gradient_quality,
    stress_test,
)
from lantern_jax.dynamics.adversary import KINEMATIC_LIMITS
from lantern_jax.scenarios.families import KNOB_RANGES
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.viz.stress import catalogue_figure, convergence_plot

SMALL = os.environ.get("LANTERN_NOTEBOOK_SMALL") == "1"
print(f"SMALL = {SMALL}")
for family, knobs in KNOB_RANGES.items():
    print(family, {k: tuple(round(x, 2) for x in r) for k, r in knobs.items()})
display(pd.DataFrame({k: vars(v) for k, v in KINEMATIC_LIMITS.items()}).T)

# %% [markdown]
# ## Adversarial cross traffic against `coop` at the right-turn junction
#
# In Right-Turn Yield the ego turns right across a flow of vehicles. Here the first flow
# vehicle (the hazard) gets a track: it may brake, speed up and drift within its lane and car
# limits. Which of those manoeuvres does `coop` fail on while the privileged expert still drives
# the scene with margin, and how fast does each method find one?

# %%
suite = load_suite()
pair = next(p for p in suite.pairs if p.family == "RTY")
cfg = StressConfig(
    space="adversary",
    actors=("hazard",),
    knots=8 if SMALL else 16,
    restarts=2 if SMALL else 8,
    budget_s=600.0,
    budget_rollouts=8 if SMALL else 96,
    popsize=2 if SMALL else 0,
)
problem, traces = stress_test(pair, "coop", cfg, suite=suite, progress=True)
print(f"{problem.space.dim} dimensions; compile {problem.info['compile_s']:.0f} s")
table = comparison_table(traces, problem)
display(table[list(SUMMARY_COLUMNS)])

# %% [markdown]
# The convergence plot: the lowest exact CUS found so far, against rollouts per restart (every
# kind counted) and against seconds on each method's own clock. The dotted line is the failure
# threshold.

# %%
display(convergence_plot(traces, f"{pair.pair_id}: coop, adversarial hazard"))

# %% [markdown]
# ## The failure catalogue
#
# Every distinct verified failure (the near-duplicate rule on the adversary's trajectory), with
# a line saying which gate failed when and what the adversary did, and a bird's-eye view of the
# policy's rollout at the failure (the adversary's path dashed). The catalogue is also a suite
# file: `lantern-jax evaluate --suite catalogue_suite.json` replays it.

# %%
entries = catalogue.catalogue_entries(problem, pair, traces, "coop")
for e in entries[:6]:
    print(f"{e['pair_id']} ({e['method']}): CUS {e['hard_cus']:.1f}; {e['description']}")
if entries:
    display(catalogue_figure(problem, entries, max_panels=3 if SMALL else 6))

# %% [markdown]
# ## Are the gradients right?
#
# The pathwise gradient of the surrogate against central finite differences of the same
# surrogate, along random directions (cosine; 1 = the same direction), at two step lengths in
# the search's unconstrained coordinates. Over ±0.002 the finite differences measure the slope
# where the gradient is taken: a cosine near 1 there says the gradient is computed right. Over
# ±0.05 they measure the slope over a neighbourhood still smaller than one step of the gradient
# search (Adam moves up to about 0.2 per coordinate a step here). Where the two steps disagree,
# the surrogate jumps within a few hundredths of that point: it is smooth in pieces, and the
# gradient, right within its piece, does not see the steps between them (`docs/stress.md`,
# "How far from a point the gradient holds"), so it says little about where a search step
# lands.

# %%
points = np.random.default_rng(7).normal(0.0, 0.5, (2 if SMALL else 8, problem.space.dim))
for fd_step in (0.002, 0.05):
    print(f"finite differences over +/-{fd_step}")
    display(gradient_quality(problem, points, 0.0, 1, directions=4 if SMALL else 8,
                             step=fd_step, batch=cfg.restarts))
