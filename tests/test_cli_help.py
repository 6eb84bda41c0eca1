"""Every command's ``--help`` gives each option's default (where it has one) and its choices."""

from __future__ import annotations

import argparse

import pytest

from lantern_jax.cli import COMMANDS, build_parser


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


@pytest.mark.parametrize("name", sorted(_commands()))
def test_help_shows_defaults_and_choices(name):
    command = _commands()[name]
    text = " ".join(command.format_help().split())
    for action in command._actions:
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue
        flag = action.option_strings[-1]
        assert action.help, f"{name} {flag}: no help text"
        if action.default not in (None, False, argparse.SUPPRESS):
            entry = " ".join(command._get_formatter()._get_help_string(action).split())
            assert "default" in entry, f"{name} {flag}: default {action.default!r} not shown"
        if action.choices and action.metavar is None:
            assert "{" + ",".join(map(str, action.choices)) + "}" in text, (name, flag)


def test_every_command_is_listed():
    assert len(_commands()) == len(COMMANDS)


def test_the_command_line_is_built_without_importing_jax_or_pandas():
    """Every ``lantern-jax`` run builds the whole parser first (``--help`` and argument errors
    answer from it): it imports neither JAX nor pandas (about 2 s on a 2-core CPU), so those
    answers are immediate."""
    import subprocess
    import sys

    code = ("import sys; from lantern_jax.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('jax', 'pandas', 'numpy') if m in sys.modules))")  # fmt: skip
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)  # fmt: skip
    assert res.returncode == 0, res.stderr
    loaded = res.stdout.strip()
    assert "jax" not in loaded and "pandas" not in loaded, loaded
