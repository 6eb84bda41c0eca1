"""Settings changed from Python, and what an evaluation answers for each (``test_settings``).

Every entry of :data:`CHANGES` changes one setting of a simulation — a scoring threshold or
weight, a tick window, the soft temperature, a protocol threshold, a planner constant of the
``coop`` policy, a text of the warning bank — as a user would in a notebook: a new settings
value (or new policy parameters) passed to the next call.  A change marked ``(static)``
compiles another program; the others run the program already compiled.  :func:`probe`
evaluates ``coop`` on :data:`PAIRS` with it and returns what the change can alter as bytes:
the route-level table (CSV), or for the temperature (which only the soft, differentiable score
reads) the soft CUS of every pair.

Run as a script (``python tests/settings_probe.py NAME ...``) it prints ``NAME SHA-256`` of
each probe, so that a fresh process can be compared with the running one.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from lantern_jax.apps.evaluation import evaluate
from lantern_jax.core.constants import ROUTE_B, WARNING_CONDITION
from lantern_jax.policies.registry import get_policy
from lantern_jax.scenarios.suite import load_suite
from lantern_jax.scoring.cus import soft_pair_cus
from lantern_jax.sim.engine import build_executions
from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings

#: A pedestrian emergence (a warning the keyword rule does not act on), a right-turn yield (one
#: it acts on, a light) and an Obstacle Reveal (cleared by the ego's stop): every change below
#: moves a number of these three pairs.
PAIRS = ["pe_0001", "rty_0001", "or_0001"]

Change = Callable[[Settings, Any], tuple[Settings, Any]]


def _scoring(**fields: Any) -> Change:
    return lambda s, p: (s.replace(scoring=s.scoring.replace(**fields)), p)


def _protocol(**fields: Any) -> Change:
    return lambda s, p: (s.replace(protocol=s.protocol.replace(**fields)), p)


def _planner(**fields: Any) -> Change:
    def change(s: Settings, p: Any) -> tuple[Settings, Any]:
        return s, p.replace(
            planner=p.planner.replace(**{k: np.float32(v) for k, v in fields.items()})
        )

    return change


def _text(text_id: int, text: str) -> Change:
    return lambda s, p: (s.replace(bank=s.bank.with_replaced_text(text_id, text)), p)


#: name -> change of (settings, coop's parameters); each alters the probe's answer.
CHANGES: dict[str, Change] = {
    "scoring.ttc_norm_s": _scoring(ttc_norm_s=6.0),
    "scoring.closing_min_mps": _scoring(closing_min_mps=4.0),
    "scoring.weights_a": _scoring(w_progress_a=0.6, w_safety_a=0.2, w_temporal_a=0.2),
    "scoring.recover_cap_s": _scoring(recover_cap_s=3.0),
    "scoring.react_window_s (static)": _scoring(react_window_s=2.0),
    "scoring.react_speed_drop_mps": _scoring(react_speed_drop_mps=0.2),
    "scoring.temperature": _scoring(temperature=0.5),
    "protocol.still_time_for_clear_s": _protocol(still_time_for_clear_s=6.0),
    "protocol.still_speed_mps": _protocol(still_speed_mps=3.0),
    "planner.idm_T": _planner(idm_T=2.0),
    "planner.max_brake": _planner(max_brake=3.0),
    "bank.text": _text(
        0, "The pedestrian at position <FRONT_CAR_POS> is about to enter the ego lane. Yield."
    ),
}


def probe(name: str | None) -> bytes:
    """What ``coop`` on :data:`PAIRS` gives under change ``name`` (``None``: the defaults): the
    route-level table (CSV) and the soft CUS of every pair (float32 bytes)."""
    settings, params = DEFAULT_SETTINGS, get_policy("coop").init(jax.random.PRNGKey(0))
    if name is not None:
        settings, params = CHANGES[name](settings, params)
    return probe_with(settings, params)


def probe_with(settings: Settings, params: Any = None) -> bytes:
    """:func:`probe` of ``settings`` and ``coop``'s parameters (default: its own)."""
    coop = get_policy("coop")
    params = coop.init(jax.random.PRNGKey(0)) if params is None else params
    suite = load_suite().select(PAIRS)
    result = evaluate([coop], [params], suite=suite, progress=False, settings=settings)
    table = result.route_table.to_csv(index=False, float_format="%.9g").encode()
    tel_a, tel_b, d_safe = pair_telemetry(result.runs[0].telemetry, suite)
    soft = jax.vmap(lambda ta, tb, d: soft_pair_cus(ta, tb, d, settings=settings.scoring))
    return table + b"\0" + np.asarray(soft(tel_a, tel_b, d_safe), np.float32).tobytes()


def pair_telemetry(telemetry: Any, suite) -> tuple[Any, Any, Any]:
    """Every pair's final telemetry of Route A with the warning and of Route B, and its
    ``d_safe``, from an evaluation's telemetry of ``suite`` (:attr:`PolicyRun.telemetry`, in
    the order of the evaluation's executions)."""
    execs = build_executions(suite, bucket=True)
    d_safe = execs.take(execs.scenarios.config.d_safe, WARNING_CONDITION)
    return execs.take(telemetry, WARNING_CONDITION), execs.take(telemetry, ROUTE_B), d_safe


def route_telemetry(policy, params, suite, settings: Settings) -> tuple[Any, Any, Any]:
    """:func:`pair_telemetry` of ``policy``'s evaluation on ``suite`` under ``settings``."""
    result = evaluate([policy], [params], suite=suite, progress=False, settings=settings)
    return pair_telemetry(result.runs[0].telemetry, suite)


def digest(data: bytes) -> str:
    """SHA-256 of a probe's bytes."""
    return hashlib.sha256(data).hexdigest()


def main(names: list[str]) -> None:
    for name in names:
        print(name, digest(probe(name)), flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
