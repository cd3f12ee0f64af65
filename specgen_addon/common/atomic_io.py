"""Safe file output: private staging, atomic publication, a ledger of what this process made,
and lock files that keep two processes off one output.

* :func:`atomic_write` stages a file under a private, unique, hidden name beside the target and
  moves it into place only when complete (``os.link`` without ``overwrite``, so a file another
  process published meanwhile is never replaced; ``os.replace`` with it). A failed write (disk
  full, quota, I/O error) is one :class:`~specgen_addon.common.errors.OutputWriteError` sentence naming
  the output and the cause, and leaves nothing behind.
* Every file published, and every folder made with :func:`make_dirs`, is entered in this
  process's ledger with its identity (device, inode): clean-up after a failed or stopped command
  (:func:`remove_created`) removes only those, and only while they still are the very files this
  process made, never a file another process wrote into the same folder.
* Inside :func:`replacements_kept` (a command's whole run), a file another process or an earlier
  run made that ``overwrite`` replaces is kept aside (a hidden hard link beside it) until the
  command ends: a failed or stopped command puts it back when its clean-up removes the new file,
  so an interrupted ``--overwrite`` leaves the old outputs whole, not half replaced; a command
  that succeeds drops the copies.
* :class:`OutputLock` holds ``.<name>.lock`` beside an output (pid and host inside) for the
  length of a command; a second command on the same output is refused before any work. A lock
  whose process is gone (same host, pid not running) is stale and taken over.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import itertools
import json
import os
import secrets
import socket
import stat
import time
from pathlib import Path
from typing import Iterable, Iterator

from specgen_addon.common.errors import OutputBusyError, OutputExistsError, OutputWriteError, SpecGenError
from specgen_addon.common.limits import check_output_dir, check_output_file, name_max

#: Files and folders this process created: absolute path -> (identity, sequence number).
_LEDGER: dict[str, tuple[tuple, int]] = {}
_SEQ = itertools.count(1)
#: Staging files being written: absolute staging path -> absolute target path.
_STAGING: dict[str, str] = {}
#: Files replaced with ``overwrite`` inside :func:`replacements_kept`: absolute target -> the
#: hidden copy of the file it replaced (None while no command keeps them).
_REPLACED: dict[str, str] | None = None
#: Staging files about to be created (path -> ledger number): a stop that lands between their
#: creation and their ledger entry still finds and removes them (the names are private and unique).
_PENDING: dict[str, int] = {}


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def file_identity(path: str | os.PathLike) -> tuple | None:
    """(device, inode, and for a file its modification time and size): an inode number freed
    and reused by another process's new file at the same path is not taken for ours."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    if stat.S_ISDIR(st.st_mode):
        return st.st_dev, st.st_ino
    return st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size


def record_created(path: str | os.PathLike) -> None:
    """Enter ``path`` (just created by this process) in the ledger with its identity."""
    ident = file_identity(Path(path))
    if ident is not None:
        _LEDGER[os.path.abspath(path)] = (ident, next(_SEQ))


def ledger_mark() -> int:
    """A mark for :func:`created_since`: entries made after this call have a larger number."""
    return next(_SEQ)


def is_ours(path: str | os.PathLike) -> bool:
    """Whether ``path`` is still the very file or folder this process created (a staging file,
    still being written, by its device and inode alone: its name is private and unique)."""
    key = os.path.abspath(path)
    entry = _LEDGER.get(key)
    if entry is None:
        return key in _PENDING and os.path.lexists(key)
    ident = file_identity(Path(path))
    if key in _STAGING:
        return ident is not None and ident[:2] == entry[0][:2]
    return ident == entry[0]


def created_since(mark: int, under: Iterable[str | os.PathLike] = ()) -> list[Path]:
    """Ledger entries made after ``mark`` (:func:`ledger_mark`), inside ``under`` if given
    (each a folder or a file), deepest first."""
    roots = [os.path.abspath(u) for u in under]
    def inside(p: str) -> bool:
        return any(p == r or p.startswith(r.rstrip(os.sep) + os.sep) for r in roots)

    # a staging file counts as its target's (a hard stop may come while it is being written)
    found = [p for p, (_, t) in _LEDGER.items()
             if t > mark and (not roots or inside(p) or (p in _STAGING and inside(_STAGING[p])))]
    found += [p for p, t in list(_PENDING.items())
              if t > mark and p not in _LEDGER and os.path.lexists(p)
              and (not roots or inside(p) or (p in _STAGING and inside(_STAGING[p])))]
    return [Path(p) for p in sorted(found, key=lambda p: -p.count(os.sep))]


def remove_created(paths: Iterable[Path], keep: Iterable[Path] = ()) -> list[Path]:
    """Remove those of ``paths`` that are still this process's own (files unlinked, folders
    removed only when empty); returns what was removed. Anything else is left alone."""
    kept = {os.path.abspath(k) for k in keep}
    removed = []
    for p in paths:
        a = os.path.abspath(p)
        if a in kept or not is_ours(p):
            continue
        with contextlib.suppress(OSError):
            if Path(p).is_dir() and not Path(p).is_symlink():
                os.rmdir(p)  # only when empty: another process's files inside stay
            else:
                os.unlink(p)
            removed.append(Path(p))
            _LEDGER.pop(a, None)
            _PENDING.pop(a, None)
        kept_aside = (_REPLACED or {}).pop(a, None)
        if kept_aside is not None and not os.path.lexists(a):   # the file it replaced, put back
            with contextlib.suppress(OSError):
                os.replace(kept_aside, a)
    return removed


@contextlib.contextmanager
def replacements_kept() -> Iterator[None]:
    """A command's run: files that ``overwrite`` replaces are kept aside until it ends (module
    docstring); :func:`remove_created` puts one back when it removes the new file, and the copies
    of the rest are dropped on the way out, whether the command succeeded or not."""
    global _REPLACED
    outer, _REPLACED = _REPLACED, {}
    try:
        yield
    finally:
        for kept_aside in _REPLACED.values():
            with contextlib.suppress(OSError):
                os.unlink(kept_aside)
        _REPLACED = outer


def _keep_aside(target: Path) -> str | None:
    """A hidden hard link to ``target`` beside it (the file an overwrite is about to replace);
    None where the file system has no hard links (the replacement is then final at once)."""
    aside = target.parent / f".{target.name}.{secrets.token_hex(4)}.replaced"
    try:
        os.link(target, aside)
    except OSError:
        return None
    return str(aside)


def make_dirs(path: str | os.PathLike) -> Path:
    """``mkdir -p`` that enters each folder it actually creates in the ledger."""
    path = Path(path)
    missing = [p for p in [path, *path.parents] if not p.exists()]
    for p in reversed(missing):
        try:
            p.mkdir()
        except FileExistsError:
            if not p.is_dir():
                raise
            continue  # another process made it: not ours
        record_created(p)
    return path


def make_output_dir(path: str | os.PathLike) -> Path:
    """An output folder, checked by :func:`~specgen_addon.common.limits.check_output_dir` and then
    made (the folders it makes are this run's, removed on failure)."""
    path = check_output_dir(path)
    try:
        make_dirs(path)
    except OSError as exc:
        raise SpecGenError(f"{path}: cannot create the output folder ({exc.strerror})") from None
    return path


def make_lock_folders(folders: Iterable[str | os.PathLike]) -> list[Path]:
    """Make the missing parents of new output folders (entered in the ledger), so that their
    locks have a place beside them; returns those made, deepest first, for
    :func:`remove_created` (which removes them only while empty). A file in the way is left for
    the command's own checks to name."""
    made: list[Path] = []
    for f in folders:
        parent = Path(os.path.abspath(f)).parent
        missing = [p for p in [parent, *parent.parents] if not p.exists()]
        try:
            make_dirs(parent)
        except OSError:
            continue
        made += missing
    return made


def _temp_name(target: Path) -> str:
    """A hidden staging name beside ``target`` that keeps its suffixes and fits the file
    system's name limit however long the target's name is."""
    suffix = "".join(target.suffixes)[-32:] or ".tmp"
    tag = secrets.token_hex(4)
    room = name_max(target.parent) - len(f"..{tag}".encode()) - len(suffix.encode())
    stem = os.fsencode(target.name[: len(target.name) - len("".join(target.suffixes))])[:max(room, 0)]
    return f".{stem.decode(errors='ignore')}.{tag}{suffix}"


def _os_error_in(exc: BaseException) -> OSError | None:
    """The OSError behind an exception (a writer's own error may wrap, or follow, the real one:
    numpy's zip writer raises ``ValueError: seek of closed file`` after ENOSPC)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno is not None:
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


#: errno values that mean "the output cannot be written here", reported as such.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EFBIG, errno.EROFS, errno.EACCES,
                 errno.EPERM, errno.ENAMETOOLONG}


def write_error(target: Path, exc: BaseException) -> OutputWriteError | None:
    """The one-sentence error for a failed write of ``target``, or None when ``exc`` is not an
    I/O failure. A writer that hides the cause (an EXR library saying only "cannot write") is
    diagnosed from the free space left."""
    os_exc = _os_error_in(exc)
    if os_exc is not None and os_exc.errno in _WRITE_ERRNOS:
        cause = os.strerror(os_exc.errno)
    elif os_exc is None and _disk_full(target.parent):
        cause = os.strerror(errno.ENOSPC)
    elif os_exc is not None:
        cause = os_exc.strerror or str(os_exc)
    else:
        return None
    return OutputWriteError(f"{target}: cannot be written ({cause}); nothing partial was left")


def _disk_full(folder: Path) -> bool:
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):
        return False
    return st.f_bavail * st.f_frsize < 64 * 1024 or st.f_favail == 0


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a private temporary path beside the target; move it onto ``path`` only on success.

    The temporary name keeps the target's suffix so writers that dispatch on it (numpy, OpenEXR,
    image libraries) behave the same. On any exception the temporary file is removed, so a failed
    or cancelled write never leaves a half-written output; an I/O failure (disk full…) becomes
    one :class:`OutputWriteError` naming ``path``. Without ``overwrite`` a file that appeared
    meanwhile (another process) is kept and :class:`OutputExistsError` raised.
    """
    target = check_output_file(path, overwrite)  # folder exists, writable; no silent overwrite
    parent = target.parent if str(target.parent) else Path(".")
    tmp = parent / _temp_name(target)
    _STAGING[os.path.abspath(tmp)] = os.path.abspath(target)
    _PENDING[os.path.abspath(tmp)] = next(_SEQ)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        _STAGING.pop(os.path.abspath(tmp), None)
        _PENDING.pop(os.path.abspath(tmp), None)
        raise write_error(target, exc) or exc from None
    os.close(fd)
    record_created(tmp)  # so that a hard stop's clean-up removes it
    _PENDING.pop(os.path.abspath(tmp), None)
    try:
        try:
            yield tmp
            os.chmod(tmp, 0o666 & ~_current_umask())  # staged as 0600; give the usual mode
            _publish(tmp, target, overwrite)
        except (SpecGenError, KeyboardInterrupt, GeneratorExit):
            raise
        except BaseException as exc:
            err = write_error(target, exc)
            if err is None:
                raise
            raise err from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        _STAGING.pop(os.path.abspath(tmp), None)
        _LEDGER.pop(os.path.abspath(tmp), None)


def _publish(tmp: Path, target: Path, overwrite: bool) -> None:
    """Move the staged file onto ``target``. The ledger learns the file first (a rename or link
    keeps its identity), so a stop at any instant leaves no published file unaccounted for; a
    path that was another process's before stays theirs (it is never removed by a clean-up)."""
    key = os.path.abspath(target)
    ours = not os.path.lexists(target) or is_ours(target)
    if not ours and overwrite and _REPLACED is not None and key not in _REPLACED:
        kept_aside = _keep_aside(target)       # put back if this command fails or is stopped
        if kept_aside is not None:
            _REPLACED[key] = kept_aside
            ours = True                        # the new file is this command's to remove
    if ours:
        record_created(tmp)  # its full identity now that it is complete
        _LEDGER[key] = _LEDGER.pop(os.path.abspath(tmp))
        _STAGING.pop(os.path.abspath(tmp), None)
    try:
        if overwrite:
            os.replace(tmp, target)
        else:
            try:
                os.link(tmp, target)  # atomic, and never replaces a file that appeared meanwhile
            except FileExistsError:
                raise OutputExistsError(f"{target}: was written by another process meanwhile; "
                                        "kept it (pass --overwrite to replace it)") from None
            except OSError as exc:
                if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EXDEV, errno.EMLINK):
                    raise
                os.replace(tmp, target)  # a file system without hard links
            else:
                tmp.unlink()
    except BaseException:
        if ours and not is_ours(target):
            _LEDGER.pop(key, None)
        raise


def write_npz(path: str | os.PathLike, **arrays) -> None:
    """``np.savez`` (uncompressed, no pickles) that closes its archive on every path: numpy's own
    leaves it open after a failed write (disk full), and its later clean-up prints a traceback."""
    import zipfile

    import numpy as np

    with open(path, "wb") as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, value in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as entry:
                np.lib.format.write_array(entry, np.asanyarray(value), allow_pickle=False)


# ------------------------------------------------------------------------------------- locks
def lock_path(target: str | os.PathLike) -> Path:
    """``.<name>.lock`` beside ``target`` (a hashed name where that would be too long)."""
    target = Path(os.path.abspath(target))
    name = f".{target.name}.lock"
    if len(os.fsencode(name)) > min(name_max(target.parent), 255):
        name = f".{hashlib.sha256(os.fsencode(target.name)).hexdigest()[:32]}.lock"
    return target.parent / name


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class _AlreadyOurs(Exception):
    """The lock file is this process's own (taken by an enclosing command)."""


class OutputLock:
    """Hold the lock files of ``targets`` (outputs, files or folders) while a command runs.

    A target whose folder does not exist is not locked (the command's own checks refuse it).
    A lock held by a live process refuses with :class:`OutputBusyError`; one left by a process
    that is gone (same host, pid not running, or an empty file older than a minute) is removed.
    """

    def __init__(self, targets: Iterable[str | os.PathLike]):
        self.targets = [Path(t) for t in targets if t is not None]
        self.held: list[tuple[Path, tuple[int, int]]] = []

    def __enter__(self) -> "OutputLock":
        try:
            for t in self.targets:
                if Path(os.path.abspath(t)).parent.is_dir():
                    self._take(lock_path(t), t)
        except BaseException:
            self.release()
            raise
        return self

    def __exit__(self, *exc) -> bool:
        self.release()
        return False

    def _take(self, lock: Path, target: Path) -> None:
        me = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}
        for _ in range(3):
            try:
                fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                try:
                    self._stale(lock, target)  # refuses unless the holder is gone
                except _AlreadyOurs:
                    return  # this process holds it already (an outer command's lock)
                with contextlib.suppress(FileNotFoundError):
                    lock.unlink()
                continue
            except OSError:
                return  # an unwritable folder: the command's own checks name it
            with os.fdopen(fd, "w") as fh:
                json.dump(me, fh)
            self.held.append((lock, file_identity(lock)))
            return
        raise OutputBusyError(f"{target}: another SpecGen command holds its lock {lock} "
                              "(wait for it to finish, or delete the lock if that command is gone)")

    @staticmethod
    def _stale(lock: Path, target: Path) -> None:
        try:
            info = json.loads(lock.read_text() or "{}")
            age = time.time() - lock.stat().st_mtime
        except FileNotFoundError:
            return
        except (OSError, ValueError):
            info, age = {}, 0.0
        pid, host = info.get("pid"), info.get("host")
        if pid == os.getpid() and host == socket.gethostname():
            raise _AlreadyOurs
        if not isinstance(pid, int):
            if age > 60:
                return
            raise OutputBusyError(f"{target}: another SpecGen command is starting on it (lock {lock})")
        if host == socket.gethostname() and not _alive(pid):
            return
        raise OutputBusyError(f"{target}: SpecGen process {pid} on {host} is writing it "
                              f"(lock {lock}; delete the lock only if that process is gone)")

    def release(self) -> None:
        """Remove the lock files still ours (idempotent; safe in a hard stop's clean-up)."""
        while self.held:
            lock, ident = self.held.pop()
            if file_identity(lock) == ident:
                with contextlib.suppress(OSError):
                    lock.unlink()
