"""Progress reporting shared by CLI commands: a tqdm bar driven by fraction callbacks."""

from __future__ import annotations

import contextlib
import sys
from typing import Callable, Iterator


@contextlib.contextmanager
def progress_bar(desc: str, total: int = 100, enabled: bool = True) -> Iterator[Callable[[float], None]]:
    """Yield ``update(fraction)`` that moves a tqdm bar on stderr (silent when disabled)."""
    if not enabled:
        yield lambda fraction: None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="%", file=sys.stderr, leave=True,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}")
    try:
        def update(fraction: float) -> None:
            bar.n = round(max(0.0, min(1.0, fraction)) * total)
            bar.refresh()

        yield update
    finally:
        bar.close()
