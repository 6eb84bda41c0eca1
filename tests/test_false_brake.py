"""Route B false brake in closed loop (paper appendix "Complete Cooperative Unified Score",
Route B gate): the gate is about places on the route, so a warning-blind policy that stops at
the warning point fails it on every family's Route B, even when it drives on after 3 s, while
the reference policies pass.

The test policy is the camera planner plus a virtual stop just past the warning point while its
own clock (its carry: seconds since the execution started) is before ``t_go``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MODE_COOP, MODE_EXPERT

from lantern_jax.constants import DT, EGO_HALF_LENGTH, FAMILIES
from lantern_jax.policies.base import Policy
from lantern_jax.policies.planner import default_planner_config, plan, stop_constraint
from lantern_jax.scoring.metrics import finalize
from lantern_jax.sim.rollout import rollout
from lantern_jax.world import tree_stack

HORIZON = 700  # ticks (35 s)
PAST_WARNING = 1.0  # m, the ego centre comes to rest this far past the warning point


def stop_at_warning_act(params, t, obs):
    """Camera planner with a stopped obstacle placed so that the ego stands 1 m past the
    warning point (IDM standstill gap 1 m to the obstacle) while its clock ``t < t_go``."""
    end_at_warning, t_go = params
    p = default_planner_config()
    to_warning = obs.dist_to_route_end - end_at_warning  # m of route to the warning point
    obstacle = to_warning + PAST_WARNING + EGO_HALF_LENGTH + 1.0
    extra = stop_constraint(p, obstacle, t < t_go)
    return plan(p, obs, obs.visible, extra)[0], t + DT


STOP_AT_WARNING = Policy(
    "stop-at-warning", lambda key: None, stop_at_warning_act, init_carry=lambda p: jnp.float32(0.0)
)


@jax.jit
def run_timed(worlds, end_at_warning, t_go):
    def one(world, e, tg):
        return rollout(world, STOP_AT_WARNING, (e, tg), HORIZON)[0]

    return jax.vmap(one)(worlds, end_at_warning, t_go)


@pytest.fixture(scope="module")
def route_bs(family_pairs):
    worlds = [family_pairs[f][1] for f in FAMILIES]
    end_at_warning = np.asarray(
        [float(w.route.length) - float(w.config.s_warn) for w in worlds], np.float32
    )
    return worlds, end_at_warning


def _metrics(final, i):
    return finalize(jax.tree.map(lambda x: x[i], final.telemetry))


@pytest.fixture(scope="module")
def stopped_for_good(route_bs):
    worlds, end = route_bs
    n = len(worlds)
    return run_timed(tree_stack(worlds), jnp.asarray(end), jnp.full((n,), 1e6, jnp.float32))


def test_stopping_for_good_at_the_warning_point_fails_every_route_b(route_bs, stopped_for_good):
    worlds, _ = route_bs
    for i, fam in enumerate(FAMILIES):
        m = _metrics(stopped_for_good, i)
        assert not bool(m.is_route_a)
        assert not bool(m.gate_false_brake), fam
        assert float(m.false_brake_max_stop_s) >= 1.0, fam
        # it did stop at the warning point, and never moved again
        prog = float(m.progress_m)
        s_warn = float(worlds[i].config.s_warn)
        assert s_warn <= prog <= s_warn + 2.0 * PAST_WARNING, (fam, prog, s_warn)


def test_stopping_three_seconds_at_the_warning_point_fails_too(route_bs, stopped_for_good):
    worlds, end = route_bs
    # The time the ego came to rest in the first run: the end of its progress minus the
    # standstill it recorded (the block gate ends a run after a 20 s standstill).
    t_rest = np.asarray(
        [float(stopped_for_good.t[i]) - float(_metrics(stopped_for_good, i).max_still_s)
         for i in range(len(worlds))], np.float32
    )  # fmt: skip
    final = run_timed(tree_stack(worlds), jnp.asarray(end), jnp.asarray(t_rest + 3.0))
    for i, fam in enumerate(FAMILIES):
        m = _metrics(final, i)
        assert not bool(m.gate_false_brake), fam
        assert 1.0 <= float(m.false_brake_max_stop_s) <= 3.5, (fam, m.false_brake_max_stop_s)
        assert bool(m.completed), f"{fam}: drove on and completed the route"


@pytest.mark.parametrize("mode", [MODE_EXPERT, MODE_COOP], ids=["expert", "coop"])
def test_reference_policies_pass_false_brake_on_every_route_b(sim, route_bs, mode):
    worlds, _ = route_bs
    final, _ = sim.batch(worlds, mode)
    for i, fam in enumerate(FAMILIES):
        m = finalize(jax.tree.map(lambda x, i=i: x[i], final.telemetry))
        assert bool(m.gate_false_brake), fam
        assert float(m.progress) == pytest.approx(1.0), fam


@pytest.mark.slow
def test_coop_false_brake_rate_on_the_suite():
    """On the whole shipped suite the cooperative reference keeps False Brake-B <= 5 %."""
    from lantern_jax.evaluate import evaluate

    rt = evaluate(["coop"], progress=False).route_table
    warned = rt[rt["condition"] == "warning"]
    assert 100.0 * float((warned["gate_false_brake"] == 0).mean()) <= 5.0
