"""Compiled evaluation programs kept on disk, so that a warm start skips tracing, lowering and
compiling.

JAX's persistent compilation cache keeps XLA's output, but finding it needs the program's
lowered text: every run still traces the whole simulator in Python and lowers it (about 2 s
for the evaluation's rollout on a 2-core CPU) before the cache answers, and then loads the
executable (about 1.5 s).  This store keeps the *loaded-ready executable itself*
(:mod:`jax.experimental.serialize_executable`), keyed by everything that determines the
program, so that a second run of the same evaluation goes straight from its arguments to a
callable program (0.75-0.9 s for a policy's three programs, measured in the README's speed
section).

**The key** (:func:`program_key`) is a SHA-256 over

* every file of this package, its modules and data (:func:`code_fingerprint`): any edit is a
  new key (also one made while a process runs, e.g. a module edited and reloaded);
* the versions of :data:`LIBRARIES` and of Python, the backend (platform, its version,
  device kinds and ids, process count), ``XLA_FLAGS`` and the JAX options that change what a
  trace produces (:data:`JAX_OPTIONS`);
* what the caller names as the program's identity (for the rollout: the policy's program --
  act function, sensors, carry -- and the slot layout), described by :func:`describe`:
  functions by module and qualified name plus everything they close over, this package's
  objects by their fields, arrays by their bytes;
* the arguments' tree structure (the static part of the settings included: tick windows, the
  user metrics; written node by node where JAX's own text names a function by its address, as
  a learned model's parameters do: :func:`structure_text`) and every leaf's shape, dtype and
  placement (the text bank's tables: their rows, a multiple of 128 texts).

Every value a user may change is an argument (:class:`lantern_jax.sim.settings.Settings`, the
policy's parameters), never baked into the program, so the key needs no picture of the
package's module state: a changed threshold runs the stored program with its new value.

A program whose identity cannot be described with certainty (a function from outside this
package, such as a user's own policy or a host-callback model; an object whose text form hides
part of its state) is not stored: it is traced and compiled as before, and JAX's persistent
cache still serves its XLA compilation.  Programs that close over constant arrays cannot be
serialized and are not stored either, and neither is a program that JAX's own cache served
or that JAX gave back from memory (:func:`compile_lowered` says why).

**Where**: the ``lantern-programs`` folder inside JAX's persistent compilation cache folder,
whenever that cache is on (``lantern-jax`` turns it on by default; ``--no-compile-cache`` and
``jax.config.update("jax_enable_compilation_cache", False)`` turn the store off with it), and
never under JAX's distributed runtime.  Files are written atomically (two processes storing
the same program leave one whole entry); at most :data:`MAX_STORED_BYTES` of programs are kept
(and at most :data:`MAX_STORED_PROGRAMS` of them), the least recently used removed first.  An
entry records its own key and the SHA-256 of its executable: an entry that cannot be read back
(truncated, corrupted, of another store format) or that holds another program than its name
says (entries swapped or copied under another name) is deleted with a warning and the program
compiled again (JAX's persistent cache still serves the XLA compilation).

**Values** (:func:`save_value`, :func:`load_value`): a few small results that every process
would otherwise compute again before its first program runs -- the split path's world
signature, a policy's observation shapes, the built-in families' worlds of a suite -- are kept
beside the programs (``*.value``, at most :data:`MAX_STORED_VALUES`), keyed by :func:`value_key`
(the same environment and code fingerprint, and texts naming everything else the value depends
on).  An entry that cannot be read back or holds another key is deleted and the value computed
again.

Loading an executable (or a value) runs code from the file, like JAX's own cache: keep the
cache folder writable by you alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import functools
import hashlib
import importlib.metadata as md
import logging
import os
import pickle
import sys
import threading
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
from jax import monitoring

from lantern_jax.io.files import atomic_write

log = logging.getLogger(__name__)

#: Sub-folder of JAX's compilation cache folder that holds the stored programs.
STORE_SUBDIR = "lantern-programs"
#: Bytes of programs kept on disk, the least recently used removed first.  Programs differ in
#: size by a hundredfold: a policy's own program on the split path is 0.15-0.5 MB, the world
#: program and a fused evaluation 4-15 MB, a stress cell's three programs 22 MB (the soft
#: program 15 MB; ``ego``'s first PE cell, 32-dimensional adversary).  A budget in bytes keeps
#: a study of many cells whole: under a count of 32 programs, a study whose programs outnumbered
#: 32 (about a dozen cells) found none of them when run again, each cell's removed by the
#: cells stored after it.
#: JAX's own persistent cache, beside it, is unbounded.
MAX_STORED_BYTES = 2 * 1024**3
#: Most programs kept on disk whatever their size (a bound on the folder's entries), and most
#: values (``*.value``) kept apart.  (:data:`lantern_jax.sim.programs.MAX_PROGRAMS` bounds the
#: programs held in a process.)
MAX_STORED_PROGRAMS = 1024
MAX_STORED_VALUES = 32
#: Bumped when the file layout changes (old entries then simply miss).
STORE_FORMAT = 2
#: JAX options that change what a trace or a compilation produces.
JAX_OPTIONS = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_numpy_dtype_promotion",
    "jax_numpy_rank_promotion",
    "jax_default_prng_impl",
    "jax_threefry_partitionable",
    "jax_debug_nans",
    "jax_debug_infs",
    "jax_disable_jit",
)
_PACKAGE = "lantern_jax"
#: Libraries whose versions are part of every key: their functions, classes and dataclass
#: objects are described by name and fields like this package's own.
LIBRARIES = ("jax", "jaxlib", "flax", "numpy", "optax")
_SUFFIX = ".program"
_VALUE_SUFFIX = ".value"  # small values kept beside the programs (save_value)
#: The index of the programs by what they lower to (:func:`lowered_key`): each entry holds the
#: key of the program entry that was compiled from that lowered program.
_LOWERED_SUFFIX = ".lowered"
#: How :func:`prune` bounds each kind of entry after a write: programs by their bytes
#: (:data:`MAX_STORED_BYTES`, and :data:`MAX_STORED_PROGRAMS` of them), values and the index
#: by their count.
_BOUNDS = {
    _SUFFIX: {"max_bytes": MAX_STORED_BYTES},
    _VALUE_SUFFIX: {"keep": MAX_STORED_VALUES},
    _LOWERED_SUFFIX: {"keep": MAX_STORED_PROGRAMS},
}


class Unkeyable(Exception):
    """An identity that :func:`describe` cannot turn into a faithful text (the program is then
    compiled as usual and not stored)."""


def store_dir() -> Path | None:
    """The store folder, or ``None`` when the store is off (JAX's persistent compilation cache
    off or without a folder, or several processes)."""
    if not jax.config.jax_enable_compilation_cache:
        return None
    base = jax.config.jax_compilation_cache_dir
    if not base or jax.process_count() > 1:
        return None
    return Path(base) / STORE_SUBDIR


def _package_files() -> list[Path]:
    root = Path(__file__).resolve().parents[1]  # the package, above io/
    return [
        p for p in sorted(root.rglob("*"))
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
    ]  # fmt: skip


def code_fingerprint() -> str:
    """SHA-256 over the path and bytes of every file of this package: its modules and the
    data they may read while a program is traced (~3 MB; hashed again only when a file's size
    or modification time changed, e.g. a module edited and reloaded in a notebook)."""
    files = _package_files()
    return _fingerprint(tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in files))


@functools.lru_cache(maxsize=4)
def _fingerprint(signature: tuple) -> str:
    root = Path(__file__).resolve().parents[1]  # the package, above io/
    h = hashlib.sha256()
    for name, _, _ in signature:
        path = Path(name)
        h.update(str(path.relative_to(root)).encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def _version(name: str) -> str:
    try:
        return md.version(name)
    except md.PackageNotFoundError:
        return "absent"


def environment() -> dict[str, Any]:
    """What outside this package's code determines a compiled program (part of every key)."""
    devices = jax.devices()
    return dict(
        format=STORE_FORMAT,
        code=code_fingerprint(),
        python=sys.version_info[:2],
        packages={n: _version(n) for n in LIBRARIES},
        backend=jax.default_backend(),
        platform_version=getattr(devices[0].client, "platform_version", ""),
        devices=[(d.id, d.device_kind) for d in devices],
        processes=jax.process_count(),
        xla_flags=os.environ.get("XLA_FLAGS", ""),
        options={k: str(getattr(jax.config, k, None)) for k in JAX_OPTIONS},
    )


def _in(module: str | None, packages: tuple[str, ...]) -> bool:
    return bool(module) and any(module == p or module.startswith(p + ".") for p in packages)


def _ours(module: str | None) -> bool:
    """This package's code (covered by :func:`code_fingerprint`)."""
    return _in(module, (_PACKAGE,))


def _versioned(module: str | None) -> bool:
    """This package's code or a library whose version is part of the key."""
    return _in(module, (_PACKAGE, *LIBRARIES))


def _array_text(a: Any) -> str:
    a = np.ascontiguousarray(np.asarray(a))
    return f"array{a.shape}{a.dtype.str}:{hashlib.sha256(a.tobytes()).hexdigest()}"


def describe(obj: Any, _depth: int = 0) -> str:
    """A text that determines ``obj`` as far as tracing a program with it is concerned.

    Functions are named by module and qualified name and followed by what they close over
    (cells, defaults, attributes): the code itself is covered by :func:`code_fingerprint` or by
    the versions of :data:`LIBRARIES`, so only functions of this package and of those
    libraries are accepted.  Their objects (dataclasses, or with a ``__dict__``) are described
    by their fields, arrays by shape, dtype and the SHA-256 of their bytes, plain values by
    their ``repr``.  Other objects are accepted by ``repr`` only when it names no memory
    address and elides nothing.

    Raises:
        Unkeyable: for anything else (a function from another package, a lambda, an empty
            closure cell, an object whose text form is not faithful).
    """
    if _depth > 40:
        raise Unkeyable("nested too deeply")
    d = _depth + 1
    if obj is None or isinstance(obj, bool | int | float | complex | str | bytes):
        return f"{type(obj).__name__}:{obj!r}"
    if isinstance(obj, enum.Enum):
        return f"enum:{type(obj).__module__}.{type(obj).__qualname__}.{obj.name}"
    if isinstance(obj, np.ndarray | np.generic | jax.Array):
        return _array_text(obj)
    if isinstance(obj, np.dtype):
        return f"dtype:{obj.str}"
    if isinstance(obj, jax.tree_util.PyTreeDef):  # static data holding a tree's structure
        return f"treedef:{structure_text(obj)}"
    if isinstance(obj, tuple | list):
        return f"{type(obj).__name__}(" + ",".join(describe(x, d) for x in obj) + ")"
    if isinstance(obj, dict):
        items = sorted((describe(k, d), describe(v, d)) for k, v in obj.items())
        return "dict(" + ",".join(f"{k}={v}" for k, v in items) + ")"
    if isinstance(obj, functools.partial):
        parts = (describe(obj.func, d), describe(obj.args, d), describe(obj.keywords, d))
        return "partial(" + ",".join(parts) + ")"
    if isinstance(obj, types.FunctionType):
        if not _versioned(obj.__module__) or "<lambda>" in obj.__qualname__:
            raise Unkeyable(f"function {obj.__module__}.{obj.__qualname__}")
        try:
            cells = [c.cell_contents for c in obj.__closure__ or ()]
        except ValueError as e:  # an empty cell
            raise Unkeyable(f"function {obj.__qualname__}: empty closure cell") from e
        attrs = {k: v for k, v in vars(obj).items() if k != "__wrapped__"}
        return (f"fn:{obj.__module__}.{obj.__qualname__}(" + describe(cells, d) + ","
                + describe(obj.__defaults__, d) + "," + describe(obj.__kwdefaults__, d) + ","
                + describe(attrs, d) + ")")  # fmt: skip
    if isinstance(obj, type):
        if _versioned(obj.__module__) or obj.__module__ == "builtins":
            return f"type:{obj.__module__}.{obj.__qualname__}"
        raise Unkeyable(f"type {obj.__module__}.{obj.__qualname__}")
    cls = type(obj)
    if _versioned(cls.__module__) and (dataclasses.is_dataclass(obj) or _ours(cls.__module__)):
        if dataclasses.is_dataclass(obj):
            fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
        elif hasattr(obj, "__dict__"):
            fields = vars(obj)
        else:
            raise Unkeyable(f"object of {cls.__qualname__} without fields")
        return f"obj:{cls.__module__}.{cls.__qualname__}" + describe(fields, d)
    if not (_versioned(cls.__module__) or cls.__module__ == "builtins"):
        raise Unkeyable(f"object of {cls.__module__}.{cls.__qualname__}")
    text = repr(obj)
    if " at 0x" in text or "..." in text or "object at" in text:
        raise Unkeyable(f"{cls.__module__}.{cls.__qualname__}: repr is not faithful")
    return f"repr:{cls.__module__}.{cls.__qualname__}:{text}"


def _placement_text(sharding: Any) -> str:
    """The sharding and the ids of its devices in order (a mesh's text names only its shape)."""
    mesh = getattr(sharding, "mesh", None)
    if mesh is not None and hasattr(mesh, "device_ids"):
        ids = np.asarray(mesh.device_ids).tolist()
    else:
        ids = sorted(d.id for d in sharding.device_set)
    return f"{sharding}@{ids}"


def _host_placement() -> str:
    """The placement text of a value ``jit`` places itself (a NumPy array, a Python scalar, an
    uncommitted array): the default device's, as :func:`_placement_text` writes it."""
    return _placement_text(jax.device_put(np.zeros((), np.bool_)).sharding)


def _leaf_text(x: Any, host: str) -> str:
    """What of an argument leaf fixes the program: shape, dtype, weak type and placement.

    A host value is written as the array ``jit`` makes of it (its dtype canonicalized, on the
    default device ``host``; a Python ``int`` or ``float`` weakly typed), so that the same
    program is found whether a setting arrives as ``np.float32(2.0)`` or as an array on the
    default device -- ``jit`` itself runs one program for both.
    """
    if isinstance(x, jax.Array):
        return f"{x.shape}{x.dtype.str}:{x.weak_type}:{_placement_text(x.sharding)}"
    if isinstance(x, np.ndarray | np.generic):
        dtype = jax.dtypes.canonicalize_dtype(x.dtype)
        return f"{np.shape(x)}{dtype.str}:False:{host}"
    if isinstance(x, bool | int | float):
        weak = not isinstance(x, bool)  # Python numbers are traced weakly typed, bools not
        dtype = jax.dtypes.canonicalize_dtype(np.result_type(type(x)))
        return f"(){dtype.str}:{weak}:{host}"
    raise Unkeyable(f"argument leaf of type {type(x).__qualname__}")


def _node_text(treedef: Any, _depth: int = 0) -> str:
    """A tree structure node by node: each node's type and static data by :func:`describe`, then
    its children (``*`` a leaf)."""
    if _depth > 200:
        raise Unkeyable("tree nested too deeply")
    data = treedef.node_data()
    if data is None:
        return "*"
    kind, aux = data
    children = ",".join(_node_text(c, _depth + 1) for c in treedef.children())
    return f"{describe(kind)}[{describe(aux)}]({children})"


def structure_text(treedef: Any) -> str:
    """The text of the arguments' tree structure in a key: JAX's own text, unless a node's
    static data is written there by its memory address (a flax NNX module's parameters name
    their attention function so), which changes from process to process; then every node is
    described (:func:`describe`), which names such a function by module and name.

    Raises:
        Unkeyable: for static data :func:`describe` cannot vouch for.
    """
    text = str(treedef)
    return text if " at 0x" not in text else _node_text(treedef)


def _key_text(identity: Any, args: tuple, code: bool = True) -> str:
    """What a program key is the hash of: the environment (without this package's code
    fingerprint unless ``code``), the identity, the arguments' structure and leaves.

    Raises:
        Unkeyable: for an identity or argument that cannot be described with certainty.
    """
    leaves, treedef = jax.tree.flatten(args)
    host = _host_placement()
    env = environment()
    if not code:
        env.pop("code")
    return "\n".join([
        repr(sorted(env.items())),
        describe(identity),
        structure_text(treedef),
        *(_leaf_text(x, host) for x in leaves),
    ])  # fmt: skip


def program_key(identity: Any, args: tuple) -> str | None:
    """The store key of the program ``identity`` compiled for ``args``, or ``None`` when it
    cannot be keyed with certainty (see :func:`describe`)."""
    try:
        text = _key_text(identity, args)
    except Unkeyable as e:
        log.debug("program not stored: %s", e)
        return None
    return hashlib.sha256(text.encode()).hexdigest()


def lowered_key(identity: Any, args: tuple, lowered: Any) -> str | None:
    """The key of the program ``identity`` for ``args`` by what it lowers to: :func:`program_key`'s
    text with the lowered program's text (``lowered.as_text()``, without debug locations) in
    place of this package's code fingerprint, or ``None`` when it cannot be keyed.

    After an edit of the package (or an upgrade) every program key changes, but most programs
    lower to what they lowered to before.  JAX's persistent cache then serves them, and a
    program it served cannot be stored (:func:`compile_lowered`), so without this index the
    store would never hold them again on that cache folder, and every run would trace and lower
    them.  The identity names whatever compiles the lowered program differently (the compiler
    options of the stress programs are part of theirs).  ``None`` too when the store is off.
    """
    if store_dir() is None:
        return None  # the store is off: nothing to find or index
    try:
        text = _key_text(identity, args, code=False)
    except Unkeyable:
        return None
    program = hashlib.sha256(lowered.as_text().encode()).hexdigest()
    return hashlib.sha256(f"{text}\nlowered {program}".encode()).hexdigest()


def describable(identity: Any) -> bool:
    """Whether a program of ``identity`` could be stored: the identity can be described with
    certainty (:func:`describe`), whether or not the store is on."""
    try:
        describe(identity)
    except Unkeyable:
        return False
    return True


_JAX_CACHE_HIT = "/jax/compilation_cache/cache_hits"
#: JAX records this duration around every backend compilation: an XLA compile, or a load from
#: its persistent cache.  A program JAX already holds in memory (the same lowered module compiled
#: again) records nothing.
_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"


class _Counts(threading.local):
    """This thread's count of JAX's persistent-cache hits and of backend compilations.  JAX
    calls its listeners in the thread that compiles, so a compilation in another thread (the
    split path compiles several programs side by side) never counts here."""

    hits = 0
    compiles = 0


_counts = _Counts()


def _count_jax_cache_hits(event: str, **_: Any) -> None:
    if event == _JAX_CACHE_HIT:
        _counts.hits += 1


def _count_backend_compiles(event: str, duration: float, **_: Any) -> None:
    if event == _BACKEND_COMPILE:
        _counts.compiles += 1


monitoring.register_event_listener(_count_jax_cache_hits)
monitoring.register_event_duration_secs_listener(_count_backend_compiles)


def compile_lowered(lowered: Any) -> tuple[Any, bool]:
    """``lowered.compile()``, and whether XLA compiled it here and now (``False``: JAX loaded it
    from its persistent compilation cache, or gave back an executable it already held in
    memory).

    Only a program compiled here may be stored: an executable that JAX loaded from its own
    cache serializes into an entry whose kernels are missing when it is loaded again (XLA on
    CPU, jaxlib 0.10: "Function ... not found" when it runs), so :func:`save` is given only
    fresh compilations; JAX's cache keeps serving the others.  That includes an executable
    JAX hands back from memory: a program lowered again in the same process (after it left
    :mod:`lantern_jax.sim.programs`' bounded cache, say) is the same module, and JAX returns
    the executable it made of it the first time, perhaps the one it loaded from its cache,
    without a compile or a cache hit.  Both are counted in this thread only.
    """
    hits, compiles = _counts.hits, _counts.compiles
    compiled = lowered.compile()
    return compiled, _counts.compiles > compiles and _counts.hits == hits


def _devices_of(compiled: Any) -> list[int] | None:
    """Ids of the devices the program runs on, in the order of its device assignment."""
    for sharding in jax.tree.leaves(compiled.input_shardings):
        assignment = getattr(sharding, "_device_assignment", None)
        if assignment:
            return [d.id for d in assignment]
    return None


def exists(key: str) -> bool:
    """Whether the store holds an entry named ``key`` (not checked: :func:`load` checks)."""
    folder = store_dir()
    return folder is not None and (folder / (key + _SUFFIX)).is_file()


def load(key: str) -> Any | None:
    """The stored program ``key`` as a callable :class:`jax.stages.Compiled`, or ``None`` when
    there is none (or it cannot be read back or holds another program: the entry is then
    deleted, with a warning)."""
    loaded = _load(key)
    return None if loaded is None else loaded[0]


def _load(key: str, trees: tuple[Any, Any] | None = None) -> tuple[Any, tuple] | None:
    """:func:`load`, with the entry's record; ``trees`` (``(in_tree, out_tree)``) replace the
    stored argument and result structures (the program kept under another key)."""
    folder = store_dir()
    if folder is None:
        return None
    path = folder / (key + _SUFFIX)
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        # deferred: only when a program is stored or loaded
        from jax.experimental import serialize_executable as se

        record = pickle.loads(blob)
        if not (isinstance(record, tuple) and len(record) == 6):
            raise ValueError(f"not an entry of store format {STORE_FORMAT}")
        stored_key, digest, payload, in_tree, out_tree, ids = record
        if stored_key != key:
            raise ValueError(f"it holds program {str(stored_key)[:12]}..., not {key[:12]}... "
                             "(swapped or copied under another name)")  # fmt: skip
        if hashlib.sha256(payload).hexdigest() != digest:
            raise ValueError("its executable does not match its SHA-256 (corrupted)")
        in_tree, out_tree = trees or (in_tree, out_tree)
        by_id = {d.id: d for d in jax.devices()}
        compiled = se.deserialize_and_load(
            payload, in_tree, out_tree, execution_devices=[by_id[i] for i in ids]
        )
    except Exception as e:  # noqa: BLE001  (any unreadable entry: compile instead)
        log.warning("stored program %s could not be loaded (%s); compiling it again", path, e)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used
    return compiled, (stored_key, digest, payload, in_tree, out_tree, ids)


def load_lowered(lowered_as: str, key: str, lowered: Any) -> Any | None:
    """The program stored under an earlier key for the same lowered program (the index entry
    ``lowered_as``, :func:`lowered_key`), now kept under ``key`` too (with ``lowered``'s argument
    and result structures) so that the next process loads it without lowering; ``None`` when
    the index names none or the entry is gone."""
    folder = store_dir()
    if folder is None:
        return None
    try:
        earlier = pickle.loads((folder / (lowered_as + _LOWERED_SUFFIX)).read_bytes())
    except Exception:  # noqa: BLE001  (absent or unreadable: compile instead)
        return None
    if not isinstance(earlier, str) or earlier == key:
        return None
    loaded = _load(earlier, trees=(lowered.in_tree, lowered.out_tree))
    if loaded is None:
        return None
    compiled, (_, digest, payload, in_tree, out_tree, ids) = loaded
    _write_indexed(folder, key, (key, digest, payload, in_tree, out_tree, ids), lowered_as)
    return compiled


def touch(key: str) -> None:
    """Mark the stored program ``key`` as used now (a process that runs it from memory uses it
    as much as one that loads it): :func:`prune` removes the least recently used entries, and a
    program every test or notebook cell runs from memory must not age out of the store while
    the programs of one-off runs are saved after it."""
    folder = store_dir()
    if folder is not None:
        with contextlib.suppress(OSError):
            os.utime(folder / (key + _SUFFIX))


def save(key: str, compiled: Any, lowered_as: str | None = None) -> bool:
    """Store ``compiled`` under ``key`` (atomically), indexed under its :func:`lowered_key`
    ``lowered_as`` when given; ``False`` when it cannot be serialized (a program with constant
    arrays) or written."""
    folder = store_dir()
    if folder is None:
        return False
    ids = _devices_of(compiled)
    if ids is None:
        return False
    try:
        # deferred: only when a program is stored or loaded
        from jax.experimental import serialize_executable as se

        payload, in_tree, out_tree = se.serialize(compiled)
        record = (key, hashlib.sha256(payload).hexdigest(), payload, in_tree, out_tree, ids)
    except Exception as e:  # noqa: BLE001  (not serializable: not stored)
        log.debug("program %s not stored: %s", key[:12], e)
        return False
    return _write_indexed(folder, key, record, lowered_as)


def _write_indexed(folder: Path, key: str, record: tuple, lowered_as: str | None) -> bool:
    """Write the program entry ``record`` under ``key`` and, when it is written and
    ``lowered_as`` is given, the index entry that names it (:func:`load_lowered` reads it)."""
    if not _write(folder, key, record, _SUFFIX):
        return False
    if lowered_as is not None:
        _write(folder, lowered_as, key, _LOWERED_SUFFIX)
    return True


def _write(folder: Path, key: str, record: Any, suffix: str) -> bool:
    """Pickle ``record`` into ``folder/<key><suffix>`` atomically and prune the entries of that
    suffix; ``False`` when it cannot be pickled or written."""
    try:
        blob = pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL)
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write(folder / (key + suffix), blob)
    except Exception as e:  # noqa: BLE001  (not picklable or not writable: not stored)
        log.debug("entry %s%s not stored: %s", key[:12], suffix, e)
        return False
    prune(folder, suffix=suffix, **_BOUNDS[suffix])
    return True


def value_key(*parts: str) -> str | None:
    """The store key of a value computed from this package's code (the environment of
    :func:`environment`) and ``parts`` (texts that name everything else it depends on), or
    ``None`` when a part names an object by its address (not the same in another process)."""
    if any(" at 0x" in part for part in parts):
        return None
    text = "\n".join([repr(sorted(environment().items())), "value", *parts])
    return hashlib.sha256(text.encode()).hexdigest()


def load_value(key: str) -> Any | None:
    """The value stored under ``key`` by :func:`save_value`, or ``None`` (none, unreadable, or
    holding another key: such an entry is deleted)."""
    folder = store_dir()
    if folder is None:
        return None
    path = folder / (key + _VALUE_SUFFIX)
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        stored_key, value = pickle.loads(blob)
        if stored_key != key:
            raise ValueError("it holds another key")
    except Exception as e:  # noqa: BLE001  (any unreadable entry: computed instead)
        log.warning("stored value %s could not be read (%s); computing it again", path, e)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used
    return value


def save_value(key: str, value: Any) -> bool:
    """Store a small picklable ``value`` under ``key`` (atomically); ``False`` when it cannot
    be pickled or written."""
    folder = store_dir()
    return folder is not None and _write(folder, key, (key, value), _VALUE_SUFFIX)


def kept(key: str | None, compute: Callable[[], Any],
         valid: Callable[[Any], bool] | None = None) -> Any:  # fmt: skip
    """The value stored under ``key`` when there is one (that ``valid`` accepts, when given),
    else ``compute()``, stored under ``key`` for later processes (``key`` None: computed, not
    stored)."""
    stored = load_value(key) if key is not None else None
    if stored is not None and (valid is None or valid(stored)):
        return stored
    value = compute()
    if key is not None:
        save_value(key, value)
    return value


def prune(
    folder: Path,
    keep: int = MAX_STORED_PROGRAMS,
    suffix: str = _SUFFIX,
    max_bytes: int | None = None,
) -> list[Path]:
    """Remove the least recently used entries of ``folder`` named ``*suffix`` (programs by
    default) until at most ``keep`` are left and, with ``max_bytes``, their sizes add up to at
    most ``max_bytes``; returns what was removed.  The most recently used entry is always kept
    (a program larger than the budget is still kept until another is stored)."""
    entries = []
    for p in folder.glob("*" + suffix):
        with contextlib.suppress(OSError):
            st = p.stat()
            entries.append((st.st_mtime, st.st_size, p))
    entries.sort(key=lambda e: e[0], reverse=True)
    removed, total = [], 0
    for i, (_, size, p) in enumerate(entries):
        total += size
        if i == 0 or (i < keep and (max_bytes is None or total <= max_bytes)):
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed
