"""Keep native libraries' chatter off stdout (Cycles and Blender's image writer print
``Saved: ...`` and timing lines from C, past Python's ``sys.stdout``), and off both streams
where a library reports a damaged file in lines of its own before raising (the OpenEXR reader
on a truncated file): the error the caller raises is then the one sentence the user reads."""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Callable, Iterator


@contextlib.contextmanager
def _to_devnull(streams) -> Iterator[list[int]]:
    """Point the file descriptors of ``streams`` (those that have one) at ``/dev/null`` for the
    block; yields copies of the originals, which still reach where the streams went."""
    fds = []
    for stream in streams:
        try:
            stream.flush()
            fds.append(stream.fileno())
        except (AttributeError, OSError, ValueError):
            continue
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield saved
    finally:
        for stream in streams:
            with contextlib.suppress(AttributeError, OSError, ValueError):
                stream.flush()
        for fd, copy in zip(fds, saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)


@contextlib.contextmanager
def native_stdout_silenced(enabled: bool = True) -> Iterator[Callable[[str], None]]:
    """Point file descriptor 1 at ``/dev/null`` for the block (a no-op when ``enabled`` is False
    or stdout has no file descriptor); Python's own prints in the block are silenced too. Yields
    ``say(line)``, which still reaches the real stdout: a job's own progress lines."""
    with _to_devnull([sys.stdout] if enabled else []) as saved:
        if not saved:
            yield lambda line: print(line, flush=True)
            return

        def say(line: str) -> None:
            os.write(saved[0], (line + "\n").encode("utf-8", "replace"))

        yield say


@contextlib.contextmanager
def native_output_silenced() -> Iterator[None]:
    """Point file descriptors 1 and 2 at ``/dev/null`` for the block (those that exist): a native
    library's own warning lines are dropped; Python exceptions still propagate, and the caller
    says what went wrong in one sentence."""
    with _to_devnull([sys.stdout, sys.stderr]):
        yield
