"""JAX's process set-up for this package: one XLA CPU device per core and the persistent
compilation cache — what makes the command line fast, for the Python API too.

The CPU device count must be set before JAX starts; the cache can be turned on at any time.
The command line does both, and so does ``import lantern_jax`` (:func:`auto_setup`;
``LANTERN_JAX_AUTO_SETUP=0`` turns that off)::

    import lantern_jax as lj       # before jax: one CPU device per core, the compile cache
    result = lj.evaluate("coop")

Where JAX was imported first, its CPU device count stays JAX's (one device: the fused rollout
then runs on one core); ``import lantern_jax`` still turns the compilation cache on
(:func:`late_cache_setup`), and :func:`setup` says, in the :class:`SetupReport` it returns, why
the device count could not be set.  Nothing is changed that the process or its environment
already decides: ``XLA_FLAGS`` with a device count, ``LANTERN_JAX_CPU_DEVICES``, a compilation
cache folder already configured or the cache turned off.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import warnings
from collections.abc import Callable

#: Environment variable that sets the number of XLA CPU devices (default: one per core).
CPU_DEVICES_ENV = "LANTERN_JAX_CPU_DEVICES"
#: Environment variable that sets the split path's worker threads
#: (:func:`lantern_jax.sim.split.worker_count`).
SPLIT_WORKERS_ENV = "LANTERN_JAX_SPLIT_WORKERS"
#: Environment variable that sets the fused path's slots per device
#: (:func:`lantern_jax.sim.engine.compact_slots`).
COMPACT_SLOTS_ENV = "LANTERN_JAX_COMPACT_SLOTS"
#: The variables that hold a count (a whole number >= 1), checked together by
#: :func:`check_counts` before a command runs.
COUNT_ENVS = (CPU_DEVICES_ENV, SPLIT_WORKERS_ENV, COMPACT_SLOTS_ENV)
#: Environment variable that moves the persistent compilation cache.
CACHE_DIR_ENV = "LANTERN_JAX_CACHE_DIR"
#: Environment variable that turns the automatic set-up on first use off (``0``).
AUTO_SETUP_ENV = "LANTERN_JAX_AUTO_SETUP"
#: JAX's variable of the shortest compilation it keeps in its persistent cache (s).
CACHE_MIN_COMPILE_ENV = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"
#: s, what lantern_jax keeps unless that variable is set: every program (JAX's default keeps
#: only those of >= 1 s).  An evaluation's scoring and tables run about 30 small programs
#: (20-400 ms each to compile, about 1 s together on a 2-core CPU, every process); loading
#: them back costs milliseconds (docs/performance.md, the inner loop).
CACHE_MIN_COMPILE_S = 0.0
#: JAX's variable naming the XLA caches it keeps inside the persistent cache folder.  JAX's
#: default enables the GPU autotuning cache there, whose path (the cache folder's) then becomes
#: part of every program's cache key -- on the CPU too, where it does nothing else: a cache
#: folder copied or moved elsewhere (a CI cache restored at another path, a folder linked to
#: another's entries) compiles every program again.
XLA_CACHES_ENV = "JAX_PERSISTENT_CACHE_ENABLE_XLA_CACHES"
#: What lantern_jax sets it to unless it is set, where no GPU plugin of JAX is installed
#: (:func:`xla_caches_default`): none (the name matches no cache), so a program's key depends
#: on the program and the compiler only.
XLA_CACHES_CPU = "none"

_PENDING = ""  # a set-up problem found at import, reported on first use


def _warn(message: str) -> None:
    """A :class:`UserWarning` at the line that called the caller of this module's function."""
    warnings.warn(message, stacklevel=3)


def _defer(message: str) -> None:
    """Keep ``message`` for :func:`warn_pending` (a problem found at import)."""
    global _PENDING
    _PENDING = "; ".join(m for m in (_PENDING, message) if m)


class SetupError(ValueError):
    """An environment variable of the set-up holds a value it cannot use; the message names
    the variable."""


@dataclasses.dataclass(frozen=True)
class SetupReport:
    """What :func:`setup` did."""

    #: XLA CPU devices asked for in ``XLA_FLAGS`` (None: none asked for, JAX's default)
    cpu_devices: int | None
    #: why the device count could not be set (JAX already imported), else ""
    cpu_devices_note: str
    #: the persistent compilation cache folder in use (None: off)
    compile_cache: str | None


def env_count(name: str) -> int | None:
    """The count in environment variable ``name``: a whole number >= 1, or None when unset.

    Raises:
        SetupError: naming the variable when it holds anything else.
    """
    given = os.environ.get(name)
    if given is not None and not (given.strip().isdigit() and int(given) >= 1):
        raise SetupError(f"environment variable {name}: expected a whole number >= 1, got "
                         f"{given!r}")  # fmt: skip
    return None if given is None else int(given)


def check_counts() -> None:
    """Check every count variable (:data:`COUNT_ENVS`) at once, so a bad one is refused before
    any work, not when the code that reads it first runs.

    Raises:
        SetupError: naming the first variable that is set to something other than a whole
            number >= 1.
    """
    for name in COUNT_ENVS:
        env_count(name)


def cpu_device_request() -> int | None:
    """The CPU device count to ask XLA for: ``$LANTERN_JAX_CPU_DEVICES``, else one per core
    this process may run on; None when ``XLA_FLAGS`` already sets one.

    Raises:
        SetupError: when ``LANTERN_JAX_CPU_DEVICES`` is not a whole number >= 1.
    """
    given = env_count(CPU_DEVICES_ENV)
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return None
    if given is not None:
        return given
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def expose_cpu_cores() -> int | None:
    """Expose one XLA CPU device per core (or ``$LANTERN_JAX_CPU_DEVICES``), so that the
    evaluator can split its batch over them; only possible before JAX is imported.

    Returns:
        The device count set in ``XLA_FLAGS``, or None when nothing was set (JAX already
        imported, ``XLA_FLAGS`` already sets a count, or one device).

    Raises:
        SetupError: when ``LANTERN_JAX_CPU_DEVICES`` is not a whole number >= 1.
    """
    n = cpu_device_request()
    if "jax" in sys.modules or n is None or n <= 1:
        return None
    flags = os.environ.get("XLA_FLAGS", "")
    os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n}".strip()
    return n


def _flag_device_count() -> int | None:
    """The CPU device count ``XLA_FLAGS`` asks for, or None."""
    for flag in os.environ.get("XLA_FLAGS", "").split():
        name, _, value = flag.partition("=")
        if name == "--xla_force_host_platform_device_count" and value.isdigit():
            return int(value)
    return None


def compile_cache_dir() -> str:
    """Where compiled programs are kept between runs.

    ``$LANTERN_JAX_CACHE_DIR`` if set, else JAX's own ``$JAX_COMPILATION_CACHE_DIR`` if set,
    else ``$XDG_CACHE_HOME/lantern-jax/jax`` (``~/.cache/lantern-jax/jax`` by default).
    """
    for var in (CACHE_DIR_ENV, "JAX_COMPILATION_CACHE_DIR"):
        if os.environ.get(var):
            return os.environ[var]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "lantern-jax", "jax")


def xla_caches_default() -> str | None:
    """The value lantern_jax gives ``$JAX_PERSISTENT_CACHE_ENABLE_XLA_CACHES`` (JAX's
    ``jax_persistent_cache_enable_xla_caches``): :data:`XLA_CACHES_CPU` when the variable is
    unset and no GPU plugin of JAX (the ``jax_plugins`` namespace) is installed, else ``None``
    (JAX's own choice stands: on a GPU its autotuning cache saves compile time)."""
    import importlib.util

    if XLA_CACHES_ENV in os.environ or importlib.util.find_spec("jax_plugins") is not None:
        return None
    return XLA_CACHES_CPU


def cache_dir_problem(path: str) -> str | None:
    """Why the folder ``path`` cannot hold the compilation cache, or None when it can (as far
    as can be told without creating it): the nearest part of the path that exists must be a
    folder this process may write in.  A folder a file stands in the way of, or one on a
    read-only file system (a read-only home directory), would otherwise fail at every compile,
    and keep nothing."""
    p = os.path.abspath(os.path.expanduser(path))
    while not os.path.exists(p) and os.path.dirname(p) != p:
        p = os.path.dirname(p)
    if not os.path.isdir(p):
        return f"{p} is not a folder"
    if not os.access(p, os.W_OK | os.X_OK):
        return f"{p} is not writable"
    return None


def unusable_cache_message(path: str, problem: str) -> str:
    """The one-line message of a compilation cache folder that cannot be used."""
    return (f"the compilation cache folder {path} cannot be used ({problem}): compiled "
            f"programs are not kept between runs; set {CACHE_DIR_ENV} to a writable "
            "folder")  # fmt: skip


def configure_compile_cache(
    enabled: bool, warn: Callable[[str], None] | None = None
) -> str | None:
    """Turn JAX's persistent compilation cache on (in :func:`compile_cache_dir`) or off.

    A second run of the same evaluation then loads its compiled programs instead of compiling
    them again, also from a cache folder copied or moved elsewhere (no folder path in the
    programs' keys on a CPU-only install, :func:`xla_caches_default`).  JAX reads the folder
    at its next compile.

    A folder that cannot be used (:func:`cache_dir_problem`) leaves the cache off, said once
    through ``warn`` (default: a :class:`UserWarning`).

    Returns:
        The cache folder, or None when the cache is off.
    """
    # deferred: JAX is configured here before its first import
    import jax

    path = compile_cache_dir()
    problem = cache_dir_problem(path) if enabled else None
    jax.config.update("jax_enable_compilation_cache", enabled and problem is None)
    if problem is not None:
        (warn or _warn)(unusable_cache_message(path, problem))
    if not enabled or problem is not None:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    if CACHE_MIN_COMPILE_ENV not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_S)
    caches = xla_caches_default()
    if caches is not None:
        jax.config.update("jax_persistent_cache_enable_xla_caches", caches)
    return path


def setup(compile_cache: bool = True) -> SetupReport:
    """Set JAX up as the command line does: one XLA CPU device per core (when JAX is not
    imported yet) and the persistent compilation cache (unless one is configured already).

    Args:
        compile_cache: keep compiled programs between runs (:func:`compile_cache_dir`; a
            folder that cannot be used leaves the cache off, with a warning); ``False`` turns
            the cache off.

    Returns:
        :class:`SetupReport`: the device count asked for, why it could not be (if so), and the
        cache folder.

    Raises:
        SetupError: when ``LANTERN_JAX_CPU_DEVICES`` is not a whole number >= 1.
    """
    late = "jax" in sys.modules
    n = expose_cpu_cores() or _flag_device_count()
    note = ""
    if late and (cpu_device_request() or 1) > 1:
        note = ("JAX was imported before lantern_jax set it up: it keeps its own CPU device "
                "count (one by default; the evaluation then runs on one core). Import "
                "lantern_jax before jax, or set XLA_FLAGS="
                "--xla_force_host_platform_device_count=N")  # fmt: skip
    # deferred: JAX is configured here before its first import
    import jax

    configured = jax.config.jax_compilation_cache_dir
    if not compile_cache:
        cache = configure_compile_cache(False)
    elif configured and jax.config.jax_enable_compilation_cache:
        cache = configured
    else:  # a folder it cannot use: warned at the caller's line
        cache = configure_compile_cache(True, warn=lambda m: warnings.warn(m, stacklevel=4))
    return SetupReport(cpu_devices=n, cpu_devices_note=note, compile_cache=cache)


def auto_setup() -> None:
    """The set-up at ``import lantern_jax``, unless ``LANTERN_JAX_AUTO_SETUP`` is ``0``.

    When JAX is not imported yet (without importing it): one XLA CPU device per core
    (:func:`expose_cpu_cores`) and ``$JAX_COMPILATION_CACHE_DIR`` set to
    :func:`compile_cache_dir` unless already set (JAX reads it when it starts), and JAX's XLA
    caches as :func:`xla_caches_default` says.  A bad ``LANTERN_JAX_CPU_DEVICES`` changes
    nothing here, nor does a cache folder that cannot be used (:func:`cache_dir_problem`: the
    cache then stays off); either is reported, as a warning, on the first use of a name of the
    package (:func:`warn_pending`).

    When JAX was imported first, its device count can no longer change, but its persistent
    cache still can: :func:`late_cache_setup`.
    """
    global _PENDING
    if os.environ.get(AUTO_SETUP_ENV, "1").strip() == "0":
        return
    if "jax" in sys.modules:
        late_cache_setup()
        return
    try:
        expose_cpu_cores()
    except SetupError as e:
        _PENDING = f"{e}; lantern_jax leaves JAX's CPU device count as it is"
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        path = compile_cache_dir()
        problem = cache_dir_problem(path)
        if problem is None:
            os.environ["JAX_COMPILATION_CACHE_DIR"] = path
        else:
            _defer(unusable_cache_message(path, problem))
    os.environ.setdefault(CACHE_MIN_COMPILE_ENV, str(CACHE_MIN_COMPILE_S))
    caches = xla_caches_default()
    if caches is not None:
        os.environ[XLA_CACHES_ENV] = caches


def late_cache_setup() -> str | None:
    """Turn JAX's persistent compilation cache on in :func:`compile_cache_dir` in a process
    that imported JAX before ``lantern_jax`` (``import jax`` first, as most scripts and
    notebooks begin), unless the process already decided: a cache folder configured
    (``$JAX_COMPILATION_CACHE_DIR`` when JAX started, or ``jax.config``) or the cache turned
    off (``jax_enable_compilation_cache`` false).  JAX reads the folder at its next compile,
    so this works after earlier compiles too.

    Without it such a process kept nothing between runs: the program store, which lives in the
    cache folder, was off as well, and every run compiled the world program again (a new
    policy on the 6-pair subset: 10.7 s to the table in a second process, against 1.6 s with
    the cache; ``docs/performance.md``).

    A folder that cannot be used is reported on the first use of a name of the package
    (:func:`warn_pending`), as :func:`auto_setup` reports its problems.

    Returns:
        The cache folder turned on, or None when it is not.
    """
    import jax

    if jax.config.jax_compilation_cache_dir or not jax.config.jax_enable_compilation_cache:
        return None
    return configure_compile_cache(True, warn=_defer)


def warn_pending() -> None:
    """Warn, once, about a set-up that :func:`auto_setup` could not do."""
    global _PENDING
    if _PENDING:
        message, _PENDING = _PENDING, ""
        warnings.warn(message, stacklevel=3)
