"""Leave-one-light-out on synthetic balls: does the θd-aware relaxed fit hold beyond the grey ball?

The shared photos are of one matte ball. Here held-out corpus materials (glossy plastics, coats,
metals: balls unlike the matte grey one) are rendered by the reference renderer under
the 12 distant lights of ../shared/data/photos/psm_gray_chrome/lights.txt (128², 16-bit
quantised, clipped at 1, as a linear camera file), one photo goes in, the other eleven are
predicted, scored as bench/photos_leave_one_out.py scores (PSNR after one shared exposure). Arms:
``before``: the refinement started from the network's table of the photo × the gain, its relaxed
fit loosening both axes everywhere (θd always counted as seen); ``relax``: the same start, the
θd-aware relaxation (:func:`specgen_addon.generate.refine.theta_d_seen`, the product's); ``rerender``:
the θd-aware relaxation started from the network's table of the canonical re-render (a candidate,
not the product's start: lab/notebook/real-photos-network.md); and a Lambertian fitted to the same
photo (the floor).

    .venv/bin/python lab/studies/synthetic_loo_relax.py --materials 6 --inputs 0 2 5 9
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))


def studio_disagreement_db(table, rerender: np.ndarray) -> float:
    """PSNR (dB, over the sphere, peak = the re-render's brightest pixel) between the network's
    table of the photo rendered in the canonical studio and the photo's analytic refit rendered
    there (the canonical re-render): low where the network's table holds what the photo's fit
    does not, e.g. a highlight the one-light photo cannot see."""
    from specgen_addon.photo.sphere_image import render_input
    from specgen_addon.render import sphere_geometry

    size = rerender.shape[0]
    mask = sphere_geometry(size).mask
    net = render_input(table, size)
    mse = float(np.mean((net[mask] - rerender[mask]) ** 2))
    return 10.0 * np.log10(float(rerender[mask].max()) ** 2 / max(mse, 1e-30))


def main(argv=None) -> int:
    import photos_leave_one_out as loo
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable
    from specgen_addon.evaluation.protocol import test_materials
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf, render_under
    from specgen_addon.generate.canonical_input import network_crop
    from specgen_addon.generate.refine import refinement
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop
    from specgen_addon.render import sphere_geometry
    from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--materials", type=int, default=6)
    ap.add_argument("--skip", type=int, default=0, help="start at this material of the split (corpus order)")
    ap.add_argument("--split", choices=["test", "val"], default="test", help="the corpus split to draw from")
    ap.add_argument("--arms", nargs="+", default=["before", "relax", "rerender"],
                    choices=["before", "relax", "rerender"])
    ap.add_argument("--inputs", type=int, nargs="+", default=[0, 2, 5, 9])
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    lights = loo.load_lights(loo.DATA / "lights.txt")
    size = loo.SIZE
    inside = sphere_geometry(size).mask
    scenes = [loo.file_lighting(l) for l in lights]
    wl = DEFAULT_WAVELENGTHS_NM
    rows = []
    seen = refinement.theta_d_seen
    if args.split == "test":
        materials = test_materials(args.skip + args.materials)
    else:
        from specgen_addon.corpus import generate_corpus
        from specgen_addon.evaluation.protocol import CORPUS_SEED, CORPUS_SIZE

        materials = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == "val"]
    for mat in materials[args.skip:args.skip + args.materials]:
        def fn(th, td, pd, mat=mat):
            wi, wo = io_from_half_diff(th, td, pd)
            return mat.eval(wi, wo, wl)

        truth = BRDFTable.tabulate(fn, wl)
        photos = []
        for lt in scenes:
            img = render_under(truth, lt.scene(size), EXPOSURE)
            photos.append(np.round(np.clip(img / max(float(np.percentile(img[inside], 99.9)), 1e-6) * 0.9, 0, 1)
                                   * 65535) / 65535)
        masks = [inside & (p.max(-1) < CLIP_LEVEL) & (p.max(-1) > 0) for p in photos]
        for i in args.inputs:
            photo, lt = photos[i], scenes[i]
            held = [j for j in range(12) if j != i]
            own = generate_brdf(SphereCrop(photo * lt.network_gain(), True))
            canonical = network_crop(SphereCrop(photo, True), photo, lt, CLIP_LEVEL)[0]
            rerender = generate_brdf(canonical)
            out = {"material": mat.name, "kind": getattr(mat, "kind", ""), "input": i,
                   "disagreement_db": round(studio_disagreement_db(own, canonical.image), 2)}
            for arm, start, always in (("before", own, True), ("relax", own, False), ("rerender", rerender, False)):
                if arm not in args.arms:
                    continue
                refinement.theta_d_seen = (lambda scene: True) if always else seen
                try:
                    res = refine_brdf(start, photo, lt, RefineOptions(clip_level=CLIP_LEVEL))
                finally:
                    refinement.theta_d_seen = seen
                preds = [render_under(res.table, scenes[j].scene(size), EXPOSURE) for j in held]
                out[arm] = loo.score(preds, [photos[j] for j in held], [masks[j] for j in held])["psnr_db"]
                out[f"{arm}_relaxed"] = res.relaxed
            albedo = loo.lambertian_albedo(photo, masks[i], lt)
            out["lambertian"] = loo.score([loo.white_render(scenes[j]) * albedo for j in held],
                                          [photos[j] for j in held], [masks[j] for j in held])["psnr_db"]
            print(json.dumps(out), flush=True)
            rows.append(out)
    for k in [*args.arms, "lambertian"]:
        print(k, round(float(np.mean([r[k] for r in rows])), 2))
    for k in args.arms:
        print(k, "below the floor:", sum(r[k] < r["lambertian"] for r in rows), "of", len(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
