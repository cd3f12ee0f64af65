"""Peak memory of reading a large photo of a sphere (target: an 8000² PNG peaks ≤ 2 GB).

Writes a SIZE×SIZE 8-bit RGB photo of a sphere (a Lambertian-shaded disc with a sharp outline,
drawn band by band), then loads it in a fresh
process with ``input_image.load_sphere_image`` (header check, bounded-memory decoding and
downsampling, sphere detection, resampling to the canonical 128²) and prints that process's peak
resident memory (``ru_maxrss``) next to the same for a 128² image (the interpreter's baseline).

Usage: ``.venv/bin/python bench/image_memory.py [--size 8000] [--format png|jpg]``
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from machine import describe_machine  # bench/machine.py, beside this script

if TYPE_CHECKING:
    import numpy as np

REPO = Path(__file__).resolve().parents[1]
TARGET_GB = 2.0

CHILD = r"""
import resource, sys, time, warnings
sys.path.insert(0, {repo!r})
warnings.simplefilter("ignore")
from specgen_addon.photo.sphere_image import load_sphere_image
t0 = time.perf_counter()
img = load_sphere_image({path!r})
dt = time.perf_counter() - t0
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, dt, img.shape)
"""


def peak_gb(path: Path) -> tuple[float, float]:
    """(peak RSS in GB, seconds) of loading ``path`` in a fresh interpreter."""
    done = subprocess.run([sys.executable, "-c", CHILD.format(repo=str(REPO), path=str(path))],
                          capture_output=True, text=True, check=True)
    gb, seconds, *_ = done.stdout.split()
    return float(gb), float(seconds)


def sphere_photo(size: int) -> np.ndarray:
    """8-bit sRGB (size, size, 3): a diffuse orange sphere lit from the upper left, black around."""
    import numpy as np

    out = np.zeros((size, size, 3), np.uint8)
    light = np.array([-0.5, 0.5, 0.7]) / np.linalg.norm([-0.5, 0.5, 0.7])
    x = (np.arange(size) + 0.5) / size * 2.2 - 1.1
    for y0 in range(0, size, 256):
        y = -((np.arange(y0, min(size, y0 + 256)) + 0.5) / size * 2.2 - 1.1)[:, None]
        r2 = x[None] ** 2 + y ** 2
        z = np.sqrt(np.clip(1 - r2, 0, None))
        shade = np.clip(x[None] * light[0] + y * light[1] + z * light[2], 0, 1) * 0.9 + 0.05
        lin = np.where(r2[..., None] < 1, shade[..., None] * np.array([0.8, 0.4, 0.15]), 0.0)
        enc = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
        out[y0:y0 + 256] = np.round(enc * 255).astype(np.uint8)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=8000)
    ap.add_argument("--format", choices=("png", "jpg"), default="png")
    args = ap.parse_args()
    from PIL import Image

    print(describe_machine())
    with tempfile.TemporaryDirectory() as tmp:
        small = Path(tmp) / f"small.{args.format}"
        big = Path(tmp) / f"big.{args.format}"
        Image.fromarray(sphere_photo(128)).save(small, quality=95)
        t0 = time.perf_counter()
        Image.fromarray(sphere_photo(args.size)).save(big, quality=95)
        print(f"wrote {args.size}×{args.size} {args.format.upper()} "
              f"({big.stat().st_size / 2**20:.0f} MiB) in {time.perf_counter() - t0:.0f} s")
        base, _ = peak_gb(small)
        peak, seconds = peak_gb(big)
    verdict = "meets" if peak <= TARGET_GB else "MISSES"
    print(f"peak RSS loading 128²: {base:.2f} GB (interpreter + libraries)")
    print(f"peak RSS loading {args.size}²: {peak:.2f} GB in {seconds:.1f} s — {verdict} the "
          f"≤ {TARGET_GB:g} GB target")


if __name__ == "__main__":
    main()
