"""Step batches made ahead by worker processes, so a GPU is not left waiting on numpy.

A step's batch is a pure function of ``(seed, step)`` (:func:`.loop.make_step_batches`), so
workers can make future steps while the network trains on the current one, and the run is the
same, bit for bit, as one that makes each batch when it needs it. On a GPU the data is the bound
(lab/notebook/gpu-training.md: 10–160 ms of numpy against 22–46 ms of network per step on an
H200; docs/headless-and-scale.md, "Data workers"), on two CPU cores the network is, and the
default is no workers.
"""

from __future__ import annotations

import collections
import signal
from typing import Any, Callable, Iterator
from specgen_addon.common.processes import can_pool, context

#: The batch maker a worker calls (set by :func:`_start_worker` in each worker).
_MAKE: Callable[[int], Any] | None = None


def _ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the training process, which stops them (no traceback per worker)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _start_worker(make: Callable[[int], Any]) -> None:
    """Each worker's start: keep the batch maker (copied by fork, pickled by spawn)."""
    global _MAKE
    _ignore_interrupts()
    _MAKE = make


def _make(step: int) -> Any:
    assert _MAKE is not None
    return _MAKE(step)


def step_batches(make: Callable[[int], Any], start: int, stop: int, workers: int = 0,
                 ahead: int | None = None) -> Iterator[Any]:
    """``make(step)`` for ``step`` in ``[start, stop)``, in order.

    With ``workers`` > 0 they are made by that many worker processes, at most ``ahead`` steps
    (default ``2 · workers``) ahead of the consumer, so memory stays bounded however fast the
    workers are. The pool is torn down when the consumer stops early (a time budget, Ctrl-C).
    """
    if workers <= 0:
        for step in range(start, stop):
            yield make(step)
        return

    if not can_pool(make):  # inside a pool worker, or spawn and ``make`` cannot travel
        for step in range(start, stop):
            yield make(step)
        return
    pool = context().Pool(workers, initializer=_start_worker, initargs=(make,))
    try:
        steps = iter(range(start, stop))
        pending: collections.deque = collections.deque()
        for step in steps:
            pending.append(pool.apply_async(_make, (step,)))
            if len(pending) >= (ahead or 2 * workers):
                break
        while pending:
            batch = pending.popleft().get()
            nxt = next(steps, None)
            if nxt is not None:
                pending.append(pool.apply_async(_make, (nxt,)))
            yield batch
    finally:
        pool.terminate()
        pool.join()
