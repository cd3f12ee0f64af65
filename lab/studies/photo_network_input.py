"""What the network is shown for a real photo under a known light, against what it was trained on.

For grey-ball photos of ``../shared/data/photos/psm_gray_chrome`` (128² crops about the mask's
circle, as ``bench/photos_leave_one_out.py``): the photo, the network's input as photo ×
``network_gain`` (the way before 2026-12-07), the Lambertian albedo fitted under the file's light
(power 1), the canonical studio render of that Lambertian (a training input of the same material),
and the canonical re-render the product now shows the network
(:mod:`specgen_addon.generate.canonical_input`): mean RGB and chromaticity over the sphere, the
99th percentile of the brightest channel, and the share of the sphere lit (> 2 % of its peak).

Usage: ``.venv/bin/python lab/studies/photo_network_input.py [--inputs 0 3 6]``
(notes: lab/notebook/real-photos-network.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))

import photos_leave_one_out as loo


def stats(name: str, img: np.ndarray, inside: np.ndarray) -> None:
    v = img[inside]
    lit = float((v.sum(1) > 0.02 * v.sum(1).max()).mean())
    mean = v.mean(0)
    print(f"  {name:34s} mean {np.round(mean, 3)} chromaticity {np.round(mean / mean.sum(), 3)} "
          f"p99 {np.percentile(v.max(1), 99):.3f} lit {lit:.2f}")


def main(argv=None) -> int:
    from specgen_addon.generate.analytic_fit import AnalyticRGB
    from specgen_addon.generate.canonical_input import canonical_input
    from specgen_addon.generate.refine import CLIP_LEVEL
    from specgen_addon.photo.sphere_image import render_input
    from specgen_addon.render import sphere_geometry

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--inputs", type=int, nargs="+", default=[0, 3, 6])
    args = ap.parse_args(argv)
    lights = loo.load_lights(loo.DATA / "lights.txt")
    inside = sphere_geometry(loo.SIZE).mask
    for i in args.inputs:
        crop = loo.crop("gray", i)
        photo = crop.image.astype(np.float64)
        lighting = loo.file_lighting(lights[i])
        gain = lighting.network_gain()
        print(f"gray.{i}: light {np.round(lights[i], 3)}, network_gain {np.round(gain, 3)}")
        stats("photo", photo, inside)
        stats("photo × network_gain", photo * gain, inside)
        white = loo.white_render(lighting)
        ok = inside & (photo.max(-1) > 0)
        albedo = (photo[ok] * white[ok]).sum(0) / (white[ok] ** 2).sum(0)
        print(f"  Lambertian albedo under the file's light (power 1): {np.round(albedo, 3)}")
        lambert = AnalyticRGB(tuple(albedo), (0.0, 0.0, 0.0), 0.5, edge=0.0)   # RGB, no lobe
        white = AnalyticRGB((1.0, 1.0, 1.0), (0.0, 0.0, 0.0), 0.5, edge=0.0)
        stats("studio render of that Lambertian", render_input(lambert, loo.SIZE), inside)
        stats("studio render of a white Lambertian", render_input(white, loo.SIZE), inside)
        made = canonical_input(photo, lighting, CLIP_LEVEL, crop.saturated)
        print(f"  {made.describe()}")
        stats("canonical re-render", made.crop.image, inside)
    return 0


if __name__ == "__main__":
    sys.exit(main())
