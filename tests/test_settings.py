"""Settings are arguments (:mod:`lantern_jax.sim.settings`): a setting changed from Python in a
running process gives the next evaluation's answer for the new value, the same answer as a
fresh process with that change, also when a second process serves the program from the
persistent cache; a traced setting runs the program already compiled.

The changes (:data:`settings_probe.CHANGES`): scoring thresholds, weights, a tick window, the
soft temperature, protocol thresholds, planner constants of ``coop`` and a text of the warning
bank, each probed on three pairs (route table and soft CUS, :func:`settings_probe.probe`).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import settings_probe as sp

from lantern_jax.dynamics.actors import ActorSettings
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.cus import pair_components
from lantern_jax.scoring.metrics import finalize
from lantern_jax.scoring.thresholds import DEFAULT_SCORING, ScoringSettings
from lantern_jax.sim import programs
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings, settings_record
from lantern_jax.types.world import tree_stack

PROBE = Path(__file__).with_name("settings_probe.py")
#: Changes of a static setting (a tick window): another program, compiled again.
STATIC = [n for n in sp.CHANGES if "(static)" in n]
TRACED = [n for n in sp.CHANGES if n not in STATIC]


@pytest.fixture(scope="module")
def default_answer() -> bytes:
    return sp.probe(None)


def test_there_are_at_least_ten_settings_of_every_kind():
    kinds = {n.split(".")[0] for n in sp.CHANGES}
    assert len(sp.CHANGES) >= 10 and kinds == {"scoring", "protocol", "planner", "bank"}
    assert "scoring.temperature" in sp.CHANGES


@pytest.mark.parametrize("name", TRACED)
def test_a_traced_setting_changed_in_process_is_answered_without_compiling(name, default_answer):
    """The changed value's answer differs from the default's, runs the programs already
    compiled (none added to the evaluator's cache), and the default comes back unchanged."""
    before = set(programs._EXECUTABLES)
    changed = sp.probe(name)
    assert changed != default_answer, name
    assert set(programs._EXECUTABLES) == before, "a traced setting compiled a new program"
    assert sp.probe(None) == default_answer


def test_a_bank_grown_by_texts_runs_the_same_program_and_answers_the_same(default_answer):
    """Texts added to the bank (a registered family's, the language diagnostic's probes) are
    rows of its padded tables, an argument of the program: nothing is compiled, and executions
    that do not read them answer as before."""
    kid = "Mind the kid at <FRONT_CAR_POS>."
    bank = DEFAULT_SETTINGS.bank.with_text("PE", "paraphrase", kid, "low")
    bank = bank.with_text(-1, "non_actionable", "Hello.")
    before = set(programs._EXECUTABLES)
    assert sp.probe_with(DEFAULT_SETTINGS.replace(bank=bank)) == default_answer
    assert set(programs._EXECUTABLES) == before, "a grown bank compiled a new program"


@pytest.mark.slow
@pytest.mark.parametrize("name", STATIC)
def test_a_static_setting_changed_in_process_compiles_its_own_program(name, default_answer):
    before = set(programs._EXECUTABLES)
    assert sp.probe(name) != default_answer, name
    assert set(programs._EXECUTABLES) - before, "a static setting must be another program"
    assert sp.probe(None) == default_answer


def _run_probe(names: list[str], cache: Path) -> dict[str, str]:
    """``settings_probe.py NAMES`` in a new process with its own persistent cache folder."""
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(cache), LANTERN_JAX_CACHE_DIR=str(cache))
    res = subprocess.run(
        [sys.executable, str(PROBE), *names], env=env, capture_output=True, text=True,
        timeout=1200, cwd=PROBE.parent,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    out = dict(line.rsplit(" ", 1) for line in res.stdout.splitlines() if line.strip())
    assert list(out) == names
    return out


@pytest.mark.slow
def test_in_process_changes_equal_fresh_processes_and_the_persistent_cache(tmp_path):
    """For each change: the answer in this process (after the default's, so every cache of the
    evaluator is warm with the old value) equals that of a fresh process that makes the changes
    in the opposite order and never evaluates the default, so that every change there follows
    another predecessor than here (an answer that leaked from the evaluation before it would
    differ); a second process, served by the program store the first one filled, gives the
    same answers in this process's order.  The first process starts from an empty cache folder,
    so it compiles every program itself and keeps each in the store (a program that JAX's
    persistent cache served is not stored: :func:`lantern_jax.io.program_store.compile_lowered`)."""
    cache = tmp_path / "cache"
    in_process = {n: sp.digest(sp.probe(n)) for n in sp.CHANGES}
    default = sp.digest(sp.probe(None))
    assert default not in in_process.values()
    assert len(set(in_process.values())) == len(in_process)  # every change moves the answer
    reverse = list(reversed(sp.CHANGES))
    assert _run_probe(reverse, cache) == in_process
    assert any((cache / "lantern-programs").glob("*.program"))  # the store was filled
    assert _run_probe(list(sp.CHANGES), cache) == in_process


def test_settings_batch_with_vmap():
    """Traced settings are pytree leaves: one pair's final telemetry scored under four TTC
    normalisers and recovery caps in one ``vmap`` equals four separate calls.  (The rollout is
    the probes' program, compiled once for the file.)"""
    coop = get_policy("coop")
    tel_a, tel_b, d_safe = sp.route_telemetry(
        coop, coop.init(jax.random.PRNGKey(0)), load_suite().select(["rty_0001"]), DEFAULT_SETTINGS
    )
    tel_a, tel_b = (jax.tree.map(lambda x: x[0], t) for t in (tel_a, tel_b))
    d_safe = d_safe[0]

    def cus(s: ScoringSettings):
        return pair_components(finalize(tel_a, s), finalize(tel_b, s), d_safe, s)["CUS"]

    norms = [1.0, 2.0, 3.0, 6.0]
    caps = [2.0, 4.0, 8.0, 16.0]
    batch = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (4,)), DEFAULT_SCORING)
    batch = batch.replace(ttc_norm_s=jnp.asarray(norms), recover_cap_s=jnp.asarray(caps))
    together = np.asarray(jax.vmap(cus)(batch))
    apart = [
        float(cus(DEFAULT_SCORING.replace(ttc_norm_s=n, recover_cap_s=c)))
        for n, c in zip(norms, caps, strict=True)
    ]
    np.testing.assert_allclose(together, apart, rtol=1e-6)
    assert len(set(np.round(apart, 4))) > 1  # the settings matter on this pair


def test_the_actors_settings_are_recorded_and_an_older_record_reads_as_the_earlier_rule():
    """Every record names the actors' rule; a record written before 2026-12-08 names it only
    where it was not that day's default, so a record without it ran under the earlier rule
    (``EARLIER_ACTORS``): ``plot`` replays it so, and ``compare`` finds no difference between
    it and a new record of that rule, and a difference between it and one of the default."""
    from lantern_jax.dynamics.actors import DEFAULT_ACTORS, EARLIER_ACTORS
    from lantern_jax.report.evidence import protocol_differences
    from lantern_jax.sim.settings import actors_of_record
    from lantern_jax.viz.pair import _settings_from_record

    assert DEFAULT_ACTORS.ego_leader == "heading_line_or_box"
    assert EARLIER_ACTORS.ego_leader == "heading_line"
    new = settings_record(DEFAULT_SETTINGS)
    assert new["actors"] == {"ego_leader": "heading_line_or_box"}
    earlier = DEFAULT_SETTINGS.replace(actors=EARLIER_ACTORS)
    older = {k: v for k, v in settings_record(earlier).items() if k != "actors"}  # as written then
    for record, actors in ((new, DEFAULT_ACTORS), (settings_record(earlier), EARLIER_ACTORS),
                           (older, EARLIER_ACTORS), (None, EARLIER_ACTORS)):  # fmt: skip
        assert actors_of_record(record) == actors
        assert _settings_from_record(record).actors == actors
    assert protocol_differences({"settings": older}, {"settings": settings_record(earlier)}) == []
    assert protocol_differences({"settings": older}, {"settings": new}) == [
        "settings.actors.ego_leader: 'heading_line' vs 'heading_line_or_box'"
    ]
    with pytest.raises(ValueError, match="ActorSettings.ego_leader: 'box'"):
        actors_of_record({**new, "actors": {"ego_leader": "box"}})


@pytest.mark.slow
def test_the_actors_rule_is_its_own_world_program_and_changes_what_it_says():
    """``coop`` on ``rty_0006``, warned, the split path: under the earlier rule
    (``"heading_line"``) a car of the flow drives into it as it pulls out; under the default
    (``"heading_line_or_box"``) the car brakes and no collision happens, from a world program of
    its own; the earlier rule again gives the first answer (no program of the other rule is
    reused)."""
    from lantern_jax.apps.evaluation import evaluate

    pair = load_suite().select(["rty_0006"])
    earlier = Settings(actors=ActorSettings(ego_leader="heading_line"))
    braking = DEFAULT_SETTINGS

    def warned(settings):
        table = evaluate(["coop"], suite=pair, settings=settings, path="split",
                         progress=False).route_table  # fmt: skip
        return table[table["condition"] == "warning"].iloc[0]

    first = warned(earlier)
    assert first["no_collision"] == 0
    before = set(programs._EXECUTABLES)
    other = warned(braking)
    assert other["no_collision"] == 1 and other["CUS"] > 50.0
    assert set(programs._EXECUTABLES) - before, "another rule must be another world program"
    again = warned(earlier)
    assert again["no_collision"] == 0 and again["CUS"] == first["CUS"]


@pytest.mark.slow
def test_the_validator_and_the_data_drive_under_the_earlier_rule():
    """What keeps ``EARLIER_ACTORS`` (the suites' validation, the dataset and the training
    recipes) drives under it, the evaluation under the default: on ``rty_0006`` the flow car
    that drives into a warned ``coop`` under the earlier rule is a collision the validator
    reports and a collision in the recorder's final state, whatever the default."""
    from lantern_jax.apps.dataset.record import DATA_ACTORS, batched_recorder
    from lantern_jax.apps.suite_generation import VALIDATION_ACTORS, dynamic_check
    from lantern_jax.dynamics.actors import DEFAULT_ACTORS, EARLIER_ACTORS
    from lantern_jax.scenarios.families import build_pair

    assert VALIDATION_ACTORS == DATA_ACTORS == EARLIER_ACTORS != DEFAULT_ACTORS
    a, b, _ = build_pair(load_suite().select(["rty_0006"]).pairs[0].params)
    ok, reasons = dynamic_check([a], [b], validator="coop")
    assert not ok[0] and "A: gate_collision failed" in reasons[0]
    coop = get_policy("coop")
    _, final = batched_recorder(coop, 300)(tree_stack([a]), coop.init(jax.random.PRNGKey(0)))
    assert not bool(np.asarray(finalize(final.telemetry).gate_collision)[0])


@pytest.mark.parametrize(
    "settings, match",
    [
        (Settings(scoring=ScoringSettings(ttc_norm_s=0.0)), r"ScoringSettings.ttc_norm_s"),
        (Settings(scoring=ScoringSettings(react_window_s=0.01)), r"react_window_s.*one tick"),
        (Settings(scoring=ScoringSettings(react_fraction=1.5)), r"react_fraction"),
        (DEFAULT_SETTINGS.replace(bank=("text",)), r"Settings.bank: expected a TextBank"),
        (DEFAULT_SETTINGS.replace(scoring=0.05), r"Settings.scoring: expected ScoringSettings"),
        (DEFAULT_SETTINGS.replace(actors="box"), r"Settings.actors: expected ActorSettings"),
        (Settings(actors=ActorSettings(ego_leader="box")), r"ActorSettings.ego_leader: 'box'"),
    ],
)
def test_bad_settings_are_refused_naming_the_field(settings, match):
    with pytest.raises(ValueError, match=match):
        settings.validate()
