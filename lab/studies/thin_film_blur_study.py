"""The thin-film fit with and without the photo's blur modelled, against the truth.

A photo's sphere is resampled by the pipeline's crop (every camera photo's is), which spreads a
sharp highlight over pixels; the thin-film fit without a blur model reads that as a rougher lobe.
For N thin films of one split, each photographed exactly framed (``independent``: other
environment samples than the fit's operator) and half a pixel off the grid (``shifted``: resampled
by the crop), the fit runs with no blur (``blur_px=(0,)``) and with the refinement's blur
candidates (σ chosen with the roughness), and each table is scored under the protocol's distant
lights (spectral PSNR, as ``evaluate --families``).

    cd bench && python thin_film_blur_study.py --split val --per-family 6 --skip 31 --json ../out/blur.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


PHOTOS = ("independent", "shifted")
#: σ grids compared: none, the refinement's candidates (``BLUR_CANDIDATES_PX``), and :data:`FINE_GRID_PX`
GRIDS = ("none", "refinement", "fine")
#: the finer σ grid of the forty-first session's rule 4 (pixels)
FINE_GRID_PX = (0.0, 0.35, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.4)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("val", "test"), default="val", help="corpus split (default val)")
    ap.add_argument("--per-family", type=int, default=3, help="thin films (default 3)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first K thin films of the split")
    ap.add_argument("--resolution", type=int, default=128, help="truth render size in pixels (default 128)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    ap.add_argument("--photos", nargs="+", default=list(PHOTOS), choices=PHOTOS, help="photos (default both)")
    ap.add_argument("--compare", nargs=2, default=["none", "refinement"], choices=list(GRIDS),
                    metavar="GRID", help=f"the two σ grids compared, from {', '.join(GRIDS)} "
                                         "(default: none refinement)")
    a = ap.parse_args(argv)
    if not 1 <= a.per_family <= 50 or a.skip < 0:
        ap.error("--per-family must be in 1..50 and --skip ≥ 0")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.generate.thin_film import fit_thin_film
    from specgen_addon.generate.pipeline import load_photo_crop
    from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_split_materials

    grids = {"none": (0.0,), "refinement": tuple(BLUR_CANDIDATES_PX), "fine": FINE_GRID_PX}
    first, second = a.compare
    variants = {"no blur" if first == "none" else first: grids[first],
                "blur" if second == "refinement" else second: grids[second]}
    base, new = list(variants)
    materials = mixed_split_materials(a.per_family, ["thin_film"], a.split, skip=a.skip)
    if not materials:
        ap.error(f"the {a.split} split has no thin films left after --skip {a.skip}")
    rows = []
    for mat in materials:
        score = truth_scorer(mat, a.resolution)
        independent = independent_photo(mat)
        images = {"independent": independent, "shifted": displaced_input(independent, 0.5)}
        for kind in a.photos:
            crop, linear = load_photo_crop(images[kind])
            photo = crop.image.astype(np.float64)
            row = {"material": mat.name, "photo": kind, "copied": bool(crop.copied), "alpha_true": mat.alpha}
            for label, blur in variants.items():
                t0 = time.perf_counter()
                fit = fit_thin_film(photo, None, clip_level=None if linear else 0.995, blur_px=blur)
                row[label] = {"truth_db": score(fit.table(WAVELENGTHS_NM)), "self_db": fit.reproduction.psnr_db,
                              "blur_px": fit.blur_px, "alpha": fit.material.alpha,
                              "film_eta": fit.material.film_eta, "thickness_nm": fit.material.thickness_nm,
                              "seconds": time.perf_counter() - t0}
            rows.append(row)
            print(f"{mat.name:8} {kind:11} α {mat.alpha:.4f} | " + " | ".join(
                f"{lab} {row[lab]['truth_db']:.2f} dB (self {row[lab]['self_db']:.1f}, σ {row[lab]['blur_px']:g}, "
                f"α {row[lab]['alpha']:.4f}, {row[lab]['seconds']:.0f} s)" for lab in variants), flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    for kind in a.photos:
        sel = [r for r in rows if r["photo"] == kind]
        d = np.array([r[new]["truth_db"] - r[base]["truth_db"] for r in sel])
        if d.size:
            print(f"{kind} ({d.size}): {base} {np.mean([r[base]['truth_db'] for r in sel]):.2f}, {new} "
                  f"{np.mean([r[new]['truth_db'] for r in sel]):.2f} dB; {new} − {base} {d.mean():+.2f} dB, "
                  f"worst {d.min():+.2f}, {int(np.sum(d < -1.0))} photos more than 1 dB below")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
