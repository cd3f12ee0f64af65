"""Benchmark: seconds and peak memory to generate the full spectral BRDF table from one image.

Usage: ``python bench/infer.py [IMAGE] [--weights W] [--backend both|torch|onnx] [--torch-ops]
[--bands 21] [--repeat 3]``

Prints the machine and, per backend (both by default, runs interleaved so a busy machine slows
both alike), the wall time of :func:`specgen_addon.model.runtime.inference.generate_brdf` for the full
90 × 90 × 180 × Λ table (1.458 M angle points × Λ bands), and the process' peak resident memory
(``getrusage`` ru_maxrss) above the level after the weights were loaded. ``--torch-ops`` adds the
torch backend with its gather head on torch ops alone (``SPECGEN_KERNELS=torch``, no numba loops),
interleaved with the others.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

from machine import copy_bandwidth_gbs, describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("image", nargs="?", type=Path, default=REPO / "examples" / "sphere.png")
    ap.add_argument("--weights", type=Path, default=None)
    ap.add_argument("--backend", choices=("both", "torch", "onnx"), default="both")
    ap.add_argument("--torch-ops", action="store_true",
                    help="also time the torch backend without its numba loops (SPECGEN_KERNELS=torch)")
    ap.add_argument("--bands", type=int, default=21)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    import os

    import numpy as np

    from specgen_addon.model.runtime import inference as infer
    from specgen_addon.model import count_parameters, load_weights
    from specgen_addon.model.runtime import gather_kernels
    from specgen_addon.spectral.spectra import wavelength_grid

    wl = wavelength_grid(380.0, 780.0, args.bands)
    backends = ("onnx", "torch") if args.backend == "both" else (args.backend,)
    for backend in backends:
        infer.get_backend(args.weights, backend)           # load once: not part of the timing
    torch_ops = "torch, torch ops only"
    if args.torch_ops and "torch" in backends:
        backends += (torch_ops,)
    params = count_parameters(load_weights(args.weights))
    warm_up = None
    if "torch" in backends and gather_kernels.load() is not None:
        # numba compiles the loops on their first call (or loads them from its on-disk cache)
        t0 = time.perf_counter()
        infer.generate_brdf(args.image, weights=args.weights, wavelengths_nm=wl, backend="torch")
        warm_up = time.perf_counter() - t0
    base = rss_mb()
    times: dict[str, list[float]] = {b: [] for b in backends}
    cpu: dict[str, list[float]] = {b: [] for b in backends}
    table = None
    for _ in range(args.repeat):
        for backend in backends:
            table = None                                   # measure one table's memory, not two
            if backend == torch_ops:
                os.environ[gather_kernels.ENV_VAR] = "torch"
            t0, c0 = time.perf_counter(), time.process_time()
            table = infer.generate_brdf(args.image, weights=args.weights, wavelengths_nm=wl,
                                        backend="torch" if backend == torch_ops else backend)
            os.environ.pop(gather_kernels.ENV_VAR, None)
            times[backend].append(time.perf_counter() - t0)
            cpu[backend].append(time.process_time() - c0)
    n_eval = table.values.size
    print(f"machine: {describe_machine()}")
    print(f"model: {params:,} parameters")
    if "torch" in backends:
        loops = "numba loops" if gather_kernels.load() is not None else "torch ops (numba not installed)"
        print(f"torch backend's gather head: {loops}")
    if warm_up is not None:
        print(f"torch: first table {warm_up:.2f} s (with compiling the numba loops, or loading them from "
              "numba's cache; not in the figures below)")
    print(f"table: {table.values.shape} = {n_eval / 1e6:.1f} M evaluations ({table.values.nbytes / 1e6:.0f} MB)")
    for backend in backends:
        t = times[backend]
        print(f"{backend}: wall best {min(t):.2f} s, median {float(np.median(t)):.2f} s over {args.repeat} "
              f"runs; CPU (all threads) best {min(cpu[backend]):.2f} s")
    print(f"peak RSS: {rss_mb():.0f} MB total, {rss_mb() - base:.0f} MB above the loaded models")
    # after the peak is read: the copy's own arrays would raise it
    print(f"memory copy: {copy_bandwidth_gbs():.1f} GB/s (one thread)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
