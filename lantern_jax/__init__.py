"""lantern_jax: the LANTERN cooperative-warning benchmark as a JAX-vectorized simulator.

The names a user needs, importable from the package itself::

    import lantern_jax as lj

    result = lj.evaluate(["expert", "coop"], suite=lj.load_suite())
    print(result.family_table)

* :func:`evaluate` — every execution of a suite for one or several policies, scored by the
  CUS, with intervals (:mod:`lantern_jax.apps.evaluation`);
* :func:`write_outputs` — an evaluation's files, as ``lantern-jax evaluate --out`` writes them
  (tables, route-level CSV and schema, reproducibility manifest, run record);
* :func:`load_suite` — a suite of route pairs (the built-in ``lantern-v3`` by default);
* :class:`Policy` and :func:`get_policy` — a policy of your own, or a registered one;
  :func:`register_policy_source` — a policy in a file or module (``file.py:NAME``);
* :func:`rollout` — one execution, tick by tick, for your own loops;
* :class:`Settings`, :class:`ScoringSettings`, :class:`ProtocolSettings`, :class:`TextBank`,
  :class:`ActorSettings`, :data:`DEFAULT_SETTINGS` and :func:`default_settings` — the values a
  simulation reads, passed as arguments (:mod:`lantern_jax.sim.settings`);
* :class:`FamilyRecord` and :func:`register_family` — a hazard family of your own
  (``docs/families.md``).

* :func:`setup` — JAX's CPU devices and compilation cache as the command line has them
  (:mod:`lantern_jax.core.jax_setup`; done by ``import lantern_jax`` itself, the device count
  only when JAX is not imported yet).

The names are loaded on first use, so ``import lantern_jax`` stays cheap and does not import
JAX; where JAX is not imported yet it exposes one XLA CPU device per core, and in any case it
turns JAX's persistent compilation cache on unless the process configured or turned off its
own (``LANTERN_JAX_AUTO_SETUP=0`` leaves both alone).
"""

from __future__ import annotations

import importlib
import importlib.metadata
from typing import TYPE_CHECKING, Any

from lantern_jax.core import jax_setup, renamed

# One XLA CPU device per core (when JAX is not imported yet) and the persistent compilation
# cache, as the command line has them (lantern_jax.core.jax_setup; LANTERN_JAX_AUTO_SETUP=0: off).
jax_setup.auto_setup()
# Renamed modules stay importable under their old names for one release (lantern_jax.core.renamed).
renamed.install()

try:
    #: The installed package's version (``pyproject.toml``); ``lantern-jax --version``.
    __version__ = importlib.metadata.version("lantern-jax")
except importlib.metadata.PackageNotFoundError:  # a checkout on sys.path, not installed
    __version__ = "0+unknown"

#: public name -> module that defines it
_EXPORTS = {
    "evaluate": "lantern_jax.apps.evaluation",
    "EvalResult": "lantern_jax.apps.evaluation",
    "load_suite": "lantern_jax.scenarios.suite",
    "Suite": "lantern_jax.scenarios.suite",
    "Policy": "lantern_jax.policies.base",
    "get_policy": "lantern_jax.policies.registry",
    "register_policy_source": "lantern_jax.policies.registry",
    "policy_names": "lantern_jax.policies.registry",
    "rollout": "lantern_jax.sim.rollout",
    "write_outputs": "lantern_jax.report",
    "setup": "lantern_jax.core.jax_setup",
    "Settings": "lantern_jax.sim.settings",
    "DEFAULT_SETTINGS": "lantern_jax.sim.settings",
    "default_settings": "lantern_jax.sim.settings",
    "ScoringSettings": "lantern_jax.scoring.thresholds",
    "ProtocolSettings": "lantern_jax.sim.protocol",
    "ActorSettings": "lantern_jax.dynamics.actors",
    "TextBank": "lantern_jax.scenarios.warnings",
    "FamilyRecord": "lantern_jax.scenarios.registry",
    "register_family": "lantern_jax.scenarios.registry",
}

__all__ = [
    "ActorSettings",
    "DEFAULT_SETTINGS",
    "EvalResult",
    "FamilyRecord",
    "Policy",
    "ProtocolSettings",
    "ScoringSettings",
    "Settings",
    "Suite",
    "TextBank",
    "default_settings",
    "evaluate",
    "get_policy",
    "load_suite",
    "policy_names",
    "register_family",
    "register_policy_source",
    "rollout",
    "setup",
    "write_outputs",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'lantern_jax' has no attribute {name!r}")
    jax_setup.warn_pending()
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


if TYPE_CHECKING:  # for type checkers and IDEs: the same names, imported eagerly
    from lantern_jax.apps.evaluation import EvalResult, evaluate
    from lantern_jax.core.jax_setup import setup
    from lantern_jax.dynamics.actors import ActorSettings
    from lantern_jax.policies.base import Policy
    from lantern_jax.policies.registry import get_policy, policy_names, register_policy_source
    from lantern_jax.report import write_outputs
    from lantern_jax.scenarios.registry import FamilyRecord, register_family
    from lantern_jax.scenarios.suite import Suite, load_suite
    from lantern_jax.scenarios.warnings import TextBank
    from lantern_jax.scoring.thresholds import ScoringSettings
    from lantern_jax.sim.protocol import ProtocolSettings
    from lantern_jax.sim.rollout import rollout
    from lantern_jax.sim.settings import DEFAULT_SETTINGS, Settings, default_settings
