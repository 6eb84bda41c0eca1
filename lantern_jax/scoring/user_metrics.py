"""Measurements of your own, folded tick by tick beside the CUS components and written as
columns of the route table.

A :class:`Metric` follows the components' contract (:mod:`lantern_jax.scoring.components`),
with one signature per function:

* ``init(settings) -> state`` — the accumulators before the first tick (a pytree of arrays);
* ``update(state, sample, tick, settings) -> state`` — fold one 20 Hz tick: ``sample`` is the
  tick's measurement (:class:`~lantern_jax.scoring.sample.TickSample`: ego speed and
  acceleration, distances, flags), ``tick`` the shared per-tick context
  (:class:`~lantern_jax.scoring.components.context.Tick`: time, protocol times so far);
* ``value(state, context, settings) -> ()`` float — the per-execution value, from the final
  accumulators and the final shared context
  (:class:`~lantern_jax.scoring.components.context.Context`).

``init`` and ``update`` see one execution (no batch axis) and run inside the compiled rollout;
``value``, like the components' hard scores, is elementwise: the evaluator applies it to a
whole batch of final states at once (a leading axis on every array), so write it with
elementwise operations (``jnp.minimum``, ``jnp.where``, arithmetic), not reductions.  The
metrics are a setting (``ScoringSettings(metrics=(m, ...))``, static: another list compiles
another program), so no cache answers for them with a program of another list.  An evaluation
with metrics writes, per metric, the column ``<name>`` (the row's Route A execution) and
``B_<name>`` (its Route B execution) after the schema's columns, and describes both in the
result's schema (name, unit, description) and its manifest.  They never enter the CUS.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp

Array = jax.Array

#: What a metric's name may look like (it names route-table columns).
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_]{0,47}")


@dataclass(frozen=True)
class Metric:
    """A per-execution measurement of your own (see the module docstring).

    Attributes:
        name: lower-case letters, digits and ``_``, starting with a letter; the route table's
            column (``B_<name>`` for Route B).
        init: ``settings -> state``.
        update: ``(state, sample, tick, settings) -> state``.
        value: ``(state, context, settings) -> ()`` float.
        unit: the value's unit (``"m/s^2"``, ``"s"``, ``"-"``).
        description: one sentence for the schema.
    """

    name: str
    init: Callable[[Any], Any]
    update: Callable[[Any, Any, Any, Any], Any]
    value: Callable[[Any, Any, Any], Array]
    unit: str = "-"
    description: str = ""

    def columns(self) -> list[dict]:
        """The schema's entries of its two route-table columns."""
        about = self.description or f"the user metric {self.name}"
        return [
            dict(name=name, dtype="float64", unit=self.unit, description=f"{about} ({route}).",
                 missing="NaN where the value is not finite")  # fmt: skip
            for name, route in ((self.name, "Route A execution of the row's condition"),
                                (f"B_{self.name}", "Route B execution"))  # fmt: skip
        ]

    def record(self) -> dict:
        """What a manifest records of it."""
        return dict(name=self.name, unit=self.unit, description=self.description)


def metric_problem(metric: Any, taken: set[str]) -> str | None:
    """Why ``metric`` cannot be scored beside the columns ``taken`` (None when it can)."""
    if not isinstance(metric, Metric):
        return f"expected a Metric, got {type(metric).__name__}"
    if not isinstance(metric.name, str) or not NAME_PATTERN.fullmatch(metric.name):
        return (f"name {metric.name!r}: 1-48 lower-case letters, digits or _, starting with a "
                "letter")  # fmt: skip
    for field in ("init", "update", "value"):
        if not callable(getattr(metric, field)):
            return f"{metric.name}: {field} must be callable"
    clash = {metric.name, f"B_{metric.name}"} & taken
    if clash:
        return f"{metric.name}: column(s) {sorted(clash)} already exist"
    return None


def init_states(metrics: tuple[Metric, ...], settings: Any) -> tuple:
    """Every metric's accumulators before the first tick."""
    return tuple(m.init(settings) for m in metrics)


def update_states(metrics: tuple[Metric, ...], states: tuple, sample: Any, tick: Any,
                  settings: Any) -> tuple:  # fmt: skip
    """Fold one tick into every metric's accumulators."""
    return tuple(m.update(s, sample, tick, settings) for m, s in zip(metrics, states, strict=True))


def values(metrics: tuple[Metric, ...], states: tuple, context: Any, settings: Any) -> tuple:
    """Every metric's float32 value of one execution (or, elementwise, of a batch)."""
    return tuple(
        jnp.asarray(m.value(s, context, settings), jnp.float32)
        for m, s in zip(metrics, states, strict=True)
    )
