"""Writing files so that a reader never sees half of them: one file, or a whole folder of them.

* :func:`atomic_write` writes one file through a hidden temporary file in the same folder and
  renames it into place, so the path holds either its old or its new content, never a part.
* :class:`StagedFolder` writes a *set* of files (an evaluation's result set) into a hidden
  staging folder beside the target and moves it into place as a whole.

How a staged folder replaces an existing one (``results/``)::

    .results.staging-<pid>-<token>/     1. every new file is written and synced here
    results/  <-->  .results.staging-…  2. one atomic exchange of the two names (Linux
                                           ``renameat2(RENAME_EXCHANGE)``)
    results/quick/ ...                  3. entries of the old folder that are not part of the
                                           set (other files, sub-folders) are moved back in
    (old result files deleted)          4. the old folder is removed

A ``kill -9`` at any moment leaves ``results/`` holding either the complete old set or the
complete new set, never a mix.  What a kill leaves beside it (a staging folder, the old folder
whose foreign entries were not yet moved back) is cleaned by the next :class:`StagedFolder` for
the same target: result files are deleted and every other entry is moved back into the target,
so nothing that is not ours is ever deleted.  Leftovers of a process that is still running are
left alone.

Where the exchange is not available (not Linux, or a file system without it) step 2 is two
renames (``results`` -> ``.results.old-…``, staging -> ``results``); a kill between them leaves
no ``results/`` until the next run puts the old folder back.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import secrets
import shutil
import sys
import tempfile
from collections.abc import Collection
from pathlib import Path

STAGING_TAG = "staging"
OLD_TAG = "old"
PROBE_TAG = "probe"


class OutputFolderError(OSError):
    """A target folder that cannot receive a result set (a file, an unwritable place...)."""


def _file_mode() -> int:
    """0o666 minus the process umask (``mkstemp`` creates files 0o600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):  # not every platform can open a folder
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def atomic_write(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically: a temporary file in the same folder, synced, then
    renamed over ``path``.

    Args:
        path: the file to write (its folder is created if needed).
        data: the content; ``str`` is written as UTF-8 with newlines untranslated.

    Returns:
        The path written.

    Raises:
        IsADirectoryError: when ``path`` is an existing folder (checked before anything is
            written, so no temporary file is left).
        OSError: when the file cannot be written; the temporary file is removed.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"cannot write {path}: it is a folder, not a file")
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _file_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(path.parent)
    return path


def is_temporary_of(entry: str, names: Collection[str]) -> bool:
    """Whether ``entry`` is a temporary file :func:`atomic_write` made for one of ``names``."""
    return entry.endswith(".tmp") and any(entry.startswith(f".{n}.") for n in names)


# ---------------------------------------------------------------------------------------------
# whole-folder replacement
# ---------------------------------------------------------------------------------------------
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _renameat2():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_RENAMEAT2 = _renameat2()


def exchange(a: Path, b: Path) -> bool:
    """Atomically swap the names of two existing paths; False where the system cannot."""
    if _RENAMEAT2 is None:
        return False
    rc = _RENAMEAT2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: not supported here
        return False
    raise OSError(err, f"cannot exchange {a} and {b}: {os.strerror(err)}")


def _leftover_name(target: Path, tag: str) -> str:
    return f".{target.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def _leftover_owner(entry: str, target: Path) -> int | None:
    """The process id in a leftover's name, or None when ``entry`` is not one of ours."""
    for tag in (STAGING_TAG, OLD_TAG, PROBE_TAG):
        prefix = f".{target.name}.{tag}-"
        if entry.startswith(prefix):
            pid = entry[len(prefix) :].split("-")[0]
            return int(pid) if pid.isdigit() else None
    return None


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _empty_into(src: Path, target: Path, owned: Collection[str]) -> None:
    """Delete ``src``'s result files, move its other entries into ``target``, remove ``src``.

    An entry that cannot move back (its name is taken in ``target``) stays in ``src``, which is
    then kept.
    """
    for entry in sorted(os.listdir(src)):
        p = src / entry
        if entry in owned or is_temporary_of(entry, owned):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink()
        elif target.is_dir() and not os.path.lexists(target / entry):
            os.rename(p, target / entry)
    with contextlib.suppress(OSError):
        src.rmdir()


def clean_leftovers(target: str | os.PathLike, owned: Collection[str]) -> list[Path]:
    """Tidy what an interrupted :class:`StagedFolder` left beside ``target``.

    A missing ``target`` whose old folder was moved aside gets it back; result files of
    leftover folders are deleted and their other entries moved back into ``target``; temporary
    files of ``owned`` names inside ``target`` are deleted.  Leftovers of running processes are
    left alone.

    Args:
        target: the result folder.
        owned: the names of the files that make up a result set.

    Returns:
        The leftover paths that were handled.
    """
    target = Path(os.path.realpath(target))
    parent = target.parent
    if not parent.is_dir():
        return []
    stale = []
    for entry in sorted(os.listdir(parent)):
        pid = _leftover_owner(entry, target)
        if pid is not None and not _alive(pid):
            stale.append(parent / entry)
    olds = [p for p in stale if f".{OLD_TAG}-" in p.name]
    if not os.path.lexists(target) and olds:
        os.rename(olds[0], target)  # a kill between the two renames of the fallback
        stale.remove(olds[0])
    for p in stale:
        if p.is_dir() and not p.is_symlink():
            _empty_into(p, target, owned)
        else:
            p.unlink()
    if target.is_dir():
        for entry in os.listdir(target):
            if is_temporary_of(entry, owned):
                (target / entry).unlink()
    return stale


def check_target_folder(target: str | os.PathLike) -> Path:
    """Check, without touching any existing file, that a folder can receive a staged result set.

    Args:
        target: the result folder (may not exist yet).

    Returns:
        The resolved target path.

    Raises:
        OutputFolderError: when ``target`` is empty, is a file, lies under a file, or it or the
            folder that will hold it cannot be written (tried for real with a probe folder).
    """
    if not str(target).strip():
        raise OutputFolderError("output folder: empty path")
    resolved = Path(os.path.realpath(target))
    if resolved.exists() and not resolved.is_dir():
        raise OutputFolderError(f"output folder {target}: is a file, not a folder")
    anc = resolved.parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise OutputFolderError(f"output folder {target}: {anc} is a file, not a folder")
    if resolved.is_dir() and not os.access(resolved, os.W_OK | os.X_OK):
        raise OutputFolderError(f"output folder {target}: not writable")
    probe = anc / _leftover_name(resolved, PROBE_TAG)
    try:
        probe.mkdir()
    except OSError as e:
        raise OutputFolderError(
            f"output folder {target}: cannot create folders in {anc} ({e.strerror or e})"
        ) from None
    probe.rmdir()
    return resolved


class StagedFolder:
    """A folder of files that appears at ``target`` as a whole (see the module docstring).

    Usage::

        with StagedFolder("results", owned=OUTPUT_FILES) as stage:
            atomic_write(stage.path / "a.csv", text)   # ... every file of the set
            stage.commit()

    Leaving the block without :meth:`commit` (an error, Ctrl-C) removes the staging folder and
    leaves ``target`` as it was.

    Args:
        target: the result folder; created or replaced by :meth:`commit`.  A symbolic link is
            followed (the folder it points to is replaced).
        owned: names of the files that make up a set.  Other entries of an existing ``target``
            are carried over into the new folder.

    Raises:
        OutputFolderError: from :func:`check_target_folder`.
    """

    def __init__(self, target: str | os.PathLike, owned: Collection[str]) -> None:
        self.target = check_target_folder(target)
        self.owned = frozenset(owned)
        self.target.parent.mkdir(parents=True, exist_ok=True)
        clean_leftovers(self.target, self.owned)
        self.path = self.target.parent / _leftover_name(self.target, STAGING_TAG)
        self.path.mkdir()
        self._done = False

    def __enter__(self) -> StagedFolder:
        return self

    def __exit__(self, *exc) -> None:
        if not self._done:
            self.discard()

    def discard(self) -> None:
        """Remove the staging folder; the target is untouched."""
        shutil.rmtree(self.path, ignore_errors=True)
        self._done = True

    def commit(self) -> Path:
        """Move the staged files into place as a whole (module docstring, steps 1-4).

        Returns:
            The target folder.
        """
        for entry in os.listdir(self.path):
            p = self.path / entry
            if p.is_file():
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())
        _fsync_dir(self.path)
        target = self.target
        if not os.path.lexists(target):
            os.rename(self.path, target)
        else:
            with contextlib.suppress(OSError):
                os.chmod(self.path, os.stat(target).st_mode & 0o7777)
            if exchange(self.path, target):
                old = self.path  # the staging name now holds the old folder
            else:
                old = target.parent / _leftover_name(target, OLD_TAG)
                os.rename(target, old)
                try:
                    os.rename(self.path, target)
                except BaseException:
                    os.rename(old, target)
                    raise
            self._done = True  # from here on the old folder is never discarded, only emptied
            _fsync_dir(target.parent)
            _empty_into(old, target, self.owned)
        self._done = True
        _fsync_dir(target.parent)
        return target
