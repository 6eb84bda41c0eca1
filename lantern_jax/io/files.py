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

**Some folders are never moved.**  A folder that is a mount point (a bind mount, a tmpfs,
Docker's ``-v host:/app/results``: its name cannot be exchanged) or that is or holds the current
folder or the home folder (``--out .``) is written *in place* (:func:`in_place_reason`):
the set is staged in a hidden folder inside it, the set's last file (its manifest) is removed
first, every other file replaces its old version atomically and the last file is written last,
so the folder holds a complete set exactly when it holds that last file.  The same happens,
with a warning, when an exchange fails with "Device or resource busy" although no mount point
was detected.  :class:`StagedFolder` logs which way a set was written when it is not the
exchange.

When the process runs as root and the folder belongs to another user, the new folder and its
files are given the old folder's owner, group and mode.

Names of leftovers and temporary files are built from the target's name, shortened with a
hash of it where the full name would not fit a file name (:data:`NAME_MAX` bytes), so a
target whose own name is that long can still be written.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import hashlib
import logging
import os
import re
import secrets
import shutil
import sys
import tempfile
import tomllib
from collections.abc import Collection, Sequence
from pathlib import Path

log = logging.getLogger(__name__)

STAGING_TAG = "staging"
OLD_TAG = "old"
PROBE_TAG = "probe"
#: Longest file name (bytes) the common file systems accept.
NAME_MAX = 255
#: Bytes of a leftover's or temporary file's name beyond the target's own name (dot, tag,
#: process id, random token, suffix), with room to spare.
_NAME_EXTRA = 48


class OutputFolderError(OSError):
    """A target folder that cannot receive a result set (a file, an unwritable place...)."""


def file_mode() -> int:
    """0o666 minus the process umask: the mode a plain ``open`` gives a new file (``mkstemp``
    creates files 0o600, readable by their owner only)."""
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


def name_stem(name: str) -> str:
    """The part of a leftover's or temporary file's name that stands for ``name``: ``name``
    itself, or where that would make the name too long for the file system, its first bytes
    and a hash of all of it (the same for the same ``name``, so leftovers are found again).

    Args:
        name: a file or folder name.
    """
    raw = name.encode()
    if len(raw) + _NAME_EXTRA <= NAME_MAX:
        return name
    digest = hashlib.sha256(raw).hexdigest()[:16]
    head = raw[: NAME_MAX - _NAME_EXTRA - len(digest) - 1].decode("utf-8", "ignore")
    return f"{head}~{digest}"


def _adopt_owner(path: Path, like: os.stat_result) -> None:
    """Give ``path`` the owner and group of ``like`` (only a process running as root can, and
    only where they differ)."""
    if os.geteuid() != 0:
        return
    st = os.lstat(path)
    if (st.st_uid, st.st_gid) != (like.st_uid, like.st_gid):
        with contextlib.suppress(OSError):
            os.lchown(path, like.st_uid, like.st_gid)


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
    fd, tmp = temporary_beside(path, ".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(path.parent)
    return path


def temporary_beside(path: Path, suffix: str) -> tuple[int, str]:
    """A new temporary file in ``path``'s folder for writing ``path`` atomically: named
    ``.{stem}.{pid}.XXXX{suffix}`` (:func:`is_temporary_of` knows it); the temporaries of the
    same file that a process no longer running left there (killed while writing) are removed
    first.  Returns ``(fd, name)`` as :func:`tempfile.mkstemp`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    stem = name_stem(path.name)
    with contextlib.suppress(OSError):
        for entry in os.listdir(path.parent):
            if not (entry.startswith(f".{stem}.") and entry.endswith(".tmp")):
                continue
            pid = entry[len(stem) + 2 :].split(".", 1)[0]
            if pid.isdigit() and not _alive(int(pid)):
                (path.parent / entry).unlink()
    return tempfile.mkstemp(prefix=f".{stem}.{os.getpid()}.", suffix=suffix, dir=path.parent)


def read_toml(path: str | os.PathLike) -> dict:
    """Parse a TOML file; a UTF-8 byte-order mark at its start (as some editors write one) is
    accepted.

    Raises:
        OSError: when the file cannot be read.
        ValueError: when it is not UTF-8 or not valid TOML (the message says where).
    """

    with open(path, "rb") as fh:
        data = fh.read()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ValueError(f"not UTF-8 text ({e})") from None
    return tomllib.loads(text)


def is_temporary_of(entry: str, names: Collection[str]) -> bool:
    """Whether ``entry`` is a temporary file :func:`atomic_write` made for one of ``names``."""
    return entry.endswith(".tmp") and any(entry.startswith(f".{name_stem(n)}.") for n in names)


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
    return f".{name_stem(target.name)}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def _leftover_owner(entry: str, target: Path) -> int | None:
    """The process id in a leftover's name, or None when ``entry`` is not one of ours."""
    for tag in (STAGING_TAG, OLD_TAG, PROBE_TAG):
        prefix = f".{name_stem(target.name)}.{tag}-"
        if entry.startswith(prefix):
            pid = entry[len(prefix) :].split("-")[0]
            return int(pid) if pid.isdigit() else None
    return None


@contextlib.contextmanager
def _locked(folder: Path):
    """Hold an exclusive lock on ``folder`` (``flock`` on the folder itself, so no lock file is
    left behind) while two writers of sets into it could otherwise interleave; without the
    lock where the system has none."""
    try:
        # deferred: POSIX only: elsewhere the lock is not taken
        import fcntl

        fd = os.open(folder, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


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
    """Tidy what an interrupted :class:`StagedFolder` left beside ``target`` (or, for a set
    written in place, inside it).

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
    for folder in (parent, target) if target.is_dir() else (parent,):
        for entry in sorted(os.listdir(folder)):
            pid = _leftover_owner(entry, target)
            if pid is not None and not _alive(pid):
                stale.append(folder / entry)
    olds = [p for p in stale if f".{OLD_TAG}-" in p.name and p.parent == parent]
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


def _mount_points() -> set[str]:
    """Every mount point of this process (``/proc/self/mountinfo``; bind mounts of a folder of
    the same file system included, which :func:`os.path.ismount` does not see)."""
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="surrogateescape") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return set()
    points = set()
    for line in lines:
        fields = line.split(" ")
        if len(fields) > 4:  # the fifth field, with " ", tab, newline, "\" octal-escaped
            points.add(re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), fields[4]))
    return points


def is_mount_point(path: str | os.PathLike) -> bool:
    """Whether ``path`` (resolved) is where a file system or a bind mount is attached."""
    resolved = os.path.realpath(path)
    return os.path.ismount(resolved) or resolved in _mount_points()


def _holds(folder: str, inner: str) -> bool:
    """Whether ``inner`` is ``folder`` or lies inside it (both resolved)."""
    return inner == folder or inner.startswith(folder.rstrip(os.sep) + os.sep)


def in_place_reason(target: str | os.PathLike) -> str | None:
    """Why a set must be written *into* the existing folder ``target`` instead of replacing the
    folder as a whole, or None when it may be replaced (see the module docstring).

    Args:
        target: the result folder.
    """
    resolved = os.path.realpath(target)
    if not os.path.isdir(resolved):
        return None
    with contextlib.suppress(OSError):
        if _holds(resolved, os.path.realpath(os.getcwd())):
            return "it is (or holds) the current folder"
    home = os.path.realpath(os.path.expanduser("~"))
    if _holds(resolved, home):
        return "it is (or holds) the home folder"
    if is_mount_point(resolved):
        return "it is a mount point (its name cannot be exchanged)"
    return None


def check_target_folder(target: str | os.PathLike, in_place: bool | None = None,
                        owned: Collection[str] = ()) -> Path:  # fmt: skip
    """Check, without touching any existing file, that a folder can receive a staged result set
    (the folder that must be writable: the target itself where the set is written in place,
    :func:`in_place_reason`, else the folder that holds it).

    Args:
        target: the result folder (may not exist yet).
        in_place: whether files are written into the folder itself (a dataset or training
            run folder, resumed in place); default: as :class:`StagedFolder` will decide.
        owned: the names of the set's files: an entry of ``target`` with one of those names
            that is not a regular file (a folder, a link) is someone else's, and is refused
            rather than replaced.

    Returns:
        The resolved target path.

    Raises:
        OutputFolderError: when ``target`` is empty, is a file, lies under a file, holds an
            entry named like a result file that is not one, or it or the folder that will hold
            it cannot be written (tried for real with a probe folder).
    """
    if not str(target).strip():
        raise OutputFolderError("output folder: empty path")
    resolved = Path(os.path.realpath(target))
    if resolved.exists() and not resolved.is_dir():
        raise OutputFolderError(f"output folder {target}: is a file, not a folder")
    for name in sorted(owned):
        entry = resolved / name
        if os.path.lexists(entry) and (entry.is_symlink() or not entry.is_file()):
            kind = "a folder" if entry.is_dir() else "a special file"
            kind = "a link" if entry.is_symlink() else kind
            raise OutputFolderError(
                f"output folder {target}: {entry} is {kind} (not a result file this project "
                "wrote); a result set would replace it: move it, or choose another folder"
            )
    anc = resolved.parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise OutputFolderError(f"output folder {target}: {anc} is a file, not a folder")
    if resolved.is_dir() and not os.access(resolved, os.W_OK | os.X_OK):
        raise OutputFolderError(f"output folder {target}: not writable")
    if in_place is None:
        in_place = in_place_reason(resolved) is not None
    where = resolved if in_place and resolved.is_dir() else anc
    probe = where / _leftover_name(resolved, PROBE_TAG)
    try:
        probe.mkdir()
    except OSError as e:
        raise OutputFolderError(
            f"output folder {target}: cannot create folders in {where} ({e.strerror or e})"
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
    leaves ``target`` as it was.  Two processes writing sets into one folder at once each
    commit under a lock on the folder that holds it: the folder ends with one of the two
    complete sets.

    Args:
        target: the result folder; created or replaced by :meth:`commit`.  A symbolic link is
            followed (the folder it points to is replaced).
        owned: names of the files that make up a set, the set's marker last (written last and
            removed first when the set is written in place).  Other entries of an existing
            ``target`` are carried over into the new folder.

    Attributes:
        in_place: why the set was (or will be) written into the existing folder file by file
            (:func:`in_place_reason`, or an exchange that failed), else None.

    Raises:
        OutputFolderError: from :func:`check_target_folder`.
    """

    def __init__(self, target: str | os.PathLike, owned: Sequence[str]) -> None:
        self.target = check_target_folder(target, owned=owned)
        self.owned = frozenset(owned)
        self.last = list(owned)[-1] if owned else None
        self.target.parent.mkdir(parents=True, exist_ok=True)
        with _locked(self.target.parent):
            clean_leftovers(self.target, self.owned)
        self.in_place = in_place_reason(self.target)
        home = self.target if self.in_place else self.target.parent
        self.path = home / _leftover_name(self.target, STAGING_TAG)
        self.path.mkdir()
        self._done = False
        if self.in_place:
            log.warning("output folder %s: %s; its result files are replaced one by one (each "
                        "atomically, %s last), not as a whole set", target, self.in_place,
                        self.last)  # fmt: skip

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
        """Move the staged files into place as a whole (module docstring, steps 1-4), or one by
        one into a folder that must be written in place.

        Returns:
            The target folder.
        """
        for entry in os.listdir(self.path):
            p = self.path / entry
            if p.is_file():
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())
        _fsync_dir(self.path)
        with _locked(self.target.parent):  # another process's set goes in before or after
            return self._commit()

    def _commit(self) -> Path:
        target = self.target
        if self.in_place:
            return self._commit_in_place()
        if not os.path.lexists(target):
            os.rename(self.path, target)
            self._done = True
            _fsync_dir(target.parent)
            return target
        like = os.stat(target)
        with contextlib.suppress(OSError):
            os.chmod(self.path, like.st_mode & 0o7777)
        for p in (self.path, *self.path.iterdir()):
            _adopt_owner(p, like)
        try:
            swapped = exchange(self.path, target)
        except OSError as e:
            if e.errno != errno.EBUSY:
                raise
            return self._busy(e)
        if swapped:
            old = self.path  # the staging name now holds the old folder
        else:
            old = target.parent / _leftover_name(target, OLD_TAG)
            try:
                os.rename(target, old)
            except OSError as e:
                if e.errno != errno.EBUSY:
                    raise
                return self._busy(e)
            try:
                os.rename(self.path, target)
            except BaseException:
                os.rename(old, target)
                raise
        self._done = True  # from here on the old folder is never discarded, only emptied
        _fsync_dir(target.parent)
        _empty_into(old, target, self.owned)
        _fsync_dir(target.parent)
        return target

    def _busy(self, error: OSError) -> Path:
        """The folder's name cannot move (a mount point that was not detected): write the set
        into it instead, and say so."""
        self.in_place = f"its name cannot be exchanged ({error.strerror})"
        log.warning("output folder %s: %s; its result files were replaced one by one (each "
                    "atomically, %s last) instead", self.target, self.in_place,
                    self.last)  # fmt: skip
        return self._commit_in_place()

    def _commit_in_place(self) -> Path:
        """The set's marker (last file) is removed, every other file replaces its old version
        atomically, the marker comes last; the staging folder is removed."""
        target, like = self.target, os.stat(self.target)
        staged = sorted(os.listdir(self.path), key=lambda n: n == self.last)
        if self.last is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(target / self.last)
        for name in staged:
            src, dst = self.path / name, target / name
            try:
                os.replace(src, dst)
            except OSError as e:
                if e.errno != errno.EXDEV:
                    raise
                atomic_write(dst, src.read_bytes())  # staged on another file system
            _adopt_owner(dst, like)
        self._done = True
        _fsync_dir(target)
        shutil.rmtree(self.path, ignore_errors=True)
        return target
