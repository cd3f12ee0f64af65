"""Signal handling of :mod:`specgen_addon.interrupts` in processes forked inside a stop block."""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time

import pytest

from specgen_addon.interrupts import HARD_STOP_GRACE_S, stop_on_signals

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="fork and POSIX signals")


def _sleep_quietly() -> None:
    time.sleep(30)


def test_a_worker_forked_inside_a_stop_block_ends_quietly_on_sigterm():
    """Pool.terminate() sends SIGTERM to the render workers: they must die by the default action,
    not raise the parent's Interrupted (a traceback per worker at the end of every corpus run)."""
    ctx = multiprocessing.get_context("fork")
    with stop_on_signals():
        child = ctx.Process(target=_sleep_quietly)
        child.start()
        time.sleep(0.3)
        os.kill(child.pid, signal.SIGTERM)
        child.join(10)
    assert child.exitcode == -signal.SIGTERM


def test_a_signal_to_a_just_forked_child_does_not_reach_the_parent():
    """SIGTERM sent the moment the child exists, before its at-fork hook ran: it must not come
    through the parent's inherited wakeup pipe (the parent's watcher would end the parent, 143)."""
    ctx = multiprocessing.get_context("fork")
    with stop_on_signals():
        child = ctx.Process(target=_sleep_quietly)
        child.start()
        child.terminate()
        child.join(2)
        if child.is_alive():      # the signal may be lost in the child's fork window
            child.kill()
            child.join(10)
        time.sleep(HARD_STOP_GRACE_S + 0.5)  # the parent's watcher would have acted by now
        assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, signal.SIG_IGN, None)


SLOW_IMPORT_SCRIPT = r"""
import sys, time
sys.path.insert(0, {repo!r})
sys.path.insert(0, {mods!r})
from specgen_addon.interrupts import Interrupted, stop_on_signals
try:
    with stop_on_signals():
        print("READY", flush=True)
        import slow_to_import   # the signal lands here (an import: deferred)
        print("IMPORTED", flush=True)
        t = time.monotonic()
        while time.monotonic() - t < 20:   # ordinary code, where it must be raised
            pass
    print("NOT STOPPED", flush=True)
except Interrupted as exc:
    print("RAISED", exc.signal_name, flush=True)
    sys.exit(exc.exit_code)
"""


def test_a_signal_inside_a_slow_import_is_raised_in_the_code_after_it(tmp_path):
    """A lazy ``import onnxruntime`` can take seconds; a Ctrl-C landing there must not end in the
    watcher's hard stop (generic message) but raise in the command's own code once it is over."""
    import subprocess
    from pathlib import Path

    mods = tmp_path / "mods"
    mods.mkdir()
    (mods / "slow_to_import.py").write_text(f"import time\ntime.sleep({HARD_STOP_GRACE_S + 2.0})\n")
    script = tmp_path / "s.py"
    script.write_text(SLOW_IMPORT_SCRIPT.format(repo=str(Path(__file__).resolve().parents[1]), mods=str(mods)))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "READY"
        time.sleep(0.5)                     # inside the import's sleep
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out
    assert "IMPORTED" in out and "RAISED SIGINT" in out, out
    assert "cancelled: stopped by" not in out, out
