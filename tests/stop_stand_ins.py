"""Stand-ins for stopping a command with Ctrl-C in a child process: Blender's own Python code
(where a signal may land), and a runner that sends SIGINT once the child says it is ready.

Import it by name (``from stop_stand_ins import sigint_when_ready``): tests/ is on the test path.
"""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

#: Source of ``fake_blender.py``: Blender code that keeps writing, fails late or sits in a long C call.
FAKE_BLENDER = r"""
import os, time
from specgen_addon.common import atomic_io as io_utils


def busy_writing(folder, seconds):
    # Blender's own Python (a startup script, an operator): running, writing files, for a while
    t = time.monotonic()
    i = 0
    while time.monotonic() - t < seconds:
        path = folder / f"from_blender_{i % 500}.txt"
        path.write_text("x")
        # SpecGen's writer called from Blender's code: the file enters the ledger of what the
        # command made (inline, so that no frame of SpecGen's own code runs here)
        st = os.lstat(path)
        io_utils._LEDGER[os.path.abspath(path)] = ((st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size),
                                                   next(io_utils._SEQ))
        i += 1
    return i


def fails_after(seconds):
    # Blender's C code whose system call the signal cut short: it reports an error a while later
    t = time.monotonic()
    while time.monotonic() - t < seconds:
        pass
    raise RuntimeError("Error: cannot read file (Interrupted system call)")


def stuck_in_a_c_call(seconds):
    # a Cycles render: one long C call under Blender's Python, where no Python signal handler runs
    import signal
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})   # the C handler runs on
    try:                                                              # another thread meanwhile
        time.sleep(seconds)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
"""


def fake_blender_modules(root: Path) -> Path:
    """Write ``fake_blender.py`` under ``root`` in a folder Blender's own modules have
    (``blender/5.0/scripts/modules``); gives that folder, for the child's ``sys.path``."""
    folder = root / "blender" / "5.0" / "scripts" / "modules"
    folder.mkdir(parents=True)
    (folder / "fake_blender.py").write_text(FAKE_BLENDER)
    return folder


def sigint_when_ready(cmd: list[str], delay: float, timeout: float = 60) -> tuple[int, str]:
    """Start ``cmd``, wait for its first line ``READY``, send SIGINT ``delay`` seconds later and wait
    up to ``timeout`` seconds for it to end (killed if it does not); gives (exit code, output)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout.readline().strip() == "READY"
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        text, _ = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, text
