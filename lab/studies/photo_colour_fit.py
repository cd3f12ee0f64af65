"""Is the network's colour error visible in its input photo? One smooth spectral gain fitted to the photo.

`evaluate`'s oracle diagnostic fits one smooth spectral gain ``g(λ) = Σ_l c_l s_l(λ)`` (Mallett &
Yuksel's three sRGB basis reflectances) to the *truth* and finds it worth 2.65 dB over the whole test
split (docs/model.md, "The forty-fourth session"). This bench fits the same three coefficients to the
*input photo* instead, by least squares in relative error (each pixel's residual divided by its value
plus 5 % of the photo's level) over the sphere's observed pixels: the photo is linear
in the gain, ``render(g · T) = Σ_l c_l render(s_l · T)`` under the photo's own (canonical) lighting.
It then scores ``g · T`` under the protocol's distant lights beside the network's table ``T`` and the
oracle gain. A photo fit with three parameters: not network alone.

``--split train`` runs the same on training materials: a colour error that is as large there as on
the held-out split is one of fit, not of generalisation (spectra never seen).

Usage: ``.venv/bin/python bench/photo_colour_fit.py [--per-family 3] [--skip 0] [--split test] [--families ...] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py
from rows import family_groups  # bench/rows.py

REPO = Path(__file__).resolve().parents[2]


def main() -> int:
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.spectral.colour_tables import mallett2019_basis
    from specgen_addon.corpus.families import FAMILY_NAMES
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.photo_fit import observed_pixels
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.photo_lighting import parse_lighting
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.spectral.spectra import spectral_to_linear_srgb
    from specgen_addon.evaluation.trained_network import mixed_split_materials

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=3, help="test materials per family (default 3)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first N of each family (default 0)")
    ap.add_argument("--split", choices=("train", "val", "test"), default="test",
                    help="corpus split to draw from (default test, the held-out one)")
    ap.add_argument("--families", nargs="+", choices=FAMILY_NAMES, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.per_family < 1 or args.skip < 0:
        ap.error("--per-family must be ≥ 1 and --skip ≥ 0")
    if args.json is not None and not args.json.parent.is_dir():
        ap.error(f"{args.json.parent}: folder not found")

    wl = np.asarray(WAVELENGTHS_NM, np.float64)
    basis = mallett2019_basis(wl)
    lighting = parse_lighting(None)                       # the canonical input lighting
    scene = lighting.scene(input_image.CANONICAL_SIZE)
    seen = observed_pixels(scene)
    geo = sphere_geometry(128)
    rows = []
    t0 = time.perf_counter()
    for mat in mixed_split_materials(args.per_family, args.families, args.split, skip=args.skip):
        image = input_image.render_input(mat)
        photo = image.astype(np.float64).reshape(-1, 3)[seen]
        table = generate_brdf(image, wavelengths_nm=wl)
        # a render is linear in the table band by band, so render(s_l · T) = s_l · render(T): one
        # spectral render gives the photo of each basis gain
        radiance = scene.render_spectral(table, wl).spectral * lighting.image_exposure
        design = np.stack([spectral_to_linear_srgb(radiance * basis[:, l], wl).reshape(-1, 3)[seen]
                           for l in range(3)], axis=-1).reshape(-1, 3)
        # relative errors, as the latent fit's log loss weighs them: the highlight and the body count
        # alike (ε = 5 % of the photo's level)
        weight = 1.0 / (photo.reshape(-1) + 0.05 * np.percentile(photo, 99.9))
        coef, *_ = np.linalg.lstsq(design * weight[:, None], photo.reshape(-1) * weight, rcond=None)
        gain = basis @ coef
        gt = render_spectral(mat, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
        row = {"material": mat.name, "family": material_family(mat),
               "network": float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean),
               "photo_gain": metrics.mean_psnr(gt, pred * gain, geo.mask),
               "oracle_gain": metrics.colour_fitted_psnr(gt, pred, wl, geo.mask)[0],
               "gain_coefficients": coef.tolist()}
        rows.append(row)
        print(f"{mat.name} {row['family']:<12} network {row['network']:.2f}  colour from the photo "
              f"{row['photo_gain']:.2f}  from the truth (oracle) {row['oracle_gain']:.2f} dB", flush=True)

    print(f"\n{describe_machine()}; {len(rows)} {args.split} materials, {time.perf_counter() - t0:.0f} s")
    print("| family | n | network alone | colour fitted to the photo | colour fitted to the truth (oracle) | photo fit better than the network |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    summary = {}
    for fam, sel in family_groups(rows):
        s = {k: float(np.mean([r[k] for r in sel])) for k in ("network", "photo_gain", "oracle_gain")}
        s["n"], s["better"] = len(sel), sum(r["photo_gain"] > r["network"] for r in sel)
        summary[fam] = s
        print(f"| {fam} | {s['n']} | {s['network']:.2f} | {s['photo_gain']:.2f} | {s['oracle_gain']:.2f} | {s['better']} |")
    if args.json is not None:
        args.json.write_text(json.dumps({"materials": rows, "families": summary}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
