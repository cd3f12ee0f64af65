"""White balance from a ColorChecker Classic (``--colour-checker``) on synthetic photos: how well the
cast is taken out, how well the greys fit the chart, where the chart is found and how long it takes.

No real photo with a chart is in the shared data, so the photos are drawn (tests/checker_photo.py:
the 24 swatches from colour-science's reference values, black gaps, on a grey background, beside
the example sphere), turned, blurred, given sensor noise and a tungsten-like cast (R 1.2, G 1.0,
B 0.55), and written as a linear EXR or an 8-bit sRGB PNG; each is read as the command line reads
it (:class:`~specgen_addon.photo.sphere_image.PhotoSource` with ``colour_checker=True``). Per photo:

* **residual cast**: the largest departure of the balanced greys' R/G or B/G from the reference's,
  % (the gains times the cast, each channel over green);
* **grey fit**: the rms difference of the balanced greys from the reference after one exposure
  factor, a share of the mean reference grey (what the run prints; above 5 % it warns);
* **centre**: the found chart's centre against the drawn one, px;
* the time to find the chart and balance (wall seconds, the photo's first read).

    .venv/bin/python bench/colour_checker.py
"""

from __future__ import annotations

import runpy
import tempfile
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: the chart drawn as the tests draw it
checker_photo = SimpleNamespace(**runpy.run_path(str(REPO / "tests" / "checker_photo.py")))

from machine import describe_machine  # bench/machine.py, beside this script
from specgen_addon.common.image_io import write_exr, write_png8
from specgen_addon.photo.image_checks import ImageNote
from specgen_addon.photo.sphere_image import PhotoSource
from specgen_addon.spectral.spectra import srgb_encode

CAST = np.array([1.2, 1.0, 0.55])
#: (name, width, height, angle °, blur σ px, noise (relative σ), file, read as linear)
CASES = [("clean", 640, 400, 4.0, 0.0, 0.0, "exr", False),
         ("noise 1 %", 640, 400, 4.0, 0.0, 0.01, "exr", False),
         ("noise 3 %, blur 1 px, 12°", 640, 400, 12.0, 1.0, 0.03, "exr", False),
         ("noise 5 %, blur 2 px, -20°", 640, 400, -20.0, 2.0, 0.05, "exr", False),
         ("8-bit sRGB PNG", 640, 400, 4.0, 0.5, 0.01, "png", False),
         ("8-bit sRGB PNG read as --linear (wrong)", 640, 400, 4.0, 0.5, 0.01, "png", True),
         ("3000×2000 EXR", 3000, 2000, 4.0, 1.0, 0.01, "exr", False)]


def _photo(root: Path, width: int, height: int, angle: float, blur: float, noise: float,
           kind: str) -> tuple[Path, np.ndarray]:
    """The drawn photo (the chart at the tests' place, scaled to ``width``) and the chart's centre."""
    from scipy.ndimage import gaussian_filter

    k = width / checker_photo.WIDTH
    centre = np.asarray(checker_photo.CHART_CENTRE) * k
    img = checker_photo.draw_checker(np.full((height, width, 3), 0.25), angle, tuple(centre),
                                     checker_photo.PITCH * k, checker_photo.GAP * k)
    if blur:
        img = gaussian_filter(img, (blur * k, blur * k, 0))
    img = np.clip(img, 0, None) * CAST * 0.8
    img *= 1 + noise * np.random.default_rng(0).standard_normal(img.shape)
    img = np.clip(img, 0, None).astype(np.float32)
    path = root / f"{len(list(root.iterdir()))}.{kind}"
    if kind == "exr":
        write_exr(path, {c: img[..., i] for i, c in enumerate("RGB")})
    else:
        write_png8(path, np.round(np.clip(srgb_encode(img), 0, 1) * 255).astype(np.uint8))
    return path, centre


def main() -> None:
    print(describe_machine())
    print(f"cast R/G/B {CAST.tolist()}; residual cast = max |balanced R/G, B/G over the reference's - 1|")
    print("| photo | residual cast | grey fit (rms) | centre off | warns | seconds |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for name, w, h, angle, blur, noise, kind, linear in CASES:
            path, centre = _photo(root, w, h, angle, blur, noise, kind)
            t0 = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ImageNote)
                crop = PhotoSource(path, encoding="linear" if linear else "auto", circle=(64.0, 64.0, 32.0),
                                   colour_checker=True).crop()
            took = time.perf_counter() - t0
            g = crop.white_gains * CAST
            off = 100 * float(np.abs(g / g[1] - 1).max())
            note = crop.white_note
            fit = note.split("reference greys to ")[1].split(" % rms")[0]
            found_at = np.array([float(v) for v in note.split(" at (")[1].split(") px")[0].split(",")])
            warns = "yes" if any("greys differ" in str(c.message) for c in caught) else "no"
            print(f"| {name} | {off:.2f} % | {fit} % | {np.linalg.norm(found_at - centre):.1f} px | {warns} "
                  f"| {took:.1f} |")


if __name__ == "__main__":
    main()
