"""Clean stops: SIGINT/SIGTERM end a command with exit 130/143 and leave no new files behind.

:func:`stop_on_signals` turns both signals into :class:`Interrupted` (a ``KeyboardInterrupt``, so
``except Exception`` never swallows it) raised in the main thread, and records the request so
long loops and per-band renders can also poll :func:`stop_requested` (for code where Blender's own
signal handling delays Python's). :class:`OutputGuard` snapshots the output folders and, when the
work fails or is stopped, removes whatever appeared in them (``keep`` names files left on purpose,
such as a resumable training checkpoint), so the final message can say truthfully what is left.
:func:`private_tempdir` keeps other libraries' temporary files (Cycles' OSL compiler) in a folder
removed on every exit path.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path
from typing import Iterable, Iterator

EXIT_ERROR = 2
EXIT_SIGINT = 128 + signal.SIGINT    # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143
#: Folders with more entries than this are snapshotted at their top level only.
MAX_SNAPSHOT_ENTRIES = 20_000

_requested: list[int] = []


class Interrupted(KeyboardInterrupt):
    """The user (SIGINT, Ctrl-C) or the system (SIGTERM) asked the command to stop."""

    def __init__(self, signum: int = signal.SIGINT):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    @property
    def signal_name(self) -> str:
        return signal.Signals(self.signum).name


def stop_requested() -> bool:
    """True once SIGINT or SIGTERM arrived under :func:`stop_on_signals` (for polling)."""
    return bool(_requested)


def raise_if_stopped() -> None:
    """Raise :class:`Interrupted` if a stop was requested (call between long steps)."""
    if _requested:
        raise Interrupted(_requested[0])


#: Clean-up steps a hard stop runs (newest first): see :func:`on_hard_stop`.
_cleanups: list = []
#: Seconds the main thread has to act on a signal before the watcher stops the process itself.
HARD_STOP_GRACE_S = 1.0


@contextlib.contextmanager
def on_hard_stop(cleanup) -> Iterator[None]:
    """Register ``cleanup()`` for a hard stop while the block runs (see :func:`stop_on_signals`)."""
    _cleanups.append(cleanup)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            _cleanups.remove(cleanup)



#: Wakeup pipes of the active :func:`stop_on_signals` blocks. A process forked while one is active
#: (a multiprocessing or Dask worker) inherits the pipe *and* the wakeup fd: a signal to that child
#: would write its number into our pipe and our watcher would end this process. Forked children
#: drop both, and get the default SIGINT/SIGTERM actions back (:func:`_forget_wakeup_in_child`).
_WAKEUP_PIPES: list[tuple[int, int]] = []


def _forget_wakeup_in_child() -> None:
    if not _WAKEUP_PIPES:
        return
    with contextlib.suppress(Exception):
        signal.set_wakeup_fd(-1)
    # The parent stops its workers with SIGTERM (Pool.terminate) or they share its Ctrl-C: a
    # worker ends quietly by the default action instead of printing our Interrupted traceback.
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(Exception):
            signal.signal(signum, signal.SIG_DFL)
    for fds in _WAKEUP_PIPES:
        for fd in fds:
            with contextlib.suppress(OSError):
                os.close(fd)
    _WAKEUP_PIPES.clear()


#: The parent's wakeup fd, set aside while it forks (:func:`_pause_wakeup_for_fork`).
_PAUSED_WAKEUP: list[int] = []


def _pause_wakeup_for_fork() -> None:
    """Before a fork, the parent unsets its wakeup fd, so a signal that reaches the child before the
    child's own at-fork hook has run cannot write into the parent's pipe (that ended the parent)."""
    if not _WAKEUP_PIPES or threading.current_thread() is not threading.main_thread():
        return
    with contextlib.suppress(Exception):
        _PAUSED_WAKEUP.append(signal.set_wakeup_fd(-1))


def _resume_wakeup_after_fork() -> None:
    while _PAUSED_WAKEUP:
        fd = _PAUSED_WAKEUP.pop()
        with contextlib.suppress(Exception):
            signal.set_wakeup_fd(fd, warn_on_full_buffer=False)


def _child_after_fork() -> None:
    _PAUSED_WAKEUP.clear()
    _forget_wakeup_in_child()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_pause_wakeup_for_fork, after_in_parent=_resume_wakeup_after_fork,
                        after_in_child=_child_after_fork)


@contextlib.contextmanager
def stop_on_signals(message=None) -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` while the block runs (main thread only).

    Python runs signal handlers only between bytecodes, and a Cycles render (or any long C call)
    keeps the main thread away from them for minutes. So a watcher thread is woken by the signal
    itself (``signal.set_wakeup_fd``); if the main thread has not acted within
    :data:`HARD_STOP_GRACE_S`, the watcher runs the registered clean-ups (:func:`on_hard_stop`:
    new outputs and temporary folders removed), prints ``message(signal name)`` and ends the
    process with 128 + signal number. A signal that lands in an import (where raising is unsafe)
    is instead delivered again once the main thread is back in ordinary code (within
    :data:`IMPORT_GRACE_S`), so a lazy import of a large library still ends in the command's own
    clean stop and message.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    acted = threading.Event()

    in_import = threading.Event()

    def handler(signum, frame):
        _requested.append(signum)
        reason = _deferral_reason(frame)
        if reason is not None:  # Blender would swallow the exception: the watcher acts instead
            if reason == "import":
                in_import.set()
            return
        if not acted.is_set():  # the first signal our code sees (a re-delivered one included)
            acted.set()
            raise Interrupted(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    read_fd, write_fd = os.pipe()
    _WAKEUP_PIPES.append((read_fd, write_fd))
    os.set_blocking(write_fd, False)
    old_wakeup = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)

    def watch() -> None:
        while True:
            try:
                data = os.read(read_fd, 1)
            except OSError:
                return
            if not data:
                return
            signum = data[0]
            if signum not in (signal.SIGINT, signal.SIGTERM) or acted.wait(HARD_STOP_GRACE_S):
                continue
            if in_import.is_set() and _wait_out_of_import(acted):
                in_import.clear()
                # the signal landed in an import (a lazy ``import onnxruntime``, say), where raising
                # is unsafe; now the main thread is back in our code: deliver it again to raise there
                with contextlib.suppress(OSError):
                    os.kill(os.getpid(), signum)
                continue
            for cleanup in reversed(list(_cleanups)):
                with contextlib.suppress(Exception):
                    cleanup()
            name = signal.Signals(signum).name
            with contextlib.suppress(Exception):
                sys.stdout.flush()
                print(message(name) if message else f"cancelled: stopped by {name}", file=sys.stderr,
                      flush=True)
            os._exit(128 + signum)

    watcher = threading.Thread(target=watch, name="specgen-signal-watch", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        signal.set_wakeup_fd(old_wakeup)
        with contextlib.suppress(ValueError):
            _WAKEUP_PIPES.remove((read_fd, write_fd))
        os.close(write_fd)
        watcher.join(timeout=2.0 if not _requested else 0.1)
        with contextlib.suppress(OSError):
            os.close(read_fd)
        for s, h in previous.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        _requested.clear()


_OWN_ROOT = str(Path(__file__).resolve().parents[1])
_BLENDER_SCRIPT_DIRS = tuple(os.sep + os.path.join("scripts", d) + os.sep
                             for d in ("addons_core", "modules", "startup", "addons"))


#: Longest wait for the main thread to leave an import before a hard stop (seconds).
IMPORT_GRACE_S = 30.0


def _main_thread_in_import() -> bool:
    """True while the main thread's innermost frames are an import (before any of SpecGen's own)."""
    frame = sys._current_frames().get(threading.main_thread().ident)
    while frame is not None:
        name = frame.f_code.co_filename
        if name.startswith("<frozen importlib"):
            return True
        if name.startswith(_OWN_ROOT) and "site-packages" not in name:
            return False
        frame = frame.f_back
    return False


def _wait_out_of_import(acted: threading.Event) -> bool:
    """Wait (up to :data:`IMPORT_GRACE_S`) until the main thread is out of the import a signal
    landed in; True when it is and nothing else has acted on the signal meanwhile."""
    deadline = time.monotonic() + IMPORT_GRACE_S
    while time.monotonic() < deadline:
        if acted.wait(0.05):
            return False
        if not _main_thread_in_import():
            return True
    return False


def _deferral_reason(frame) -> str | None:
    """Why a signal must not raise in the interrupted code: ``"blender"`` for Blender's own Python
    (add-on registration, Cycles' engine callbacks: Blender catches and prints exceptions raised
    there instead of passing them on), ``"import"`` for an import (it may run inside bpy's C
    start-up, where raising crashes it), reached before any of SpecGen's frames; None otherwise."""
    while frame is not None:
        name = frame.f_code.co_filename
        if any(d in name for d in _BLENDER_SCRIPT_DIRS):
            return "blender"
        if name.startswith("<frozen importlib"):
            return "import"
        if name.startswith(_OWN_ROOT) and "site-packages" not in name:
            return None
        frame = frame.f_back
    return None



def as_interrupted(exc: BaseException) -> Interrupted:
    """A plain ``KeyboardInterrupt`` (Ctrl-C outside :func:`stop_on_signals`) as SIGINT."""
    return exc if isinstance(exc, Interrupted) else Interrupted(_requested[0] if _requested else signal.SIGINT)


def _snapshot(folder: Path) -> set[str]:
    if not folder.is_dir():
        return set()
    seen: set[str] = set()
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            seen.add(os.path.relpath(os.path.join(root, name), folder))
        if len(seen) > MAX_SNAPSHOT_ENTRIES:
            return {p for p in seen if os.sep not in p}
    return seen


class OutputGuard:
    """Remove what a failed or stopped command created in its output folders.

    ``folders`` are snapshotted on entry (a missing one is removed whole if it was created);
    ``keep`` holds paths to leave in place on purpose. After the block, :attr:`removed` and
    :attr:`kept` list what happened, for the final message.
    """

    def __init__(self, folders: Iterable[str | os.PathLike], keep: Iterable[str | os.PathLike] = ()):
        self.folders = [Path(f) for f in folders if f is not None]
        self.keep = {Path(k).resolve() for k in keep}
        self.removed: list[Path] = []
        self.kept: list[Path] = []
        self._before: dict[Path, set[str] | None] = {}

    def __enter__(self) -> "OutputGuard":
        for f in self.folders:
            self._before[f] = _snapshot(f) if f.exists() else None
        _cleanups.append(self.clean)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        with contextlib.suppress(ValueError):
            _cleanups.remove(self.clean)
        if exc_type is not None:
            self.clean()
        return False

    def clean(self) -> None:
        """Remove what appeared in the folders since entry (except ``keep``)."""
        for folder, before in self._before.items():
            self._clean(folder, before)

    def _clean(self, folder: Path, before: set[str] | None) -> None:
        if not folder.is_dir():
            return
        # deepest first, so a new folder is empty (bar kept files) when its turn comes
        for rel in sorted(_snapshot(folder) - (before or set()), key=lambda p: -p.count(os.sep)):
            path = folder / rel
            if path.resolve() in self.keep:
                self.kept.append(path)
                continue
            with contextlib.suppress(OSError):
                if path.is_dir() and not path.is_symlink():
                    path.rmdir()  # fails (kept) when a kept file is inside
                else:
                    path.unlink()
                self.removed.append(path)
        if before is None:
            with contextlib.suppress(OSError):
                folder.rmdir()

    def left_behind(self) -> str:
        """One clause for a message: what the stopped command left on purpose, or that it left
        nothing."""
        existing = [p for p in self.kept if p.exists()]
        if existing:
            return "kept " + ", ".join(str(p) for p in existing)
        return "nothing partial was left"


@contextlib.contextmanager
def private_tempdir(prefix: str = "specgen_") -> Iterator[Path]:
    """Point :mod:`tempfile` (and so Cycles' OSL compiler) at a fresh folder; remove it after."""
    work = Path(tempfile.mkdtemp(prefix=prefix))
    previous = tempfile.tempdir
    tempfile.tempdir = str(work)

    def remove() -> None:
        shutil.rmtree(work, ignore_errors=True)

    try:
        with on_hard_stop(remove):
            yield work
    finally:
        tempfile.tempdir = previous
        remove()


def verbose_requested(argv: Iterable[str] | None = None) -> bool:
    """``--verbose`` on the command line, or ``SPECGEN_VERBOSE=1`` (tracebacks to the console)."""
    return os.environ.get("SPECGEN_VERBOSE", "") not in ("", "0") or \
        "--verbose" in (sys.argv if argv is None else list(argv))


def print_traceback_if(verbose: bool, exc: BaseException) -> None:
    """The full traceback of ``exc`` on stderr, only when ``verbose`` (never in the one-line message)."""
    if verbose:
        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
