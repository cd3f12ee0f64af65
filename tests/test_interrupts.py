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
