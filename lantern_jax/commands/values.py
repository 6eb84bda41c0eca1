"""The numeric options' value types: every number the command line takes is checked by argparse
itself, before anything is loaded or compiled, and a bad one is refused in one line naming the
option, the value and the range (exit 2).

Each function returns an argparse ``type=`` converter::

    parser.add_argument("--seed", type=seed())
    parser.add_argument("--restarts", type=whole(1, 1024))
    parser.add_argument("--budget-s", type=number(0.0, 86400.0, low_open=True))
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from lantern_jax.core.constants import MAX_SEED

#: Largest count (pairs, sequences, epochs, ...) any command takes.
MAX_COUNT = 10**6


def whole(low: int, high: int | None = None) -> Callable[[str], int]:
    """A whole number in ``[low, high]`` (``high`` None: no upper bound)."""
    where = f">= {low}" if high is None else f"in {low} .. {high}"

    def convert(text: str) -> int:
        try:
            value = int(text.strip(), 10)
        except (ValueError, AttributeError):
            raise argparse.ArgumentTypeError(f"expected a whole number {where}, got "
                                             f"{text!r}") from None  # fmt: skip
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"expected a whole number {where}, got {value}")
        return value

    convert.__name__ = "whole number"
    return convert


def count(high: int = MAX_COUNT) -> Callable[[str], int]:
    """A count: a whole number in ``1 .. high``."""
    return whole(1, high)


def seed() -> Callable[[str], int]:
    """A generator seed: a whole number in ``0 .. MAX_SEED``."""
    return whole(0, MAX_SEED)


def number(low: float, high: float | None = None, low_open: bool = False) -> Callable[[str], float]:
    """A finite number in ``[low, high]`` (``(low, high]`` with ``low_open``)."""
    left = "(" if low_open else "["
    where = f"in {left}{low:g}, {'inf' if high is None else f'{high:g}'}]"

    def convert(text: str) -> float:
        try:
            value = float(text.strip())
        except (ValueError, AttributeError):
            raise argparse.ArgumentTypeError(f"expected a number {where}, got {text!r}") from None
        bad = (not math.isfinite(value) or value < low or (low_open and value == low)
               or (high is not None and value > high))  # fmt: skip
        if bad:
            raise argparse.ArgumentTypeError(f"expected a finite number {where}, got {text}")
        return value

    convert.__name__ = "number"
    return convert
