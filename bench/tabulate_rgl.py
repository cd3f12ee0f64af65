"""Seconds to tabulate each real RGL file onto the full MERL grid (90 × 90 × 180).

Target: ≤ 5 s per file on the 2-core CPU-only machine.

Usage: ``.venv/bin/python bench/tabulate_rgl.py [--repeat N] [--spectral] [FILE ...]``; without
files it uses ../shared/data/rgl/*.bsdf beside the repository. ``--spectral`` also times a
spectral file the script writes (the real felt's grid with 195 wavelengths, tabulated onto the
default 21-band grid), since the real spectral files are not available here.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]

from specgen_addon.brdf.formats.rgl import read_rgl, read_tensor_file, tabulate_rgl, write_rgl  # noqa: E402
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM  # noqa: E402

TARGET_SECONDS = 5.0


def time_tabulation(path: Path, repeat: int, wavelengths=None) -> float:
    """Best of ``repeat`` wall-clock times of read + tabulate (seconds)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        table = tabulate_rgl(read_rgl(path), wavelengths)
        best = min(best, time.perf_counter() - start)
    assert table.values.shape[:3] == (90, 90, 180)
    return best


def spectral_copy(source: Path, folder: Path) -> Path:
    """The source's adaptive grid with a 195-wavelength spectra field (360–1000 nm)."""
    f = read_tensor_file(source)
    wavelengths = np.linspace(360.0, 1000.0, 195)
    t = ((wavelengths - 360.0) / 640.0)[:, None, None]
    rgb = f["rgb"].astype(np.float64)
    spectra = (1 - t) * rgb[:, :, 2:3] + t * rgb[:, :, 0:1]
    return write_rgl(folder / f"{source.stem}_spectral.bsdf", description="spectral benchmark copy",
                     theta_i=f["theta_i"], ndf=f["ndf"], sigma=f["sigma"], vndf=f["vndf"],
                     luminance=f["luminance"], spectra=spectra, wavelengths=wavelengths)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path)
    parser.add_argument("--repeat", type=int, default=3, help="report the best of N runs")
    parser.add_argument("--spectral", action="store_true",
                        help="also time a written 195-wavelength file tabulated onto 21 bands")
    args = parser.parse_args()
    files = args.files or sorted((REPO.parent / "shared" / "data" / "rgl").glob("*.bsdf"))
    if not files:
        print("no RGL files given and none found in ../shared/data/rgl", file=sys.stderr)
        return 2
    print(f"machine: {describe_machine()}")
    print(f"grid: 90 x 90 x 180 = {90 * 90 * 180} direction pairs; best of {args.repeat}")
    missed = False
    rows = [(p.name, p, None) for p in files]
    with tempfile.TemporaryDirectory() as tmp:
        if args.spectral:
            rows.append((f"{files[0].stem} as 195-λ spectral -> 21 bands",
                         spectral_copy(files[0], Path(tmp)), DEFAULT_WAVELENGTHS_NM))
        for label, path, wavelengths in rows:
            seconds = time_tabulation(path, args.repeat, wavelengths)
            ok = seconds <= TARGET_SECONDS
            missed |= not ok
            print(f"{label}: {seconds:.2f} s ({'meets' if ok else 'MISSES'} the {TARGET_SECONDS:g} s target)")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
