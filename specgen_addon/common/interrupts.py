"""Clean stops: SIGINT/SIGTERM end a command with exit 130/143 and leave no new files behind.

:func:`stop_on_signals` turns both signals into :class:`Interrupted` (a ``KeyboardInterrupt``, so
``except Exception`` never swallows it) raised in the main thread, and records the request so
long loops and per-band renders can also poll :func:`stop_requested` (for code where Blender's own
signal handling delays Python's). :class:`OutputGuard`, when the work fails or is stopped, removes
the files this process made in its output folders, by identity (``keep`` names files left on
purpose, such as a resumable training checkpoint), so the final message can say truthfully what
is left, and never removes a file another process wrote there.
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
from specgen_addon.common.atomic_io import created_since, is_ours, ledger_mark, remove_created

EXIT_ERROR = 2
EXIT_SIGINT = 128 + signal.SIGINT    # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143

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
        _act_in_main_thread(_requested[0])


#: Acquired once per stop by whoever acts on it: the main thread (by raising :class:`Interrupted`
#: in our code) or the watcher (a hard stop). The other side stands down, so a stop is never acted
#: on twice, with one side cleaning the output folders while the other still writes into them.
_stop_token = threading.Lock()
_stop_owner: list[str] = []


def _claim_stop(who: str) -> str:
    """Claim the current stop for ``who`` ("main" or "watcher"); returns who owns it."""
    if _stop_token.acquire(blocking=False):
        _stop_owner.append(who)
        return who
    deadline = time.monotonic() + 1.0
    while not _stop_owner and time.monotonic() < deadline:  # the owner is between its two steps
        time.sleep(0.001)
    return _stop_owner[0] if _stop_owner else who


def _release_stop() -> None:
    _stop_owner.clear()
    if _stop_token.locked():
        _stop_token.release()


def _remove_blender_session_folder() -> None:
    """Remove the session folder a loaded bpy made (``bpy.app.tempdir``, ``blender_XXXXXX`` in
    the temporary folder), which Blender removes itself on a normal exit only. The module is
    looked up, never imported: the core does not load bpy."""
    bpy = sys.modules.get("bpy")
    folder = getattr(getattr(bpy, "app", None), "tempdir", "") if bpy is not None else ""
    if not folder:
        return
    folder = os.path.abspath(folder)
    if os.path.basename(folder.rstrip(os.sep)).startswith("blender_") and \
            os.path.dirname(folder.rstrip(os.sep)) == os.path.abspath(tempfile.gettempdir()):
        shutil.rmtree(folder, ignore_errors=True)


class _Parked(BaseException):
    """Raised asynchronously in the main thread once the watcher owns a stop. CPython creates the
    exception object when a handler (an ``except``, ``finally`` or ``with`` block, or Blender's C
    code printing it) takes it, and creating it waits for the watcher's ``os._exit``: the main
    thread runs none of that handler's code, nor anything after the C call it was in."""

    def __init__(self, *args):
        _wait_for_the_watchers_exit()
        super().__init__(*args)  # pragma: no cover - the process ends first


#: Set once the main thread has stopped for the watcher's exit: only then does its clean-up start.
_MAIN_PARKED = threading.Event()
#: How long the watcher waits for the main thread to stop before cleaning up anyway (it is in one
#: long C call then, as a Cycles render, and runs no Python that could write).
PARK_WAIT_S = 2.0


def _wait_for_the_watchers_exit() -> None:
    """Block this (main) thread for good: the watcher owns the stop and ends the process."""
    _MAIN_PARKED.set()
    threading.Event().wait()


def _park_main_thread() -> None:
    """Park the main thread at its next Python instruction (see :class:`_Parked`). A thread busy
    in one C call (a Cycles render) is parked when, if ever, the call returns."""
    import ctypes

    with contextlib.suppress(Exception):
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(threading.main_thread().ident),
                                                   ctypes.py_object(_Parked))


def _act_in_main_thread(signum: int) -> None:
    """Raise :class:`Interrupted` unless the watcher is already stopping the process; then wait
    for its exit instead of going on (and writing more files) while it cleans up."""
    if _claim_stop("main") == "main":
        raise Interrupted(signum)
    _wait_for_the_watchers_exit()


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
    keeps the main thread away from them for minutes. A signal that lands in Blender's own Python
    or in an import is not raised there either (Blender would swallow the exception; raising in
    bpy's C start-up crashes it). So a watcher thread is woken by the signal itself
    (``signal.set_wakeup_fd``) and follows the main thread (:func:`_follow_main_thread`):

    - while the main thread runs Python, or sits in an import, the watcher waits; once it is back
      in our own code the signal is delivered again and raised there, so the command's own clean
      stop and message follow;
    - if the main thread stays in one C call outside an import for :data:`HARD_STOP_GRACE_S`, or
      has not come back within :data:`MAX_DEFERRAL_S`, the watcher stops the process itself: it
      runs the registered clean-ups (:func:`on_hard_stop`: new outputs and temporary folders
      removed), prints ``message(signal name)`` and exits with 128 + signal number.

    Whichever side acts first owns the stop (:func:`_claim_stop`); the other stands down.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if not _requested or _requested[-1] != signum:
            _requested.append(signum)
        _last_handled[0] = time.monotonic()
        if _deferral_reason(frame) is not None:  # the watcher follows the main thread instead
            return
        if not _stop_owner:  # the first signal our code sees (a re-delivered one included)
            _act_in_main_thread(signum)

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
            if signum not in (signal.SIGINT, signal.SIGTERM) or _stop_owner:
                continue
            if not _follow_main_thread(signum) or _claim_stop("watcher") != "watcher":
                continue
            with contextlib.suppress(Exception):
                sys.stdout.flush()
            _park_main_thread()  # nothing of the command runs on (and writes) while we clean up
            # a starved main thread may still run a few instructions (create a file) before it
            # takes the parking: clean up only once it has stopped
            _MAIN_PARKED.wait(PARK_WAIT_S)
            for cleanup in reversed(list(_cleanups)):
                with contextlib.suppress(Exception):
                    cleanup()
            _remove_blender_session_folder()   # os._exit skips Blender's own clean-up of it
            name = signal.Signals(signum).name
            with contextlib.suppress(Exception):
                text = message(name) if message else f"cancelled: stopped by {name}"
                os.write(sys.stderr.fileno(), (text + "\n").encode())
            os._exit(128 + signum)

    watcher = threading.Thread(target=watch, name="specgen-signal-watch", daemon=True)
    watcher.start()
    try:
        yield
    finally:  # nested, so that a signal landing here cannot skip the rest of the tear-down
        try:
            for s, h in previous.items():
                signal.signal(s, h if h is not None else signal.SIG_DFL)
            signal.set_wakeup_fd(old_wakeup)
        finally:
            try:
                with contextlib.suppress(ValueError):
                    _WAKEUP_PIPES.remove((read_fd, write_fd))
                os.close(write_fd)
                watcher.join(timeout=2.0 if not _requested else 0.1)
                with contextlib.suppress(OSError):
                    os.close(read_fd)
            finally:
                _requested.clear()
                _release_stop()


_OWN_ROOT = str(Path(__file__).resolve().parents[2])
_THIS_FILE = __file__
_BLENDER_SCRIPT_DIRS = tuple(os.sep + os.path.join("scripts", d) + os.sep
                             for d in ("addons_core", "modules", "startup", "addons"))


#: Longest wait for the main thread to come back to our code (from an import or from Blender's
#: own Python that keeps running) before a hard stop (seconds).
MAX_DEFERRAL_S = 30.0
#: How often the watcher looks at the main thread, and delivers the signal again (seconds).
_FOLLOW_POLL_S = 0.02
_REDELIVER_S = 0.1
#: When the main thread last ran our signal handler (time.monotonic()): its heartbeat.
_last_handled = [0.0]


def _main_thread_position() -> str | None:
    """Where the main thread is: :func:`_deferral_reason` of its innermost frame ("import",
    "blender", or None for our own code)."""
    frame = sys._current_frames().get(threading.main_thread().ident)
    return None if frame is None else _deferral_reason(frame)


def _follow_main_thread(signum: int) -> bool:
    """After a signal, deliver it again every :data:`_REDELIVER_S` until the main thread acts on
    it (False): its handler raises as soon as it runs in our own code, and defers it, beating a
    heartbeat, while it runs Blender's Python or an import. True when the watcher must stop the
    process itself: no heartbeat for :data:`HARD_STOP_GRACE_S` outside an import (one long C
    call, as a Cycles render), or no stop within :data:`MAX_DEFERRAL_S`. (A heartbeat, not a look
    at the main thread's frame: a loop that spends its time in one C call shows the same frame
    at every look, though it runs.)"""
    start = time.monotonic()
    last_kick = start
    while not _stop_owner:
        now = time.monotonic()
        if now - start > MAX_DEFERRAL_S:
            return True
        if _main_thread_position() != "import" and \
                now - max(_last_handled[0], start) >= HARD_STOP_GRACE_S:
            return True
        if now - last_kick >= _REDELIVER_S:
            last_kick = now
            with contextlib.suppress(OSError):
                os.kill(os.getpid(), signum)
        time.sleep(_FOLLOW_POLL_S)
    return False


def _deferral_reason(frame) -> str | None:
    """Why a signal must not raise in the interrupted code: ``"blender"`` for Blender's own Python
    (add-on registration, Cycles' engine callbacks: Blender catches and prints exceptions raised
    there instead of passing them on), ``"import"`` for an import (it may run inside bpy's C
    start-up, where raising crashes it), reached before any of SpecGen's frames; None otherwise.
    This module's own frames (a signal handler running, or interrupted by a second signal) are
    looked through, to the code they interrupted."""
    while frame is not None:
        name = frame.f_code.co_filename
        if name == _THIS_FILE:
            frame = frame.f_back
            continue
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


class OutputGuard:
    """Remove what a failed or stopped command created in its output folders, and nothing else.

    Ownership is by identity, not by a snapshot of the folders: only files and folders in this
    process's ledger (:mod:`.io_utils`: every :func:`~.io_utils.atomic_write` publication and
    :func:`~.io_utils.make_dirs` folder) made while the guard was active, and still the very
    files made, are removed; another process's files in the same folders stay. A folder that did
    not exist on entry is removed only when empty. ``keep`` holds paths to leave in place on
    purpose. After the block, :attr:`removed` and :attr:`kept` list what happened.
    """

    def __init__(self, folders: Iterable[str | os.PathLike], keep: Iterable[str | os.PathLike] = ()):
        self.folders = [Path(f) for f in folders if f is not None]
        self.keep = [Path(k) for k in keep]
        self.removed: list[Path] = []
        self.kept: list[Path] = []
        self._missing: list[Path] = []
        self._mark = 0

    def __enter__(self) -> "OutputGuard":
        self._missing = [f for f in self.folders if not f.exists()]
        self._mark = ledger_mark()
        _cleanups.append(self.clean)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is not None:
                try:
                    self.clean()
                except KeyboardInterrupt:  # a signal in the middle of the clean-up: finish it
                    self.clean()
                    raise
        finally:  # registered until now, so a hard stop meanwhile also cleans
            with contextlib.suppress(ValueError):
                _cleanups.remove(self.clean)
        return False

    def clean(self) -> None:
        """Remove what this process made in the folders since entry (except ``keep``)."""
        mine = created_since(self._mark, self.folders)
        keep = {os.path.abspath(k) for k in self.keep}
        self.kept += [p for p in mine if os.path.abspath(p) in keep and is_ours(p)
                      and p not in self.kept]
        self.removed += remove_created(mine, keep=self.keep)
        for folder in self._missing:  # made by this run, or by a library on its behalf
            with contextlib.suppress(OSError):
                folder.rmdir()  # only when empty

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
