"""One pair of a suite up close: its three executions recorded, and one figure of them.

* :func:`record_pair` — roll out a pair's three executions (Route A with the warning, Route A
  without it, Route B) with every tick recorded, in one jitted call;
* :func:`plot_pair` — bird's-eye view of one execution at its most telling tick next to the
  timeline of both Route A conditions, with collisions, the first failed gate, the warning's
  delivery, the event onset and the clearance marked; optionally written as PNG (and an
  animation) to a folder;
* :func:`telling_tick`, :func:`hazard_clearance`, :func:`first_failed_gate` — the pieces the
  figure is chosen and annotated with.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path
from typing import Any

import jax
import numpy as np
from matplotlib.figure import Figure

from lantern_jax.apps.diagnostics import run_recorded
from lantern_jax.apps.evaluation import EvalResult, settings_record
from lantern_jax.core.constants import (
    CONDITIONS,
    EGO_HALF_LENGTH,
    EGO_HALF_WIDTH,
    NO_WARNING_CONDITION,
    ROUTE_A_GATE_NAMES,
    WARNING_CONDITION,
)
from lantern_jax.maths import geometry
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import build_pair
from lantern_jax.scenarios.protocol_variants import get_ablation
from lantern_jax.scenarios.suite import SUITE_ID, Suite, load_suite
from lantern_jax.scoring.components import ROUTE_A_GATES
from lantern_jax.sim.settings import Settings, actors_of_record, default_settings
from lantern_jax.viz.animate import save_animation
from lantern_jax.viz.common import (
    collision_index,
    happened,
    num_valid_ticks,
    save_figure,
    to_numpy,
)
from lantern_jax.viz.plots import bev_plot
from lantern_jax.viz.timeline import timeline_plot

__all__ = [
    "ROUTE_B",
    "PairRecording",
    "RecordedExecution",
    "first_failed_gate",
    "hazard_clearance",
    "plot_pair",
    "record_pair",
    "telling_tick",
]

#: The third execution of a pair (the two Route A ones are :data:`~lantern_jax.core.constants.
#: CONDITIONS`).
ROUTE_B = "route-b"
EXECUTIONS = (*CONDITIONS, ROUTE_B)
_ALIASES = {
    "warning": WARNING_CONDITION,
    "no-warning": NO_WARNING_CONDITION,
    "no_warning": NO_WARNING_CONDITION,
    "nowarning": NO_WARNING_CONDITION,
    "route-b": ROUTE_B,
    "route_b": ROUTE_B,
    "b": ROUTE_B,
}
GATE_LABELS = {
    "gate_collision": "collision",
    "gate_route_deviation": "route deviation",
    "gate_lane": "lane keeping",
    "gate_rule": "red light",
    "gate_block": "blocked",
    "gate_false_brake": "false brake",
}
SHOWN_IDS = 6  # pair ids named in the message for an unknown one


@dataclasses.dataclass(frozen=True)
class RecordedExecution:
    """One recorded execution (NumPy arrays, no batch axis).

    Attributes:
        condition: ``"warning"``, ``"no-warning"`` (Route A) or ``"route-b"``.
        scenario: its :class:`~lantern_jax.types.world.Scenario`.
        record: its ``TickRecord``, leading time axis ``N`` (the horizon, in ticks of
            :data:`~lantern_jax.core.constants.DT`); entries after the execution ended repeat it.
        final: its final :class:`~lantern_jax.sim.state.State`.
        metrics: its hard :class:`~lantern_jax.scoring.metrics.ExecutionMetrics`.
    """

    condition: str
    scenario: Any
    record: Any
    final: Any
    metrics: Any

    @property
    def collided(self) -> bool:
        """Whether the ego collided at some tick."""
        return bool(self.final.telemetry.collision.collided)

    @property
    def collision_time(self) -> float | None:
        """s, the first collision's time stamp, or None without a collision."""
        t = float(self.final.telemetry.collision.t_collision)
        return t if self.collided and happened(t) else None


@dataclasses.dataclass(frozen=True)
class PairRecording:
    """The three recorded executions of one pair under one policy (:func:`record_pair`).

    Attributes:
        pair_id, family, weather: the pair's.
        policy: the policy's name.
        ablation: the ablation applied to the Route A executions (``"none"``).
        settings: the :class:`~lantern_jax.sim.settings.Settings` the executions ran under.
        warning, no_warning, route_b: the executions.
    """

    pair_id: str
    family: str
    weather: str
    policy: str
    ablation: str
    settings: Settings
    warning: RecordedExecution
    no_warning: RecordedExecution
    route_b: RecordedExecution

    def execution(self, condition: str) -> RecordedExecution:
        """The execution of ``condition``: ``"warning"``, ``"no-warning"`` or ``"route-b"``
        (``"nowarning"``, ``"no_warning"``, ``"route_b"`` and ``"B"`` are accepted too).

        Raises:
            ValueError: naming the accepted conditions.
        """
        key = _ALIASES.get(str(condition).lower())
        if key is None:
            raise ValueError(f"condition {condition!r}: expected one of {', '.join(EXECUTIONS)}")
        return {
            WARNING_CONDITION: self.warning,
            NO_WARNING_CONDITION: self.no_warning,
            ROUTE_B: self.route_b,
        }[key]


def _resolve_suite(suite: Suite | str | os.PathLike | None) -> Suite:
    if suite is None:
        return load_suite()
    if isinstance(suite, Suite):
        return suite
    return load_suite(suite)


def _find_pair(suite: Suite, pair_id: str):
    for p in suite.pairs:
        if p.pair_id == pair_id:
            return p
    ids = [p.pair_id for p in suite.pairs]
    shown = ", ".join(ids[:SHOWN_IDS]) + (", ..." if len(ids) > SHOWN_IDS else "")
    raise ValueError(
        f"pair {pair_id!r} is not in suite {suite.suite_id} ({len(ids)} pairs: {shown})"
    )


def record_pair(
    policy: Policy | str,
    pair_id: str,
    suite: Suite | str | os.PathLike | None = None,
    settings: Settings | None = None,
    policy_params: Any = None,
    ablation: str = "none",
) -> PairRecording:
    """Roll out the three executions of one pair with every tick recorded.

    The executions are built as an evaluation builds them
    (:func:`~lantern_jax.sim.engine.build_executions`): Route A with ``warning_enabled`` on and
    off (the ablation applied to both), and Route B; they run in one jitted, vmapped call
    (:func:`~lantern_jax.apps.diagnostics.run_recorded`) for the longest route timeout.

    Args:
        policy: a registered policy name or a :class:`~lantern_jax.policies.base.Policy`.
        pair_id: the pair's id, e.g. ``"pe_0001"``.
        suite: a :class:`~lantern_jax.scenarios.suite.Suite`, a suite id or a manifest path;
            default the built-in suite.
        settings: default :func:`~lantern_jax.sim.settings.default_settings`.
        policy_params: the policy's parameters; default its ``init`` with ``PRNGKey(0)`` (as
            :func:`~lantern_jax.apps.evaluation.evaluate` uses).
        ablation: one of :func:`~lantern_jax.apps.evaluation.ablation_names`.

    Returns:
        :class:`PairRecording`.

    Raises:
        ValueError: for a pair id not in the suite (naming it and a few known ids) or an
            unknown ablation.
    """
    s = _resolve_suite(suite)
    spec = _find_pair(s, pair_id)
    fn = get_ablation(ablation).apply
    pol = get_policy(policy) if isinstance(policy, str) else policy
    params = pol.init(jax.random.PRNGKey(0)) if policy_params is None else policy_params
    settings = default_settings() if settings is None else settings.validate()
    a, b, _ = build_pair(spec.params, validate=False)
    routes_a = []
    for on in (True, False):
        cfg = a.config.replace(warning_enabled=np.asarray(on))
        routes_a.append(a.replace(config=cfg if fn is None else fn(cfg)))
    scenarios = [*routes_a, b]
    final, rec, metrics = run_recorded(pol, params, scenarios, settings)
    execs = [
        RecordedExecution(
            condition=cond,
            scenario=to_numpy(sc),
            record=jax.tree.map(lambda x, k=k: x[k], rec),
            final=jax.tree.map(lambda x, k=k: x[k], final),
            metrics=jax.tree.map(lambda x, k=k: x[k], metrics),
        )
        for k, (cond, sc) in enumerate(zip(EXECUTIONS, scenarios, strict=True))
    ]
    return PairRecording(
        pair_id=spec.pair_id,
        family=spec.family,
        weather=spec.weather,
        policy=getattr(pol, "name", str(policy)),
        ablation=ablation,
        settings=settings,
        warning=execs[0],
        no_warning=execs[1],
        route_b=execs[2],
    )


def hazard_clearance(scenario: Any, record: Any) -> np.ndarray:
    """Ego-hazard box-surface distance at every recorded tick.

    Args:
        scenario: the execution's :class:`~lantern_jax.types.world.Scenario`
            (``config.hazard_index`` names the hazard's actor slot).
        record: its ``TickRecord`` with a leading time axis ``N``.

    Returns:
        ``(N,)`` float, m (0 when the boxes overlap); NaN where the hazard is absent (never in
        Route B) and after the end of the execution.
    """
    sc, rec = to_numpy(scenario), to_numpy(record)
    n_all, n = int(rec.t.shape[0]), num_valid_ticks(rec)
    h = int(sc.config.hazard_index)
    out = np.full(n_all, np.nan)
    if not 0 <= h < sc.actors.valid.shape[0] or not bool(sc.actors.valid[h]):
        return out
    ego_ext = np.array([EGO_HALF_LENGTH, EGO_HALF_WIDTH], np.float32)
    d = jax.vmap(geometry.box_distance, in_axes=(0, 0, None, 0, 0, None))(
        rec.ego_xy[:n],
        rec.ego_yaw[:n],
        ego_ext,
        rec.actor_xy[:n, h],
        rec.actor_yaw[:n, h],
        sc.actors.extent[h],
    )
    present = np.asarray(rec.actor_present[:n, h], bool)
    out[:n] = np.where(present, np.asarray(d, float), np.nan)
    return out


def telling_tick(record: Any, collision_time: Any = None, clearance: Any = None) -> int:
    """The record entry that shows an execution best.

    Args:
        record: a ``TickRecord`` with a leading time axis ``N`` (``t``, s; ``done``).
        collision_time: s, the first collision (None, NaN or never: no collision).
        clearance: ``(N,)`` m, ego-hazard distance per entry, NaN where there is none
            (:func:`hazard_clearance`); None: not known.

    Returns:
        The first collision's entry when the execution collided; else the entry of minimum
        clearance (the first one on ties); else, without any clearance sample, the last entry of
        the execution.
    """
    i = collision_index(record, collision_time)
    if i is not None:
        return i
    n = num_valid_ticks(record)
    if clearance is not None:
        c = np.asarray(clearance, float).reshape(-1)[:n]
        if np.isfinite(c).any():
            return int(np.nanargmin(np.where(np.isfinite(c), c, np.nan)))
    return n - 1


def first_failed_gate(execution: RecordedExecution, settings: Settings | None = None):
    """The gate the execution failed first.

    Route A executions are judged by the Route A gates (collision, route deviation, lane
    keeping, red light, blocked), Route B by the false-brake gate: the gates a pair's score
    reads from each.  Among several failed gates the one with the earliest failure time wins
    (gates without a failure time come last, in :data:`~lantern_jax.core.constants.GATE_NAMES`
    order).

    Args:
        execution: a :class:`RecordedExecution`.
        settings: the settings it ran under (default
            :func:`~lantern_jax.sim.settings.default_settings`); their scoring thresholds give
            the failure times.

    Returns:
        ``(metric field, label, time)``, e.g. ``("gate_collision", "collision", 4.15)`` (time in
        s, NaN when the gate has none), or None when every gate passed.
    """
    scoring = (default_settings() if settings is None else settings).scoring
    is_a = bool(execution.scenario.config.is_route_a)
    names = ROUTE_A_GATE_NAMES if is_a else ("gate_false_brake",)
    tel = execution.final.telemetry
    failed = []
    for order, name in enumerate(names):
        if bool(getattr(execution.metrics, name)):
            continue
        field = name.removeprefix("gate_")
        t = np.nan
        if field in ROUTE_A_GATES:
            times = ROUTE_A_GATES[field].failure_times(getattr(tel, field), tel.context, scoring)
            t = float(np.min([float(np.asarray(x)) for x in times]))
            t = t if happened(t) else np.nan
        failed.append((np.isnan(t), t if not np.isnan(t) else 0.0, order, name, t))
    if not failed:
        return None
    *_, name, t = min(failed)
    return name, GATE_LABELS.get(name, name), t


# ---------------------------------------------------------------------------------------------
# the figure
# ---------------------------------------------------------------------------------------------
def _from_result(result: EvalResult, policy: Policy | str | None, settings: Settings | None):
    """(policy, suite, settings, ablation) of an evaluation's result."""
    man = result.manifest or {}
    names = [p["name"] for p in man.get("policies", [])]
    if policy is None:
        if len(names) != 1:
            raise ValueError(f"plot_pair: name the policy; the result holds {names}")
        policy = names[0]
    name = policy if isinstance(policy, str) else getattr(policy, "name", None)
    if names and name not in names:
        raise ValueError(f"plot_pair: policy {name!r} is not in the result (it holds {names})")
    suite_id = str(man.get("suite_id", SUITE_ID)).removesuffix("-sub")
    try:
        suite = load_suite(suite_id)
    except (OSError, ValueError):  # a suite from a file the result does not locate
        suite = load_suite()
    if settings is None:
        settings = _settings_from_record(man.get("settings"))
    return policy, suite, settings, str(man.get("ablation", "none"))


def _settings_from_record(record: dict | None) -> Settings:
    """The :class:`Settings` an evaluation's manifest records (:func:`settings_record`)."""
    # a record written before 2026-12-08 may name no actors (then the rule of then)
    base = default_settings().replace(actors=actors_of_record(record))
    if not record or record == settings_record(base):
        return base
    if record.get("text_bank") != settings_record(base)["text_bank"]:
        raise ValueError(
            "plot_pair: the result ran with a text bank other than the default one; pass its "
            "settings= explicitly"
        )
    scoring = dataclasses.replace(base.scoring, **record.get("scoring", {}))
    protocol = dataclasses.replace(base.protocol, **record.get("protocol", {}))
    return base.replace(scoring=scoring, protocol=protocol).validate()


def safe_name(name: str) -> str:
    """``name`` as a file name's part (what :func:`plot_pair` names its files with)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "policy"


_safe = safe_name


def figure_stem(pair_id: str, policy: str, condition: str) -> str:
    """The file stem :func:`plot_pair` writes one execution's figure under:
    ``<pair>_<policy>_<condition>`` (``.png``, and ``.gif`` for the animation)."""
    return f"{_safe(pair_id)}_{_safe(policy)}_{condition}"


def _gate_text(ex: RecordedExecution, settings: Settings) -> str:
    g = first_failed_gate(ex, settings)
    if g is None:
        return "all gates passed"
    _, label, t = g
    return f"first failed gate: {label}" + (f" at t = {t:.2f} s" if np.isfinite(t) else "")


def pair_figure(rec: PairRecording, condition: str = WARNING_CONDITION) -> Figure:
    """The figure of :func:`plot_pair` from a recording (see there)."""
    ex = rec.execution(condition)
    clear = hazard_clearance(ex.scenario, ex.record)
    tick = telling_tick(ex.record, ex.collision_time, clear)
    fig = Figure(figsize=(17.0, 7.0))
    ax_bev = fig.add_axes((0.04, 0.08, 0.36, 0.84))
    ax_v = fig.add_axes((0.57, 0.53, 0.30, 0.39))
    ax_a = fig.add_axes((0.57, 0.08, 0.30, 0.39), sharex=ax_v)
    ax_v.tick_params(labelbottom=False)
    why = (
        "first collision"
        if ex.collided
        else ("minimum clearance" if np.isfinite(clear).any() else "end of the execution")
    )
    cond = ex.condition.replace("-", " ")
    bev_plot(
        ex.scenario,
        ex.record,
        tick,
        ax=ax_bev,
        title=f"{rec.pair_id} {cond} ({why})",
        collision_time=ex.collision_time,
    )
    ax_bev.text(
        0.015,
        0.015,
        _gate_text(ex, rec.settings),
        transform=ax_bev.transAxes,
        ha="left",
        va="bottom",
        fontsize=8,
        zorder=10,
        gid="gate",
        color="#9d0208" if first_failed_gate(ex, rec.settings) else "#1b4332",
        bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="#999999", alpha=0.9),
    )
    w, nw = rec.warning, rec.no_warning
    timeline_plot(
        w.record,
        nw.record,
        w.final.protocol,
        nw.final.protocol,
        title="Route A: warning vs no warning",
        collision_times=(w.collision_time, nw.collision_time),
        axes=(ax_v, ax_a),
    )
    # each execution's first failed gate, in the room right of the acceleration axes
    ax_a.text(
        1.02,
        1.0,
        "first failed gate",
        transform=ax_a.transAxes,
        ha="left",
        va="top",
        fontsize=8,
        fontweight="bold",
    )
    runs = (
        ("warning", "warning", w),
        ("nowarning", "no warning", nw),
        ("route-b", "route B", rec.route_b),
    )
    for k, (key, label, e) in enumerate(runs):
        g = first_failed_gate(e, rec.settings)
        what = "none" if g is None else g[1] + (f", t = {g[2]:.2f} s" if np.isfinite(g[2]) else "")
        ax_a.text(
            1.02,
            0.9 - 0.1 * k,
            f"{label}: {what}",
            transform=ax_a.transAxes,
            ha="left",
            va="top",
            fontsize=8,
            gid=f"gate:{key}",
            color="#1b4332" if g is None else "#9d0208",
        )
    suffix = "" if rec.ablation == "none" else f", ablation {rec.ablation}"
    fig.suptitle(f"{rec.pair_id} ({rec.family}, {rec.weather}): {rec.policy}{suffix}", fontsize=12)
    return fig


def plot_pair(
    result_or_policy: EvalResult | PairRecording | Policy | str,
    policy: Policy | str | None = None,
    pair_id: str | None = None,
    condition: str = WARNING_CONDITION,
    out: str | os.PathLike | None = None,
    animate: bool = False,
    *,
    suite: Suite | str | os.PathLike | None = None,
    settings: Settings | None = None,
    policy_params: Any = None,
) -> Figure | tuple[Figure, list[Path]]:
    """Figure of one pair under one policy: what happened, when, and which gate it failed.

    Left, the bird's-eye view (:func:`~lantern_jax.viz.plots.bev_plot`) of the ``condition``'s
    execution at its most telling tick (:func:`telling_tick`: the first collision if it
    collided, else the minimum ego-hazard clearance), with a red X where the ego collided
    (``gid="collision"``) and its first failed gate (``gid="gate"``).  Right, the timeline
    (:func:`~lantern_jax.viz.timeline.timeline_plot`) of both Route A conditions: speed and
    acceleration, the warning's delivery shaded, event onset, warning termination and clearance
    lines, red lines and Xs at collisions (``gid="collision:<run>"``, run ``warning`` or
    ``nowarning``) and each execution's first failed gate (``gid="gate:<run>"``, also
    ``gate:route-b``).

    Args:
        result_or_policy: an :class:`~lantern_jax.apps.evaluation.EvalResult` (its manifest gives
            the suite (the built-in one when it names no shipped suite), the settings and the
            ablation), a :class:`PairRecording` (drawn as is), or a policy name / object.
        policy: with a result, the policy to show (may be left out when the result holds one);
            otherwise must be None.
        pair_id: the pair's id; default the first pair of the suite.
        condition: the execution of the bird's-eye view: ``"warning"``, ``"no-warning"`` or
            ``"route-b"``.
        out: a folder; the figure is written there as ``<pair>_<policy>_<condition>.png``
            (:func:`~lantern_jax.viz.common.save_figure`).
        animate: with ``out``, also write the execution's animation next to it
            (:func:`~lantern_jax.viz.animate.save_animation`, GIF).
        suite: the suite when ``result_or_policy`` is a policy (default the built-in one).
        settings: the settings to run under (default: the result's, else
            :func:`~lantern_jax.sim.settings.default_settings`).
        policy_params: the policy's parameters (default its ``init``; a result does not keep
            them).

    Returns:
        The figure; with ``out``, ``(figure, paths written)``.

    Raises:
        ValueError: for a pair id not in the suite (naming it), an unknown condition, a policy
            not in the result, or a policy given twice.
    """
    if isinstance(result_or_policy, PairRecording):
        rec = result_or_policy
        if pair_id is not None and pair_id != rec.pair_id:
            raise ValueError(f"plot_pair: the recording is of pair {rec.pair_id}, not {pair_id}")
    else:
        ablation = "none"
        if isinstance(result_or_policy, EvalResult):
            pol, s, settings, ablation = _from_result(result_or_policy, policy, settings)
        elif policy is not None:
            raise ValueError(
                "plot_pair: policy given twice (first argument and policy=); pass the pair as "
                "pair_id="
            )
        else:
            pol, s = result_or_policy, _resolve_suite(suite)
        if isinstance(result_or_policy, EvalResult) and suite is not None:
            s = _resolve_suite(suite)
        pid = s.pairs[0].pair_id if pair_id is None else pair_id
        rec = record_pair(pol, pid, s, settings, policy_params, ablation)
    ex = rec.execution(condition)  # checks the condition
    fig = pair_figure(rec, ex.condition)
    if out is None:
        return fig
    stem = figure_stem(rec.pair_id, rec.policy, ex.condition)
    folder = Path(out)
    paths = [save_figure(fig, folder / f"{stem}.png")]
    if animate:
        title = f"{rec.pair_id} {ex.condition.replace('-', ' ')}"
        paths.append(
            save_animation(
                ex.scenario,
                ex.record,
                folder / f"{stem}.gif",
                title=title,
                collision_time=ex.collision_time,
            )
        )
    return fig, paths
