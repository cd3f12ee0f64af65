"""Which self-reproduction figure tells a wrong input light from a right one, on the shared real
grey-ball photos: the refined table's self-reproduction (what the warning uses today) beside
lighting-free references fitted to the same pixels.

For each grey photo, the refinement runs as the product runs it (network on the photo × gain,
refined under the lighting) under the file's light (right) and under wrong ones: the canonical
studio (no light given), the light of photo i+6 (another direction), and the file light mirrored
left-right. Printed per row: refined and network self-reproduction (dB), a Lambertian under the
given light, and the best second-order spherical-harmonic Lambertian (9 lighting coefficients per
channel, fitted by least squares to the same pixels: any distant lighting of a Lambertian ball,
Ramamoorthi & Hanrahan 2001), all with the product's PSNR (``render.photo_reproduction``); with
``lab/patches/lighting-warning-any-light.diff`` applied, also the refinement's own reference
(``RefineResult.any_light_db``) and whether its rule warned.

With ``--synthetic N``: the first N materials of the corpus's training split instead (no study of
the refinement has scored them), rendered by the reference renderer under lights 0 and 5 of the
photos' file as 16-bit linear photos (as ``synthetic_loo_relax.py`` makes them).

    .venv/bin/python lab/studies/lighting_warning.py --json lab/runs/lighting_warning.jsonl
    .venv/bin/python lab/studies/lighting_warning.py --synthetic 16 --json lab/runs/lighting_warning_synthetic.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO))

from photos_leave_one_out import DATA, SIZE, crop, file_lighting, lambertian_albedo, load_lights, white_render  # noqa: E402


def sh9(normals: np.ndarray) -> np.ndarray:
    """(N, 9) real spherical-harmonic basis up to order 2 (unnormalised: its span is what counts)."""
    x, y, z = normals.T
    return np.stack([np.ones_like(x), x, y, z, x * y, y * z, x * z, x * x - y * y, 3 * z * z - 1], 1)


def residual_figures(photo: np.ndarray, rendered: np.ndarray, mask: np.ndarray, scale: float) -> dict:
    """Where the refined render misses the photo: PSNR (dB, the photo's level) over its brightest
    5 % of pixels and over the rest, and the brightest pixels' share of the squared residual."""
    lum = photo[mask].mean(1)
    top = lum >= np.percentile(lum, 95)
    err = ((rendered[mask] - photo[mask]) / scale) ** 2
    db = lambda e: round(float(-10 * np.log10(max(e.mean(), 1e-30))), 2)  # noqa: E731
    return {"bright_db": db(err[top]), "rest_db": db(err[~top]),
            "bright_share": round(float(err[top].sum() / max(err.sum(), 1e-30)), 4)}


def synthetic_cases(n: int, lights: np.ndarray, split: str = "train"):
    """(name, light index, SphereCrop) of ``n`` corpus materials of ``split`` under lights 0, 5."""
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable
    from specgen_addon.corpus import generate_corpus
    from specgen_addon.evaluation.protocol import CORPUS_SEED, CORPUS_SIZE
    from specgen_addon.generate.refine import render_under
    from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop
    from specgen_addon.render import sphere_geometry
    from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM as wl

    inside = sphere_geometry(SIZE).mask
    train = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == split][:n]
    for mat in train:
        def fn(th, td, pd, mat=mat):
            wi, wo = io_from_half_diff(th, td, pd)
            return mat.eval(wi, wo, wl)

        truth = BRDFTable.tabulate(fn, wl)
        for i in (0, 5):
            img = render_under(truth, file_lighting(lights[i]).scene(SIZE), EXPOSURE)
            img = np.round(np.clip(img / max(float(np.percentile(img[inside], 99.9)), 1e-6) * 0.9, 0, 1)
                           * 65535) / 65535
            crop_ = SphereCrop(img, True)
            yield f"{mat.name} ({getattr(mat, 'kind', '')})", i, crop_


def main() -> int:
    from specgen_addon.generate.pipeline import NETWORK_BAND_GAP_NM
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.photo_lighting import InputLighting
    from specgen_addon.photo.sphere_image import SphereCrop
    from specgen_addon.render import sphere_geometry
    from specgen_addon.render.photo_reproduction import photo_scale, rgb_psnr

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", type=int, nargs="+", default=list(range(12)))
    ap.add_argument("--synthetic", type=int, default=0, help="N training-split corpus materials instead")
    ap.add_argument("--split", choices=["train", "val"], default="train", help="the corpus split of --synthetic")
    ap.add_argument("--save", type=Path, default=None,
                    help="a folder for each row's photo, refined render and observed pixels (.npz)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.save:
        args.save.mkdir(parents=True, exist_ok=True)
    lights = load_lights(DATA / "lights.txt")
    geo = sphere_geometry(SIZE)
    out = open(args.json, "w") if args.json else None
    cases = ([(f"gray.{i}", i, crop("gray", i)) for i in args.inputs] if not args.synthetic
             else synthetic_cases(args.synthetic, lights, args.split))
    for name, i, c in cases:
        photo = c.image.astype(np.float64)
        mask = geo.mask & (photo.max(-1) < CLIP_LEVEL) & (photo.max(-1) > 0)
        rows_b = photo[mask]
        s = photo_scale(rows_b)
        basis = sh9(geo.normals[mask])
        coef, *_ = np.linalg.lstsq(basis, rows_b, rcond=None)
        sh_db = rgb_psnr(rows_b, basis @ coef, s)
        mirrored = lights[i] * np.array([-1.0, 1.0, 1.0])
        for kind, lighting in (("file", file_lighting(lights[i])), ("studio", InputLighting()),
                               ("other", file_lighting(lights[(i + 6) % 12])),
                               ("mirrored", file_lighting(mirrored))):
            start = generate_brdf(SphereCrop(photo * lighting.network_gain(), c.copied), band_gap_nm=NETWORK_BAND_GAP_NM)
            res = refine_brdf(start, photo, lighting, RefineOptions(clip_level=CLIP_LEVEL, exclude=c.saturated))
            lam = white_render(lighting) * lambertian_albedo(photo, mask, lighting)
            row = {"photo": name, "input": i, "light": kind, "any_light_db": getattr(res, "any_light_db", None),
                   "product_bright_share": getattr(res, "bright_share", None),
                   "warned": any("does not explain" in w for w in res.warnings), "refined_db": round(res.after.psnr_db, 2),
                   "network_db": round(res.before.psnr_db, 2),
                   "lambert_given_db": round(rgb_psnr(rows_b, lam[mask], s), 2), "sh9_lambert_db": round(sh_db, 2)}
            row.update(residual_figures(photo, res.rendered, mask, s))
            if args.save:
                np.savez_compressed(args.save / f"{name.split()[0]}_{i}_{kind}.npz", photo=photo.astype(np.float32),
                                    rendered=res.rendered.astype(np.float32), mask=mask)
            print(json.dumps(row), flush=True)
            if out:
                out.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
