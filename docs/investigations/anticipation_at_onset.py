"""What the ego was doing between warning onset and event onset, and why Anticipation scored it
as it did, per Route A execution (warning condition).

Anticipation (the paper's appendix, ``lantern_jax.scoring.components.anticipation``) credits the
first 0.5-s window after warning onset in which at least 80 % of the ticks show an
acceleration <= -0.5 m/s^2 or a speed >= 1 m/s below the pre-warning speed, scaled by how long
before the event it began; with coincident onset (Right-Turn Yield) a response must already be
present at the event.  This script prints, per family, how many executions responded before
the event, and for every execution scoring below ``--below``: how the event began
(geometric trigger, anti-deadlock rule, or coincident with the warning), the warning-to-event
interval, the ego's speed at onset and its mean acceleration over the 0.5 s before the event,
and where the hazard actor was then (ahead / left of the ego, m) with its speed and the
ego's closing speed on it (m/s; > 0 = the ego gains on it; the hazard's velocity is taken from
its positions at the onset tick and the next, so a hazard that starts moving in the onset tick,
as Right-Turn Yield's flow does, shows its speed after the start)::

    python docs/investigations/anticipation_at_onset.py      # expert, every family
    python docs/investigations/anticipation_at_onset.py --policy coop --family VC RTY

The rollouts are the simulator's own (:func:`lantern_jax.apps.diagnostics.run_recorded`); S_ant is
the scorer's.
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd
from hazard_first_seen import recorded_route_a

from lantern_jax.core.constants import DT, FAMILIES
from lantern_jax.policies.registry import policy_names
from lantern_jax.scenarios.suite import SUITE_ID
from lantern_jax.scoring.components import anticipation
from lantern_jax.scoring.thresholds import DEFAULT_SCORING


def onset_table(family: str, policy: str, suite: str = SUITE_ID) -> pd.DataFrame:
    """One row per Route A execution of ``family`` (warning condition).

    Columns: ``pair``; ``event`` (``geometric``, ``anti-deadlock`` or ``coincident``);
    ``onset_to_event_s``; ``S_ant``; ``react_after_onset_s`` (NaN: no sustained response);
    ``v_onset`` (m/s, ego speed at warning onset); ``a_pre_event`` (m/s^2, mean ego
    acceleration over the 0.5 s before the event tick); ``hazard_ahead_m`` and
    ``hazard_left_m`` (hazard centre in the ego frame at onset); ``hazard_speed`` (m/s) and
    ``closing_speed`` (m/s, ego speed minus the hazard's velocity along the ego heading).
    """
    s, idx, batch, final, rec, met = recorded_route_a(family, policy, suite)
    s_ant = np.asarray(
        anticipation.score(met.t_ref_s, met.t_event_s, met.t_react_s,
                           met.anticipation_available, met.coincident_onset)
    )  # fmt: skip
    hazard = np.asarray(batch.config.hazard_index)
    window = DEFAULT_SCORING.react_window  # ticks, the scorer's response window
    rows = []
    for k, i in enumerate(idx):
        t = rec.t[k]
        t_ref, t_event = float(met.t_ref_s[k]), float(met.t_event_s[k])
        j = int(np.searchsorted(t, t_ref - 1e-4))  # the tick that reached the warning point
        je = int(np.searchsorted(t, t_event - 1e-4))
        h = int(hazard[k])
        yaw = float(rec.ego_yaw[k][j])
        fwd, left = np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])
        d = rec.actor_xy[k][j, h] - rec.ego_xy[k][j]
        vel = (rec.actor_xy[k][j + 1, h] - rec.actor_xy[k][j, h]) / DT
        if bool(met.coincident_onset[k]):
            how = "coincident"
        elif bool(final.protocol.event_forced[k]):
            how = "anti-deadlock"
        else:
            how = "geometric"
        rows.append({
            "pair": s.pairs[i].pair_id,
            "event": how,
            "onset_to_event_s": t_event - t_ref,
            "S_ant": float(s_ant[k]),
            "react_after_onset_s": float(met.t_react_s[k]) - t_ref,
            "v_onset": float(rec.ego_speed[k][j]),
            "a_pre_event": float(np.mean(rec.ego_accel[k][max(je - window + 1, 0):je + 1])),
            "hazard_ahead_m": float(d @ fwd),
            "hazard_left_m": float(d @ left),
            "hazard_speed": float(np.hypot(*vel)),
            "closing_speed": float(rec.ego_speed[k][j] - vel @ fwd),
        })  # fmt: skip
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policy", default="expert", help=f"one of {', '.join(policy_names())}")
    ap.add_argument("--family", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    ap.add_argument("--suite", default=SUITE_ID)
    ap.add_argument(
        "--below",
        type=float,
        default=0.5,
        help="list the executions whose S_ant is below this (default 0.5)",
    )
    a = ap.parse_args()
    fmt = lambda x: f"{x:.2f}"  # noqa: E731
    for fam in a.family:
        df = onset_table(fam, a.policy, a.suite)
        early = int((df["S_ant"] > 0).sum())
        print(
            f"\n{fam}, {a.policy}: responded before the event in {early} of {len(df)}; "
            f"mean S_ant {100.0 * df['S_ant'].mean():.1f}; events "
            + ", ".join(f"{n} {k}" for k, n in df["event"].value_counts().items())
        )
        low = df[df["S_ant"] < a.below]
        if len(low):
            print(low.to_string(index=False, float_format=fmt))


if __name__ == "__main__":
    main()
