"""How SpecGen starts worker processes: one start method for every pool, chosen in one place.

Linux starts workers by ``fork`` (fast, no re-import); Windows has only ``spawn`` and macOS
defaults to it, so every pool must also work there: what a worker runs is pickled, and nothing
may rely on memory copied at fork. ``SPECGEN_START_METHOD=spawn`` (or ``forkserver``) makes a
Linux run behave like those platforms, which is how the tests check it.

A pool worker is a daemonic process and may not start processes of its own (``daemonic processes
are not allowed to have children``): :func:`may_start_workers` tells code that would start a
nested pool to do the work in-process instead.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal
import sys
from typing import Any

from specgen_addon.common.errors import SpecGenError

#: Environment variable naming the start method (fork, spawn or forkserver).
ENV_START_METHOD = "SPECGEN_START_METHOD"


def start_method() -> str:
    """The start method of SpecGen's pools: ``$SPECGEN_START_METHOD`` when set, otherwise
    ``fork`` on Linux and ``spawn`` elsewhere (Windows has no fork; macOS's fork is unsafe)."""
    available = mp.get_all_start_methods()
    wanted = os.environ.get(ENV_START_METHOD, "").strip().lower()
    if wanted:
        if wanted not in available:
            raise SpecGenError(f"{ENV_START_METHOD}={wanted} is not available here "
                               f"(choose one of {', '.join(available)})")
        return wanted
    return "fork" if sys.platform.startswith("linux") and "fork" in available else "spawn"


def context() -> Any:
    """The multiprocessing context of :func:`start_method`."""
    return mp.get_context(start_method())


def quiet_worker() -> None:
    """Pool initializer: the worker leaves Ctrl-C to its parent, which stops the pool. Under fork
    the at-fork hooks of :mod:`.interrupts` see to that; a spawned worker starts with Python's
    default handler and would print a KeyboardInterrupt traceback of its own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def may_start_workers() -> bool:
    """False inside a pool worker (a daemonic process), which cannot have children."""
    return not mp.current_process().daemon


def picklable(obj: Any) -> bool:
    """Whether ``obj`` can be sent to a spawned worker (closures and lambdas cannot)."""
    try:
        pickle.dumps(obj)
    except Exception:  # noqa: BLE001 - pickling raises many kinds (PicklingError, AttributeError, TypeError)
        return False
    return True


def can_pool(task: Any = None, per_task: bool = False) -> bool:
    """Whether a pool may run ``task`` here: not inside a pool worker, and ``task`` picklable when
    it travels to the workers: always for a function given with each task (``Pool.imap``,
    ``per_task``), and at the workers' start under any start method but fork (``initargs``)."""
    if not may_start_workers():
        return False
    return task is None or (start_method() == "fork" and not per_task) or picklable(task)


def pool_workers(workers: int, task: Any = None, per_task: bool = False) -> int:
    """How many processes a pool for ``task`` may use: ``workers``, or 1 (in-process) where
    :func:`can_pool` says no."""
    return workers if workers <= 1 or can_pool(task, per_task) else 1
