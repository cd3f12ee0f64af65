"""Keep native libraries' chatter off stdout (Cycles and Blender's image writer print
``Saved: ...`` and timing lines from C, past Python's ``sys.stdout``)."""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Callable, Iterator


@contextlib.contextmanager
def native_stdout_silenced(enabled: bool = True) -> Iterator[Callable[[str], None]]:
    """Point file descriptor 1 at ``/dev/null`` for the block (a no-op when ``enabled`` is False
    or stdout has no file descriptor); Python's own prints in the block are silenced too. Yields
    ``say(line)``, which still reaches the real stdout: a job's own progress lines."""
    try:
        fd = sys.stdout.fileno() if enabled else -1
    except (AttributeError, OSError, ValueError):
        fd = -1
    if fd < 0:
        yield lambda line: print(line, flush=True)
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    devnull = os.open(os.devnull, os.O_WRONLY)

    def say(line: str) -> None:
        os.write(saved, (line + "\n").encode("utf-8", "replace"))

    try:
        os.dup2(devnull, fd)
        yield say
    finally:
        sys.stdout.flush()
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)
