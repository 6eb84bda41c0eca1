"""``lantern-jax policies``: the registered policies, with their sensors and descriptions."""

from __future__ import annotations

import argparse
from collections.abc import Sequence


def cmd_policies(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """``lantern-jax policies``: registered policies with descriptions."""
    del args, argv
    from tabulate import tabulate

    from lantern_jax.policies.registry import get_policy, policy_names

    rows = []
    for name in policy_names():
        p = get_policy(name)
        rows.append([name, ", ".join(p.sensors), p.description])
    print(tabulate(rows, headers=["policy", "sensors", "description"], disable_numparse=True))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``policies`` on the command line's sub-parsers."""
    po = sub.add_parser("policies", help="list registered policies", allow_abbrev=False)
    po.set_defaults(func=cmd_policies)
