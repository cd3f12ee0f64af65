"""The latent fit on photos that share no samples with its operator: truth before and after.

For N materials per family of one split of the mixed corpus, the sphere photographed under the
canonical lighting with other environment samples than the fit's operator (``independent``: seed 1,
twice the directions) and the same photo half a pixel off the grid (``shifted``) go through the
user's pipeline (the sphere is found and cropped; the network the cut chooses runs). Each photo's
table is then scored against the truth under the protocol's distant lights (spectral PSNR, as
``evaluate --families``):

* ``network``: the network alone;
* ``refined``: the shipped refinement of the network's table (:func:`specgen_addon.generate.refine.refine_brdf`);
* ``fit``: the network's latent fitted to the photo (:func:`specgen_addon.generate.latent_fit.fit_latent`);
* ``fit+ref``: the shipped refinement of the fitted table;
* with ``--also-holdout``, ``fit ho`` and ``fit ho+ref``: the same with
  ``LatentFitOptions(holdout=True)`` (fitted to one half of the sphere's blocks, judged by the other);
* with ``--also-keep-peak``, ``fit kp`` and ``fit kp+ref``: the same with
  ``LatentFitOptions(keep_peak=True)`` (θh finer than the photo's pixel left to the network).

Settings are chosen on ``--split val``; figures are reported on ``test``.

    cd bench && python latent_fit_study.py --split val --per-family 1 --skip 17 --json ../out/fit_val.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


PHOTOS = ("independent", "shifted")
COLUMNS = ("network", "refined", "fit", "fit+ref", "fit ho", "fit ho+ref", "fit kp", "fit kp+ref")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("val", "test"), default="val", help="corpus split (default val)")
    ap.add_argument("--per-family", type=int, default=1, help="materials per family (default 1)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first K materials of each family")
    ap.add_argument("--photos", nargs="+", default=list(PHOTOS), choices=PHOTOS, help="photos (default both)")
    ap.add_argument("--resolution", type=int, default=128, help="truth render size in pixels (default 128)")
    ap.add_argument("--no-refine", action="store_true", help="score the network and the fit only")
    ap.add_argument("--also-holdout", action="store_true", help="also the fit with holdout=True")
    ap.add_argument("--also-keep-peak", action="store_true", help="also the fit with keep_peak=True")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    a = ap.parse_args(argv)
    if not 1 <= a.per_family <= 20 or a.skip < 0 or not 16 <= a.resolution <= 1024:
        ap.error("--per-family must be in 1..20, --skip ≥ 0 and --resolution in 16..1024")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf, sphere_crop
    from specgen_addon.generate.latent_fit import LatentFitOptions, fit_latent
    from specgen_addon.generate.refine import RefineOptions, refine_brdf
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_split_materials

    wl = np.asarray(WAVELENGTHS_NM, np.float64)
    rows = []
    for mat in mixed_split_materials(a.per_family, None, a.split, skip=a.skip):
        score = truth_scorer(mat, a.resolution)

        independent = independent_photo(mat)
        for kind in a.photos:
            image = independent if kind == "independent" else displaced_input(independent, 0.5)
            crop = sphere_crop(image)
            photo = crop.image.astype(np.float64)            # an array: linear, nothing clipped
            network = generate_brdf(crop, wavelengths_nm=wl)
            row = {"material": mat.name, "family": material_family(mat), "photo": kind, "network": score(network)}
            if not a.no_refine:
                row["refined"] = score(refine_brdf(network, photo, None, RefineOptions(clip_level=None)).table)
            for label, options in [("fit", LatentFitOptions())] + (
                    [("fit ho", LatentFitOptions(holdout=True))] if a.also_holdout else []) + (
                    [("fit kp", LatentFitOptions(keep_peak=True))] if a.also_keep_peak else []):
                fit = fit_latent(crop, photo, None, None, wl, options, network_table=network)
                row.update({label: score(fit.table), f"{label}_self_db": [fit.before_db, fit.after_db],
                            f"{label}_held_out_db": fit.held_out_db, f"{label}_improved": fit.improved,
                            f"{label}_blur_px": fit.blur_px, f"{label}_seconds": fit.seconds})
                if not a.no_refine:
                    row[f"{label}+ref"] = score(refine_brdf(fit.table, photo, None,
                                                            RefineOptions(clip_level=None)).table)
            rows.append(row)
            print(f"{mat.name:8} {row['family']:11} {kind:11} "
                  + " | ".join(f"{c} {row[c]:6.2f}" for c in COLUMNS if c in row)
                  + f" | fit self {row['fit_self_db'][0]:.1f} → {row['fit_self_db'][1]:.1f} dB, "
                  f"{row['fit_seconds']:.0f} s", flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    cols = [c for c in COLUMNS if c in rows[0]]
    print(f"mean ({len(rows)} photos): " + " | ".join(f"{c} {np.mean([r[c] for r in rows]):.2f}" for c in cols))
    if "refined" in cols:
        for c in cols[2:]:
            d = np.array([r[c] - r["refined"] for r in rows])
            print(f"{c} against refined: mean {d.mean():+.2f} dB, worst {d.min():+.2f}, "
                  f"photos below by more than 1 dB: {int((d < -1).sum())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
