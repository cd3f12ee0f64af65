"""Refinement on photos that do not share the refinement's environment samples.

The canonical input is rendered with the same samples (56 directions per pixel, seed 0) that the
refinement's operator uses, so its fit can be exact (an "inverse crime"). A real photo has no
sampling error in common with the fit. Here each held-out material's exactly framed photo is
rendered with other samples (``--photo-seed``, ``--photo-scale`` × the renderer's default 112
directions), and the network alone and the refined table are scored under the protocol's distant
lights (spectral PSNR, as ``evaluate --families``). ``--operator-scale``/``--operator-seed`` also
refine with a denser operator (the input renders' sampling replaced for the fit only).

    cd bench && python independent_photo_refine.py --per-family 1 --photo-scale 2
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np



def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1, help="held-out materials per family (default 1)")
    ap.add_argument("--photo-seed", type=int, default=1, help="the photo's sampling seed (default 1)")
    ap.add_argument("--photo-scale", type=float, default=2.0,
                    help="the photo's directions per pixel as a multiple of 112 (default 2)")
    ap.add_argument("--operator-scale", type=float, default=None,
                    help="also refine with an operator of this multiple of 112 directions")
    ap.add_argument("--operator-seed", type=int, default=2, help="that operator's seed (default 2)")
    a = ap.parse_args(argv)
    if a.per_family < 1 or not 0.25 <= a.photo_scale <= 8 or a.photo_seed < 0 or a.operator_seed < 0 \
            or (a.operator_scale is not None and not 0.25 <= a.operator_scale <= 8):
        ap.error("--per-family ≥ 1, seeds ≥ 0 and scales in [0.25, 8]")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.generate.refine import RefineOptions, refine_brdf
    from specgen_addon.render import EnvSampling
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    photo_sampling = replace(EnvSampling().scaled(a.photo_scale), seed=a.photo_seed)
    arms = [("refined", None)]
    if a.operator_scale is not None:
        arms.append(("denser op", replace(EnvSampling().scaled(a.operator_scale), seed=a.operator_seed)))
    shipped_sampling = input_image.input_sampling
    scores: dict[str, list[float]] = {}
    for mat in mixed_test_materials(a.per_family):
        score = truth_scorer(mat, 64)

        photo = independent_photo(mat, photo_sampling).astype(np.float64)
        table = generate_brdf(photo, wavelengths_nm=WAVELENGTHS_NM)
        row = {"network": score(table)}
        for label, sampling in arms:
            # the refinement's scene comes from input_image's cached canonical scene
            input_image.input_sampling = shipped_sampling if sampling is None else (lambda s=sampling: s)
            input_image._scene.cache_clear()
            try:
                row[label] = score(refine_brdf(table, photo, None, RefineOptions(clip_level=None)).table)
            finally:
                input_image.input_sampling = shipped_sampling
                input_image._scene.cache_clear()
        for k, v in row.items():
            scores.setdefault(k, []).append(v)
        print(f"{mat.name:8} " + "  ".join(f"{k} {v:.2f}" for k, v in row.items()), flush=True)
    print("mean (dB, distant lights): " + ", ".join(f"{k} {np.mean(v):.2f}" for k, v in scores.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
