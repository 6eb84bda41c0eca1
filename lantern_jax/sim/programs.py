"""Compiled programs of this process: a bounded cache in front of the program store.

* :func:`executable` — AOT-compile a jitted function for its arguments once (keyed by the
  function, its static arguments and the arguments' structure, shapes and dtypes); with an
  identity, the program is also kept on disk by :mod:`lantern_jax.io.program_store` and loaded
  from there by a later process;
* :func:`stored` — a jitted function called through :func:`executable` (and the store);
* :func:`remember` — build a value (a jitted function, usually) once per key;
* :func:`abstract` — ``jax.eval_shape`` of a package function once per argument structure,
  kept in the program store for later processes (an abstract trace of the observation costs
  about a second).

Both caches keep at most :data:`MAX_PROGRAMS` entries (least recently used dropped).
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from lantern_jax.io import program_store

MAX_PROGRAMS = 32  # compiled programs kept in this process (least recently used dropped)

_EXECUTABLES: collections.OrderedDict[tuple, Any] = collections.OrderedDict()
#: The program store's key of each program in :data:`_EXECUTABLES` that has one.
_STORE_KEYS: dict[tuple, str] = {}
_BUILT: collections.OrderedDict[tuple, Any] = collections.OrderedDict()


def remember(key: tuple, build) -> Any:
    """``build()`` once per ``key`` (what the built function depends on besides its
    arguments), in a bounded cache (:data:`MAX_PROGRAMS` entries, least recently used
    dropped)."""
    if key in _BUILT:
        _BUILT.move_to_end(key)
    else:
        _BUILT[key] = build()
        while len(_BUILT) > MAX_PROGRAMS:
            _BUILT.popitem(last=False)
    return _BUILT[key]


def _avals(tree: Any) -> tuple:
    """Tree structure (static settings included), shapes and dtypes of arguments."""
    leaves, treedef = jax.tree.flatten(tree)
    return treedef, tuple((tuple(np.shape(x)), str(np.result_type(x))) for x in leaves)


def _key(fn, static: dict, args: tuple) -> tuple:
    return (fn, tuple(sorted(static.items())), _avals(args))


def executable(fn, *args, static: dict | None = None, timings: dict | None = None,
               identity: Any = None, stage: Callable[[str], None] | None = None):  # fmt: skip
    """AOT-compile ``fn(*args, **static)`` once per program (bounded in-process cache keyed by
    the function, its static arguments and the arguments' structure, shapes and dtypes).

    With an ``identity`` (what determines the program besides the package's code and the
    arguments, :func:`lantern_jax.io.program_store.program_key`) the compiled program is also kept
    on disk in the program store and, in a later process, loaded from there.  After an edit of
    the package the key is new; a program that still lowers to what an earlier key's did is
    then loaded from that entry once lowered
    (:func:`lantern_jax.io.program_store.load_lowered`), and kept under the new key.

    ``timings`` (optional) receives the seconds of tracing and lowering (``"trace + lower"``),
    of XLA's compilation or the load from JAX's persistent cache (``"XLA compile"``) and of a
    load from the program store (``"program load"``); all 0 when the program was already
    compiled in this process.  ``stage`` (optional) is called with ``"compiling"`` just before
    a program is traced and compiled (not when it is found in this process or the program
    store).
    """
    static = static or {}
    key = _key(fn, static, args)
    spent = {"trace + lower": 0.0, "XLA compile": 0.0, "program load": 0.0}
    if key in _EXECUTABLES:
        _EXECUTABLES.move_to_end(key)
        if key in _STORE_KEYS:
            program_store.touch(_STORE_KEYS[key])  # used: it must not age out of the store
    else:
        t0 = time.perf_counter()
        stored = program_store.program_key(identity, args) if identity is not None else None
        exe = program_store.load(stored) if stored is not None else None
        if exe is not None:
            spent["program load"] = time.perf_counter() - t0
        else:
            if stage is not None:
                stage("compiling")
            lowered = fn.lower(*args, **static)
            t1 = time.perf_counter()
            spent["trace + lower"] = t1 - t0
            # kept under another key for the same lowered program (the package edited since)
            as_lowered = program_store.lowered_key(identity, args, lowered) if stored else None
            exe = program_store.load_lowered(as_lowered, stored, lowered) if as_lowered else None
            if exe is not None:
                spent["program load"] = time.perf_counter() - t1
            else:
                t2 = time.perf_counter()
                exe, fresh = program_store.compile_lowered(lowered)
                spent["XLA compile"] = time.perf_counter() - t2
                if stored is not None and fresh:
                    program_store.save(stored, exe, as_lowered)
        _EXECUTABLES[key] = exe
        if stored is not None:
            _STORE_KEYS[key] = stored
        while len(_EXECUTABLES) > MAX_PROGRAMS:
            _STORE_KEYS.pop(_EXECUTABLES.popitem(last=False)[0], None)
    if timings is not None:
        timings.update(spent)
    return _EXECUTABLES[key]


def stored(fn, identity: Any) -> Callable[..., Any]:
    """``fn`` as a callable that runs, for each call's arguments, the program :func:`executable`
    gives (compiled once per argument structure, kept in the program store under ``identity``).
    Each call pays for :func:`executable`'s lookup (about 1.4 ms for a stress cell's soft
    program of a learned policy, whose parameters are hundreds of leaves)."""

    def call(*args: Any) -> Any:
        return executable(fn, *args, identity=identity)(*args)

    return call


def abstract(name: str, fn: Callable, *args: Any, parts: tuple[str, ...] = ()) -> Any:
    """``jax.eval_shape(fn, *args)``, computed once per argument structure: in this process
    (:func:`remember`), and through the program store (:func:`lantern_jax.io.program_store.kept`)
    in later ones.

    Only for a function of this package's code (the store's key covers the code through
    :func:`lantern_jax.io.program_store.environment`, not the function object): ``name`` names
    it, ``parts`` whatever else it depends on besides the arguments' structure, leaf shapes
    and dtypes (a policy's sensors, say).
    """
    leaves, treedef = jax.tree.flatten(args)
    shapes = repr([(tuple(np.shape(x)), str(jax.numpy.result_type(x))) for x in leaves])
    key = program_store.value_key("abstract", name, str(treedef), shapes, *parts)
    return remember(("abstract", key or f"{name}|{treedef}|{shapes}|{parts}"),
                    lambda: program_store.kept(key, lambda: jax.eval_shape(fn, *args)))
