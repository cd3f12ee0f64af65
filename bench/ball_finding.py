"""The ball found without a mask on the shared real photos, against the mask's circle and the
photos' own silhouette.

Data: ../shared/data/photos/psm_gray_chrome (12 photos of a matte grey ball and 12 of a chrome
ball, 512×340, 8-bit values that behave as linear, each with the dataset's drawn mask). Per photo:
the circle the product finds with no mask or circle given (:func:`crop_sphere`, as ``infer`` and
the panel do, values read linearly), and

* against the **mask's circle** (:func:`mask_circle`: the soft mask's centroid and its
  area-equivalent radius, as ``--mask`` uses it): the centre's distance and the radius' difference
  (found − mask), px;
* against the **silhouette**: the circle through the photo's own outline, measured without a
  model where every side of the ball is lit, on the brightest-of-twelve image: along 360 rays from
  the mask's centre, the point where the brightness is halfway between the rim's (3 px inside)
  and the ground's (3–6 px outside), the stand below left out, a least-squares circle through
  those points (:func:`half_rise_circle`; its radius reads about 0.2 px small, the rim's shading
  still falling towards the edge 3 px inside). The same two figures;
* the time (CPU seconds, process time) the finding took.

    .venv/bin/python bench/ball_finding.py [--kinds gray chrome] [--photos 0 1 ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from machine import describe_machine  # bench/machine.py, beside this script
from specgen_addon.common.errors import ImageInputError
from specgen_addon.photo.ndimage_np import fit_circle, map_coordinates
from specgen_addon.photo.read import read_photo
from specgen_addon.photo.sphere_detect import luminance
from specgen_addon.photo.sphere_image import crop_sphere, mask_circle, read_mask

DATA = REPO.parent / "shared" / "data" / "photos" / "psm_gray_chrome"


def half_rise_circle(lum: np.ndarray, cx: float, cy: float, r: float, rays: int = 360,
                     below: tuple[float, float] = (30.0, 150.0)) -> tuple[float, float, float] | None:
    """The silhouette near (cx, cy, r) without a model (module docstring): rays whose angle (degrees,
    y down) lies in ``below`` (the stand) and rays with under a tenth of the best rim's contrast
    are left out."""
    phi = (np.arange(rays) + 0.5) / rays * 2 * np.pi
    deg = np.degrees(phi)
    phi = phi[(deg < below[0]) | (deg > below[1])]
    rho = np.arange(r - 6.0, r + 6.0 + 1e-9, 0.05)
    x, y = cx + np.cos(phi)[:, None] * rho, cy + np.sin(phi)[:, None] * rho
    prof = map_coordinates(lum, [y - 0.5, x - 0.5], order=1, mode="nearest")
    rim = prof[:, np.searchsorted(rho, r - 3.0)]
    ground = np.median(prof[:, rho > r + 3.0], axis=1)
    half = 0.5 * (rim + ground)
    ok = rim - ground > 0.1 * np.max(rim - ground)
    fall = (prof < half[:, None]) & (rho > r - 3.0)[None]
    j = np.argmax(fall, axis=1)
    ok &= fall.any(axis=1) & (j > 0)
    k = np.nonzero(ok)[0]
    if k.size < 10:
        return None
    a, b = prof[k, j[k] - 1], prof[k, j[k]]
    edge = rho[j[k] - 1] + (a - half[k]) / (a - b) * (rho[1] - rho[0])
    fx, fy, fr = fit_circle(np.stack([cx + edge * np.cos(phi[k]), cy + edge * np.sin(phi[k])], -1))
    return float(fx), float(fy), float(fr)


def _offsets(found, ref) -> tuple[float, float]:
    return float(np.hypot(found[0] - ref[0], found[1] - ref[1])), float(found[2] - ref[2])


def run(kind: str, photos: list[int]) -> list[dict]:
    rgbs = {i: read_photo(DATA / kind / f"{kind}.{i}.tga", encoding="linear").rgb[..., :3]
            for i in range(12)}
    mask = mask_circle(read_mask(DATA / kind / f"{kind}.mask.tga", rgbs[0].shape[:2]))
    silhouette = half_rise_circle(luminance(np.max(list(rgbs.values()), axis=0)), *mask)
    print(f"\n{kind}: mask's circle ({mask[0]:.2f}, {mask[1]:.2f}, r {mask[2]:.2f})"
          + ("; silhouette not measured (no rim stands out)" if silhouette is None else
             f"; silhouette ({silhouette[0]:.2f}, {silhouette[1]:.2f}, r {silhouette[2]:.2f})"))
    print("photo | found (cx, cy, r) px | vs mask: centre, radius px | vs silhouette: centre, radius px | CPU s")
    rows = []
    for i in photos:
        t0 = time.process_time()
        try:
            crop = crop_sphere(rgbs[i])
            found, how = crop.circle, crop.circle_source
        except ImageInputError as exc:
            found, how = None, str(exc)
        cpu = time.process_time() - t0
        if found is None:
            print(f"{i:5d} | not found ({how}) | | | {cpu:.2f}")
            rows.append({"photo": i, "found": None, "cpu_s": cpu})
            continue
        dm, rm = _offsets(found, mask)
        ds, rs = _offsets(found, silhouette) if silhouette else (float("nan"), float("nan"))
        vs_silhouette = f"{ds:.2f}, {rs:+.2f}" if silhouette else "not measured"
        print(f"{i:5d} | ({found[0]:.2f}, {found[1]:.2f}, {found[2]:.2f}) | {dm:.2f}, {rm:+.2f} | "
              f"{vs_silhouette} | {cpu:.2f}")
        rows.append({"photo": i, "found": found, "how": how, "mask": (dm, rm), "silhouette": (ds, rs),
                     "cpu_s": cpu})
    ok = [r for r in rows if r["found"] is not None]
    if ok:
        dm = np.array([r["mask"][0] for r in ok])
        rm = np.array([r["mask"][1] for r in ok])
        ds = np.array([r["silhouette"][0] for r in ok])
        rs = np.array([r["silhouette"][1] for r in ok])
        worst = np.maximum(dm, np.abs(rm))
        print(f"{kind}: found in {len(ok)} of {len(rows)}; vs mask: centre {dm.min():.2f}–{dm.max():.2f} "
              f"(median {np.median(dm):.2f}), radius {rm.min():+.2f} to {rm.max():+.2f}, "
              f"{int(np.sum(worst <= 0.5))} of {len(rows)} within 0.5 px (centre and radius)")
        if silhouette:
            worst_s = np.maximum(ds, np.abs(rs))
            print(f"{kind}: vs silhouette: centre {ds.min():.2f}–{ds.max():.2f} (median {np.median(ds):.2f}), "
                  f"radius {rs.min():+.2f} to {rs.max():+.2f}, "
                  f"{int(np.sum(worst_s <= 0.5))} of {len(rows)} within 0.5 px")
        print(f"{kind}: CPU per photo {np.median([r['cpu_s'] for r in rows]):.2f} s median, "
              f"{max(r['cpu_s'] for r in rows):.2f} s max")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kinds", nargs="+", default=["gray", "chrome"], choices=["gray", "chrome"])
    ap.add_argument("--photos", nargs="+", type=int, default=list(range(12)))
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"needs the shared photos at {DATA}", file=sys.stderr)
        return 2
    print(describe_machine())
    for kind in args.kinds:
        run(kind, args.photos)
    return 0


if __name__ == "__main__":
    sys.exit(main())
