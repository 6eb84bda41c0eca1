"""Fragility radius: every pair's first-order distance to a collision, from one backward pass.

For each pair of a suite, the policy's **soft collision margin** ``m`` on Route A (the minimum
over ticks of ``max(box distance to the hazard, 0.1 m/s - ego speed)``, log-sum-exp smoothed
and capped at :data:`~lantern_jax.apps.stress.plausibility.CAP_M`: the surrogate of the stress
search's ``margin`` objective) is differentiated with respect to the pair's **normalised knobs**
``u`` in ``[0, 1]^K`` (each family knob's documented range mapped onto ``[0, 1]``:
:attr:`lantern_jax.scenarios.families.FamilyRecord.knobs`).  The first-order distance to
``m = 0`` along the steepest direction is the **fragility radius**::

    r = m(u0) / |grad_u m(u0)|,        direction d = -grad_u m(u0) / |grad_u m(u0)|

in units of a knob's whole range (``r = 0.2``: a fifth of one range, or that length spread over
several knobs).  Every pair of the suite is one row of a single vmapped forward and backward
pass: the knobs of all families form one vector (:func:`knob_union`), a knob outside a pair's
family has an empty range there and is left as the scene has it (masked, no gradient), so the
whole suite is **one compiled program** per policy.  A pair whose margin does not move with its
knobs (gradient 0, e.g. the margin is capped far from the hazard) has an infinite radius.

The prediction is **verified by hard rollouts** (:mod:`lantern_jax.apps.stress.fragility_probes`;
the knob space itself is :mod:`lantern_jax.apps.stress.knob_box`): the scene at ``u0 + t d`` for
``t`` = 0.5, 1, 1.5 and 2 radii (:data:`MULTIPLES`), and at :data:`LINE_POINTS` evenly spaced
points of the whole line inside the box (so "fails anywhere along the line" is measured too),
each built as an ordinary suite pair (the pair's parameters plus a ``knobs`` field) and evaluated by
:func:`lantern_jax.apps.evaluation.evaluate` with the privileged expert beside the policy.  A probe
is a **verified failure** when the policy fails there (a gate, or a pair CUS below
:data:`~lantern_jax.apps.stress.plausibility.FAIL_BELOW_CUS`) and it is plausible: the expert passes
every Route A gate there with a clearance of at least
:data:`~lantern_jax.apps.stress.plausibility.EXPERT_MARGIN_M` (rule 1 of
:mod:`lantern_jax.apps.stress.plausibility`, as the route table states it; the knob space has no
tracks, so rules 2-4 do not apply).  Every verified failure is written as a suite manifest that
``lantern-jax evaluate --suite`` re-runs to the reported CUS.

What is simplified, and why:

* the radius is taken over the knobs only (no adversarial track: a track's space differs per
  actor slot, which would split the suite into several programs);
* the margin is to the **hazard** only, over the stress search's interaction window
  (:func:`lantern_jax.apps.stress.report.soft_horizon`, the longest of the suite).  With every actor
  watched, a neighbour passing at a steady distance holds the soft minimum and carries no
  gradient with respect to the hazard's knobs (measured: ``learned-closed-loop``'s median VC
  radius on ``lantern-v3`` goes from 0.40 to 17.8); over whole executions the margins of that
  policy on that suite are identical and the pass takes three times as long.  A collision with
  another actor is therefore not predicted (``docs/stress.md`` names where it happens);
* it predicts a *collision* (the margin reaching zero), while a verified failure is any failure
  of the pair (a gate or a CUS below the threshold), which the table shows
  (``first_failure_gates``).
"""

from __future__ import annotations

import dataclasses
import io
import json
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from lantern_jax.apps.stress.fragility_probes import (
    LINE_POINTS,
    MULTIPLES,
    PROBE_COLUMNS,
    SAMPLING_SCALE,
    evaluate_pairs,
    sampling_check,
    verify_probes,
)
from lantern_jax.apps.stress.knob_box import Boxes, knob_boxes
from lantern_jax.apps.stress.objective import soft_margin
from lantern_jax.apps.stress.report import soft_horizon
from lantern_jax.apps.stress.watch import soft_rollout
from lantern_jax.core.constants import CONDITIONS, WARNING_CONDITION
from lantern_jax.io.files import StagedFolder, atomic_write
from lantern_jax.policies.base import Policy
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.families import family
from lantern_jax.scenarios.knobs import knob
from lantern_jax.scenarios.suite import Suite, build_suite_batches, suite_hash
from lantern_jax.scoring.uncertainty import sample_interval
from lantern_jax.sim.engine import program_identity
from lantern_jax.sim.programs import executable, remember
from lantern_jax.sim.settings import Settings, default_settings
from lantern_jax.types.world import Scenario

Array = jax.Array

WITHIN = 2.0  # radii: a verified failure this close counts as predicted
TEMPERATURE = 0.1  # m, the soft margin's temperature (the stress search's default)
BOUND_EPS = 1e-6  # normalised: a knob this close to a bound of its range sits on it


def _set_masked(scenario: Scenario, names: tuple[str, ...], values: Array, active: Array):
    """``scenario`` with each active knob set to its value (an inactive one left as it is)."""
    for k, n in enumerate(names):
        moved = knob(n).set(scenario, values[k])
        scenario = jax.tree.map(lambda new, old, a=active[k]: jnp.where(a, new, old), moved,
                                scenario)  # fmt: skip
    return scenario


def pair_margin(
    u: Array, scenario: Scenario, lo: Array, hi: Array, active: Array, driver: Any, params: Any,
    names: tuple[str, ...], horizon: int, settings: Settings,
) -> Array:  # fmt: skip
    """() float32, m: ONE pair's soft collision margin on Route A with its knobs at ``u`` (K,).

    Args:
        u: (K,) float32, normalised knob values in [0, 1].
        scenario: the pair's Route A (its condition set).
        lo, hi: (K,) float32, the knob ranges (equal where inactive).
        active: (K,) bool, the knobs of the pair's family.
        driver: the policy; ``params`` its parameters.
        names: the knobs (:func:`knob_union`).
        horizon: ticks of the soft rollout.
        settings: carrying the soft temperature.
    """
    values = lo + (hi - lo) * u
    sc = _set_masked(scenario, names, values, active)
    hazard = sc.config.hazard_index[None].astype(jnp.int32)
    _, watch = soft_rollout(sc, driver, params, horizon, settings, hazard, jnp.zeros((1,), bool))
    return soft_margin(watch.margin_lse, settings.scoring.temperature)


def margin_program(policy: Policy, names: tuple[str, ...], horizon: int) -> Any:
    """``jit((u (P, K), scenarios, lo, hi, active, params, settings) -> (margins (P,),
    grads (P, K)))``: every pair's margin and its gradient in one vmapped pass, built once per
    policy program, knob set and horizon in this process (:func:`radii` keeps the compiled
    program in the program store for later ones).  XLA's default options: with
    :func:`~lantern_jax.core.xla_options.fast_compile_options` it compiled 5-9 s sooner, but the
    gradients through 500 soft ticks moved the radii by up to 0.4 % (docs/performance.md)."""

    def one(u, sc, lo, hi, active, params, settings):
        return pair_margin(u, sc, lo, hi, active, policy, params, names, horizon, settings)

    return remember(
        ("fragility", getattr(policy, "program", policy), names, horizon),
        lambda: jax.jit(jax.vmap(jax.value_and_grad(one),
                                 in_axes=(0, 0, 0, 0, 0, None, None))),
    )  # fmt: skip


def radius_of(margin: np.ndarray, grad: np.ndarray, active: np.ndarray,
              u0: np.ndarray) -> tuple:  # fmt: skip
    """First-order distance to ``margin = 0`` inside the box, and its direction, per row.

    The gradient is projected on the box first: a knob at a bound of its range whose descent
    would leave the range does not move (a scene at ``hazard_delay = 0`` cannot trigger
    earlier), so the radius is the distance along the steepest direction the box allows.

    Args:
        margin: (P,) m, the margins (a margin <= 0 is a collision already: radius 0).
        grad: (P, K) m per unit of normalised knob, their gradients.
        active: (P, K) bool, the coordinates that may move.
        u0: (P, K) the normalised point, in [0, 1].

    Returns:
        ``(radius (P,), direction (P, K))``: radius in normalised units (inf where the projected
        gradient vanishes), direction the unit projected steepest descent (zeros there).
    """
    g = np.where(active, np.asarray(grad, np.float64), 0.0)
    blocked = ((u0 <= BOUND_EPS) & (g > 0)) | ((u0 >= 1.0 - BOUND_EPS) & (g < 0))
    g = np.where(blocked, 0.0, g)
    norm = np.linalg.norm(g, axis=1)
    safe = norm > 0
    direction = np.where(safe[:, None], -g / np.where(safe, norm, 1.0)[:, None], 0.0)
    m = np.asarray(margin, np.float64)
    radius = np.where(m <= 0, 0.0, np.where(safe, m / np.where(safe, norm, 1.0), np.inf))
    return radius, direction


def line_end(u0: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(P,) the largest ``t`` with ``u0 + t d`` inside the box ``[0, 1]^K`` (0 for d = 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(direction > 0, (1.0 - u0) / direction, np.inf)
        down = np.where(direction < 0, -u0 / direction, np.inf)
    t = np.min(np.minimum(up, down), axis=1)
    return np.where(np.isfinite(t), t, 0.0)


def probe_distances(radius: np.ndarray, t_end: np.ndarray) -> np.ndarray:
    """(P, J) distances along the line to probe: ``MULTIPLES`` radii (NaN past the box's edge,
    for an infinite radius, or a zero one: the scene itself, evaluated apart), then
    :data:`LINE_POINTS` evenly spaced up to the edge; a distance already probed is NaN."""
    mult = np.asarray(MULTIPLES)[None, :] * radius[:, None]
    keep = np.isfinite(mult) & (mult > 0) & (mult <= t_end[:, None] + 1e-9)
    mult = np.where(keep, mult, np.nan)
    frac = np.arange(1, LINE_POINTS + 1)[None, :] / LINE_POINTS
    line = np.where(t_end[:, None] > 0, frac * t_end[:, None], np.nan)
    out = np.concatenate([mult, line], axis=1)
    for row in out:  # a point probed twice (a multiple on a line point) is probed once
        seen: list[float] = []
        for j, t in enumerate(row):
            if np.isfinite(t) and any(abs(t - u) <= 1e-9 for u in seen):
                row[j] = np.nan
            elif np.isfinite(t):
                seen.append(float(t))
    return out


@dataclasses.dataclass
class Fragility:
    """What :func:`fragility` measured (see the module docstring)."""

    policy: str
    condition: str
    table: pd.DataFrame  # one row per pair (:data:`TABLE_COLUMNS`, then d_<knob> per knob)
    probes: pd.DataFrame  # one row per probe: pair_id, probe, t, multiple, CUS, failed, ...
    families: pd.DataFrame  # per-family summary with intervals (:func:`family_summary`)
    failures: dict  # suite manifest of every verified failure (``lantern-jax evaluate``)
    seconds: dict[str, float]  # wall seconds: "compile", "radius", "verify", "sampling"
    sampling: pd.DataFrame | None = None  # :func:`sampling_check`'s correlations (None: not run)


#: The per-pair table's columns (then ``d_<knob>``: the direction, per knob of the union).
TABLE_COLUMNS = ("pair_id", "family", "margin_m", "grad_norm", "radius", "t_end",
                 "in_box", "nominal_cus", "nominal_failed", "first_failure_t",
                 "first_failure_multiple", "first_failure_gates", "fails_on_line",
                 "fails_within")  # fmt: skip


def _first_failures(table: pd.DataFrame, probes: pd.DataFrame) -> pd.DataFrame:
    """Per pair: the nearest verified failure along the line (t, in radii, its gates), whether
    there is one (``fails_on_line``; never for a pair that fails in its own scene) and whether
    it lies within :data:`WITHIN` radii (``fails_within``)."""
    out = table.set_index("pair_id")
    out["first_failure_t"] = np.nan
    out["first_failure_gates"] = ""
    if len(probes):
        hit = probes[probes["failed"]].sort_values("t").groupby("pair_id").first()
        out.loc[hit.index, "first_failure_t"] = hit["t"]
        out.loc[hit.index, "first_failure_gates"] = hit["failed_gates"]
    out["first_failure_multiple"] = out["first_failure_t"] / out["radius"]
    # a pair that fails in its own scene has nothing to predict: it is counted apart
    out["fails_on_line"] = out["first_failure_t"].notna() & ~out["nominal_failed"].astype(bool)
    out["fails_within"] = out["fails_on_line"] & (out["first_failure_multiple"] <= WITHIN + 1e-9)
    return out.reset_index()


def family_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per family and over the suite (``all``): pairs, the median radius, the mean of
    ``min(radius, 1)`` (a bounded radius: 1 = no collision within one knob range) with its
    bootstrap interval over pairs, the share of pairs with a verified failure on the line and,
    among those, the share found within :data:`WITHIN` radii, each with its interval."""
    rows = []
    groups = [(f, table[table["family"] == f]) for f in table["family"].unique()]
    for fam, g in [*groups, ("all", table)]:
        bounded = np.minimum(g["radius"].to_numpy(float), 1.0)
        on_line = g["fails_on_line"].to_numpy(bool)
        within = np.where(on_line, g["fails_within"].to_numpy(float), np.nan)
        strata = g["family"].to_numpy() if fam == "all" else None
        b_lo, b_hi, _ = sample_interval(bounded, strata)
        l_lo, l_hi, _ = sample_interval(on_line.astype(float), strata)
        w_lo, w_hi, w_n = sample_interval(within, strata) if on_line.any() else (
            np.nan, np.nan, 0)  # fmt: skip
        rows.append(dict(
            family=fam, pairs=len(g), median_radius=float(np.median(g["radius"])),
            bounded_radius=float(np.mean(bounded)), bounded_radius_lo=float(b_lo),
            bounded_radius_hi=float(b_hi), fails_on_line=float(np.mean(on_line)),
            fails_on_line_lo=float(l_lo), fails_on_line_hi=float(l_hi),
            within_2r=float(np.nanmean(within)) if on_line.any() else np.nan,
            within_2r_lo=float(w_lo), within_2r_hi=float(w_hi), within_2r_n=int(w_n),
        ))  # fmt: skip
    return pd.DataFrame(rows)


def failure_suite(probes: pd.DataFrame, policy: str) -> dict:
    """The verified failures as a suite manifest (``lantern-jax evaluate --suite`` re-runs it;
    each pair id is the pair's, then ``_p<probe>``)."""
    specs = [] if probes.empty else list(probes.loc[probes["failed"], "spec"])
    specs = list({s.sha256: s for s in reversed(specs)}.values())[::-1]  # one per scene
    return dict(
        suite_id=f"fragility-{policy}",
        format_version=1,
        seed=0,
        pairs=[dict(pair_id=s.pair_id, family=s.family, weather=s.weather, sha256=s.sha256,
                    params=s.params) for s in specs],  # fmt: skip
        suite_sha256=suite_hash(specs),
        generation_report={},
    )


def radii(
    suite: Suite, policy: Policy, params: Any, condition: str = WARNING_CONDITION,
    temperature: float = TEMPERATURE, settings: Settings | None = None,
) -> tuple[pd.DataFrame, Boxes, np.ndarray, dict]:  # fmt: skip
    """Every pair's margin, gradient, radius and direction (one vmapped pass, no verification).

    Returns:
        ``(table, boxes, direction (P, K), seconds)``: the table has pair_id, family, margin_m,
        grad_norm, radius, t_end (the line's length inside the box), in_box and ``d_<knob>``.
    """
    if condition not in CONDITIONS:
        raise ValueError(f"condition: {condition!r} not one of {', '.join(CONDITIONS)}")
    if not temperature > 0:
        raise ValueError(f"temperature: must be > 0, got {temperature!r}")
    settings = (settings or default_settings()).with_temperature(float(temperature))
    scen_a, _ = build_suite_batches(suite)
    n = len(suite)
    warned = np.full((n,), condition == WARNING_CONDITION)
    scen_a = scen_a.replace(config=scen_a.config.replace(warning_enabled=warned))
    boxes = knob_boxes(suite, scen_a)
    horizon = max(soft_horizon(jax.tree.map(lambda x, i=i: x[i], scen_a), None)
                  for i in range(n))  # fmt: skip
    fn = margin_program(policy, boxes.names, horizon)
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    args = (f32(boxes.u0), scen_a, f32(boxes.lo), f32(boxes.hi), jnp.asarray(boxes.active),
            params, settings)  # fmt: skip
    # kept in the program store: a rerun in a new process loads it (the knobs' functions in the
    # identity, since a registered knob may be a user's own)
    identity = ("fragility", program_identity(policy), boxes.names, horizon,
                tuple(knob(n) for n in boxes.names))  # fmt: skip
    t0 = time.perf_counter()
    compiled = executable(fn, *args, identity=identity)
    t1 = time.perf_counter()
    margin, grad = jax.device_get(compiled(*args))
    t2 = time.perf_counter()
    radius, direction = radius_of(margin, grad, boxes.active, boxes.u0)
    t_end = line_end(boxes.u0, direction)
    table = pd.DataFrame(dict(
        pair_id=[p.pair_id for p in suite.pairs], family=[p.family for p in suite.pairs],
        margin_m=np.asarray(margin, np.float64),
        grad_norm=np.linalg.norm(np.where(boxes.active, grad, 0.0), axis=1),  # unprojected
        radius=radius, t_end=t_end, in_box=boxes.in_box,
    ))  # fmt: skip
    for k, nm in enumerate(boxes.names):
        table[f"d_{nm}"] = direction[:, k]
    return table, boxes, direction, {"compile": t1 - t0, "radius": t2 - t1, "horizon": horizon}


def fragility(
    suite: Suite, policy: Policy | str, condition: str = WARNING_CONDITION,
    temperature: float = TEMPERATURE, settings: Settings | None = None, verify: bool = True,
    progress: bool = True, sampling: int = 0, sampling_scale: float = SAMPLING_SCALE,
    seed: int = 0,
) -> Fragility:  # fmt: skip
    """The fragility radius of every pair of ``suite`` for ``policy``, verified by hard rollouts.

    Args:
        suite: the pairs (any families with knobs).
        policy: a policy or a registered name.
        condition: ``"warning"`` or ``"no_warning"`` (Route A's condition).
        temperature: m, the soft margin's temperature.
        settings: scoring and protocol settings (default: the paper's).
        verify: run the hard probes (:func:`verify_probes`).
        progress: print a line per stage.
        sampling: draws per pair of :func:`sampling_check` (0: not run); adds the column
            ``sampled_failure_rate`` and :attr:`Fragility.sampling`.
        sampling_scale: normalised radius of those draws around each scene.
        seed: the draws' seed.

    Raises:
        ValueError: naming a bad condition or temperature, or a family without knobs.
    """
    pol = get_policy(policy) if isinstance(policy, str) else policy
    bad = sorted({p.family for p in suite.pairs if not family(p.family).knobs})
    if bad:
        raise ValueError(f"families without stress-testing knobs: {', '.join(bad)}")
    settings = settings or default_settings()
    say = (lambda m: print(f"[fragility] {pol.name}: {m}", flush=True)) if progress else None
    if say:
        say(f"compiling the margin and its gradient for {len(suite)} pairs (one program)")
    params = pol.init(jax.random.PRNGKey(0))
    table, boxes, direction, secs = radii(suite, pol, params, condition, temperature, settings)
    if say:
        say(f"compiled in {secs['compile']:.1f} s; radii of {len(suite)} pairs in "
            f"{secs['radius']:.1f} s (soft horizon {secs['horizon']} ticks)")  # fmt: skip
    t0 = time.perf_counter()
    nominal = evaluate_pairs(list(suite.pairs), pol, condition, settings, suite.suite_id)
    table["nominal_cus"] = nominal.loc[table["pair_id"], "CUS"].to_numpy()
    table["nominal_failed"] = nominal.loc[table["pair_id"], "policy_failed"].to_numpy()
    probes = pd.DataFrame(columns=PROBE_COLUMNS)
    if verify:
        dist = probe_distances(table["radius"].to_numpy(), table["t_end"].to_numpy())
        if say:
            say(f"verifying {int(np.isfinite(dist).sum())} probes along the predicted "
                f"directions ({dist.shape[1]} evaluations of the suite)")  # fmt: skip
        probes = verify_probes(suite, pol, boxes, direction, dist, condition, settings, say)
    table = _first_failures(table, probes)
    cols = [*TABLE_COLUMNS, *(c for c in table.columns if c.startswith("d_"))]
    table = table[cols]
    secs["verify"] = time.perf_counter() - t0
    correlations = None
    if sampling:
        t0 = time.perf_counter()
        rate, correlations = sampling_check(suite, pol, boxes, table, condition, settings,
                                            int(sampling), sampling_scale, seed, say)  # fmt: skip
        table["sampled_failure_rate"] = rate
        secs["sampling"] = time.perf_counter() - t0
    return Fragility(pol.name, condition, table, probes.drop(columns=["spec"], errors="ignore"),
                     family_summary(table), failure_suite(probes, pol.name), secs,
                     correlations)  # fmt: skip


#: The files :func:`write_fragility` writes (and owns in its output folder).
FRAGILITY_FILES = ("fragility_probes.csv", "fragility_families.csv", "fragility_sampling.csv",
                   "fragility_suite.json", "fragility.png", "fragility.csv")  # fmt: skip


def write_fragility(out: str | Path, result: Fragility, figure: Any = None) -> dict[str, Path]:
    """Write a fragility run's files into ``out`` as one set (:class:`lantern_jax.io.files.
    StagedFolder`): the per-pair table, the probes, the per-family summary, the sampling
    check's correlations (when run), the verified failures as a suite manifest and (given a
    matplotlib ``figure``) the figure.

    Returns:
        File name -> path, for every file written.
    """
    written = []
    with StagedFolder(out, FRAGILITY_FILES) as stage:
        def put(file: str, data: str | bytes) -> None:
            atomic_write(stage.path / file, data)
            written.append(file)

        put("fragility_probes.csv", result.probes.to_csv(index=False))
        put("fragility_families.csv", result.families.to_csv(index=False))
        if result.sampling is not None:
            put("fragility_sampling.csv", result.sampling.to_csv(index=False))
        put("fragility_suite.json", json.dumps(result.failures, indent=1) + "\n")
        if figure is not None:
            buf = io.BytesIO()
            figure.savefig(buf, format="png", dpi=110)
            put("fragility.png", buf.getvalue())
        put("fragility.csv", result.table.to_csv(index=False))  # the set's marker, last
        stage.commit()
    return {n: Path(out) / n for n in written}
