"""Refinement settings on photos that share no samples with its operator: truth after refinement.

For N materials per family of one split of the mixed corpus, three photos of the sphere under the
canonical lighting go through the user's pipeline (the sphere is found and cropped; the network
that the cut chooses runs):

* ``canonical``: the input render itself, which shares the refinement operator's environment
  samples (an "inverse crime": the fit can be exact);
* ``independent``: the same exactly framed photo rendered with other samples (seed 1, twice the
  directions), as a real photo shares none;
* ``shifted``: the independent photo half a pixel off the grid (resampled by the crop, as a
  camera's photo is; the canonical render moved would still share the operator's samples).

Each photo's network table is then refined with every candidate setting of ``RefineOptions``
(:data:`SETTINGS`) and scored against the truth under the
protocol's distant lights (spectral PSNR, as ``evaluate --families``), beside the photo's
self-reproduction. Settings are chosen on ``--split val``; figures are reported on ``test``.

    cd bench && python refine_prior_study.py --split val --per-family 1 --json ../out/bench/prior_val.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


#: candidate settings: label → RefineOptions fields ("shipped": the defaults; "block smoothness":
#: one smoothness weight per block of knots, the earlier default)
SETTINGS: dict[str, dict] = {
    "shipped": {},
    "block smoothness": {"smooth_weight": "block"},
    "floor": {"fit_floor": 1.0},
    "block, floor": {"smooth_weight": "block", "fit_floor": 1.0},
    "body network": {"body_prior": "network"},
    "no relax": {"relax_below_db": 0.0},
    # θh knots of the correction: the shipped ones start (0°, 0.5°, 1.1°, ...); the earlier ones
    # also had 0.04° and 0.2°, inside one pixel of the highlight
    "knots from 0.04°": {"theta_h_knots": (0, 2, 4, 7, 10, 14, 19, 25, 32, 41, 51, 65, 89)},
    "knots from 1.1°": {"theta_h_knots": (0, 10, 14, 19, 25, 32, 41, 51, 65, 89)},
    # the relaxed fit only where it predicts held-out pixels better (shipped); "relax below 42 dB"
    # tries it wherever the smooth fit reproduced the photo below 42 dB
    "relax by holdout": {"relax_holdout": True},
    "relax below 42 dB": {"relax_holdout": False},
    # the lobe's correction only where it predicts held-out pixels better than the network's lobe
    "lobe by holdout": {"lobe_holdout": True},
    # the relaxed fit loosens the θh smoothness only (not adopted)
    "relax θh only": {"relax_axes": "theta_h", "relax_holdout": False},
    # the body: a convex mix of Otsu 2018's and the network's colour-matched spectra (not adopted),
    # the number being the network's share
    "body blend 1/2": {"body_prior": "blend", "body_blend": 0.5},
    "body blend 1/4": {"body_prior": "blend", "body_blend": 0.25},
    # Otsu 2018's body where the eye sees, the network's in the tails (visibility below 0.3 / 0.1)
    "body tails 0.3": {"body_prior": "tails", "body_visibility": 0.3},
    "body tails 0.1": {"body_prior": "tails", "body_visibility": 0.1},
}
PHOTOS = ("canonical", "independent", "shifted")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("val", "test"), default="val", help="corpus split (default val)")
    ap.add_argument("--per-family", type=int, default=1, help="materials per family (default 1)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first K materials of each family")
    ap.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS),
                    help="settings to compare (default all)")
    ap.add_argument("--photos", nargs="+", default=list(PHOTOS), choices=PHOTOS, help="photos (default all)")
    ap.add_argument("--resolution", type=int, default=64,
                    help="truth render size in pixels (default 64; paper-tables scores at 128, where a "
                         "sharp highlight's peak falls on a pixel more often)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    a = ap.parse_args(argv)
    if not 1 <= a.per_family <= 20 or a.skip < 0:
        ap.error("--per-family must be in 1..20 and --skip ≥ 0")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.generate.pipeline import generate, load_photo_crop
    from specgen_addon.generate.refine import CLIP_LEVEL, CorrectionBasis, RefineOptions, refine_brdf
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_split_materials

    rows = []
    for mat in mixed_split_materials(a.per_family, None, a.split, skip=a.skip):
        fam = material_family(mat)
        score = truth_scorer(mat, a.resolution)

        canonical = input_image.render_input(mat)
        independent = independent_photo(mat)
        images = {"canonical": canonical, "independent": independent,
                  "shifted": displaced_input(independent, 0.5)}
        for kind in a.photos:
            image = images[kind]
            crop, linear = load_photo_crop(image)
            photo = crop.image.astype(np.float64)
            table = generate(image, refine=False, wavelengths_nm=WAVELENGTHS_NM).table
            row = {"material": mat.name, "family": fam, "photo": kind, "network": score(table)}
            for label in a.settings:
                t0 = time.perf_counter()
                kw = dict(SETTINGS[label])
                if "theta_h_knots" in kw:
                    kw["basis"] = CorrectionBasis(theta_h_knots=kw.pop("theta_h_knots"))
                opts = RefineOptions(clip_level=None if linear else CLIP_LEVEL, **kw)
                res = refine_brdf(table, photo, None, opts)
                row[label] = {"truth_db": score(res.table), "self_db": res.after.psnr_db,
                              "self_de": res.after.delta_e2000, "self_network_db": res.before.psnr_db,
                              "improved": res.improved, "blur_px": res.blur_px,
                              "relaxed_gain_db": res.relaxed_gain_db, "relaxed": res.relaxed,
                              "relaxed_holdout_db": res.relaxed_holdout_db,
                              "lobe_holdout_db": res.lobe_holdout_db, "lobe_kept": res.lobe_kept,
                              "seconds": time.perf_counter() - t0}
            rows.append(row)
            print(f"{mat.name:8} {fam:11} {kind:11} network {row['network']:6.2f} | "
                  + " | ".join(f"{lab} {row[lab]['truth_db']:6.2f} ({row[lab]['self_db']:.1f})"
                               for lab in a.settings), flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    for kind in a.photos:
        sel = [r for r in rows if r["photo"] == kind]
        if not sel:
            continue
        print(f"mean {kind} ({len(sel)}): network {np.mean([r['network'] for r in sel]):.2f} | "
              + " | ".join(f"{lab} {np.mean([r[lab]['truth_db'] for r in sel]):.2f} "
                           f"(self {np.mean([r[lab]['self_db'] for r in sel]):.1f}, worst gain "
                           f"{min(r[lab]['truth_db'] - r['network'] for r in sel):+.2f})"
                           for lab in a.settings))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
