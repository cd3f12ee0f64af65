"""One description of the benchmarking machine, printed by every script in bench/."""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np


def describe_machine() -> str:
    """Architecture, cores, memory, Python/numpy versions and the current load average."""
    mem = ""
    try:
        mem = f", {os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE') / 2**30:.0f} GB"
    except (ValueError, OSError, AttributeError):
        pass
    accel = "CPU only"
    torch = sys.modules.get("torch")  # named only when the bench already uses torch
    if torch is not None and torch.cuda.is_available():
        accel = f"GPU {torch.cuda.get_device_name(0)} (torch {torch.__version__})"
    return (f"{platform.machine()}, {os.cpu_count()} cores{mem}, {accel}; Python "
            f"{platform.python_version()}, numpy {np.__version__}; "
            f"load average {os.getloadavg()[0]:.2f}")


def copy_bandwidth_gbs(megabytes: int = 200, repeat: int = 5) -> float:
    """Best memory bandwidth of one thread copying a ``megabytes`` array (GB/s, read + write).

    Printed beside timings so that machines of the same core count can be told apart: the same
    code's full-table inference has taken from 1.4 s to 10 s on different 2-core machines."""
    src = np.ones(megabytes * 2**20 // 8)
    dst = np.empty_like(src)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        np.copyto(dst, src)
        best = min(best, time.perf_counter() - t0)
    return 2 * src.nbytes / best / 1e9
