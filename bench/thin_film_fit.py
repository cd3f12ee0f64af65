"""The thin-film fit (``infer --model thin-film``) against the network, on held-out thin films.

For the first N thin-film materials of the mixed test split (the materials ``evaluate --families``
scores), each photographed under the canonical lighting, three predictions are compared with the
truth: the network alone, the network refined to the photo (the product's default) and the
thin-film family's fit to the photo. Per material:

* spectral PSNR / SSIM under the evaluation protocol's distant lights (as ``evaluate``; 64² spheres,
  20 wavelengths), so the fit's figures sit beside the network's per-family row;
* the hue (CIELAB h°, Y-normalised) of the specular direction over θd 0–80°: mean error against the
  truth, and mean ΔE2000, as ``family_checks.py``;
* the fit's self-reproduction (RGB PSNR / ΔE2000 against the photo) and the film it found.

Usage: ``.venv/bin/python bench/thin_film_fit.py [--films 8] [--weights W.pt] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from family_checks import THETA_D, _hue_error, _lab, _specular  # bench/family_checks.py
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[1]


def hue_errors(truth, brdf, wavelengths: np.ndarray) -> tuple[float, float]:
    """(mean |hue error| in degrees, mean ΔE2000) of the specular direction over θd."""
    import colour

    lab_t = _lab(_specular(truth, THETA_D, wavelengths), 0.5, wavelengths)
    lab_p = _lab(_specular(brdf, THETA_D, wavelengths), 0.5, wavelengths)
    h_t, h_p = (np.degrees(np.arctan2(x[:, 2], x[:, 1])) for x in (lab_t, lab_p))
    return float(_hue_error(h_t, h_p).mean()), float(np.mean(colour.delta_E(lab_t, lab_p, method="CIE 2000")))


def main() -> None:
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.generate.thin_film import fit_thin_film
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.generate.refine import RefineOptions, refine_brdf
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import RESOLUTION, mixed_test_materials

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--films", type=int, default=8, help="held-out thin films to score (default 8)")
    p.add_argument("--weights", type=Path, default=None, help="network weights (default: shipped)")
    p.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    args = p.parse_args()
    if args.films < 1:
        p.error("--films must be ≥ 1")
    print(f"machine: {describe_machine()}")
    print(f"weights: {args.weights or 'shipped'}")
    wl = np.asarray(WAVELENGTHS_NM, dtype=np.float64)
    geo = sphere_geometry(RESOLUTION)
    rows = []
    for m in mixed_test_materials(args.films, ["thin_film"]):
        image = input_image.render_input(m)
        network = generate_brdf(image, weights=args.weights, wavelengths_nm=wl)
        refined = refine_brdf(network, image, options=RefineOptions(clip_level=None)).table
        t0 = time.perf_counter()
        fit = fit_thin_film(image, clip_level=None)
        seconds = time.perf_counter() - t0
        gt = render_spectral(m, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
        row = {"material": m.name, "kind": m.kind, "truth": {"alpha": m.alpha, "film_eta": m.film_eta,
                                                             "thickness_nm": m.thickness_nm},
               "fitted": {"kind": fit.material.kind, "alpha": fit.material.alpha, "film_eta": fit.material.film_eta,
                       "thickness_nm": fit.material.thickness_nm, "seconds": round(seconds, 1),
                       "self_psnr_db": fit.reproduction.psnr_db, "self_delta_e2000": fit.reproduction.delta_e2000}}
        for tag, brdf, table in (("network", network, network), ("refined", refined, refined),
                                 ("fit", fit, fit.table(wl))):
            pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
            res = metrics.spectral_metrics(gt, pred, geo.mask)
            hue, de = hue_errors(m, brdf, wl)
            row[tag] = {"psnr_distant": float(res.psnr_mean), "ssim_distant": float(res.ssim_mean),
                        "hue_error_deg": hue, "delta_e2000_theta_d": de}
        rows.append(row)
        print(f"{m.name} {m.kind:24s} truth η_f {m.film_eta:.3f} d {m.thickness_nm:6.1f} α {m.alpha:.3f} | "
              f"fit {fit.material.kind} η_f {fit.material.film_eta:.3f} d {fit.material.thickness_nm:6.1f} "
              f"α {fit.material.alpha:.3f} ({seconds:.0f} s, photo {fit.reproduction.text()})")
        print("    " + "; ".join(f"{tag}: {row[tag]['psnr_distant']:.2f} dB, hue error "
                                 f"{row[tag]['hue_error_deg']:.1f}°, ΔE2000 {row[tag]['delta_e2000_theta_d']:.2f}"
                                 for tag in ("network", "refined", "fit")), flush=True)
    print(f"mean over {len(rows)} held-out thin films:")
    for tag in ("network", "refined", "fit"):
        print(f"  {tag:8s} PSNR {np.mean([r[tag]['psnr_distant'] for r in rows]):.2f} dB, "
              f"SSIM {np.mean([r[tag]['ssim_distant'] for r in rows]):.4f}, "
              f"hue error {np.mean([r[tag]['hue_error_deg'] for r in rows]):.1f}°, "
              f"ΔE2000 over θd {np.mean([r[tag]['delta_e2000_theta_d'] for r in rows]):.2f}")
    if args.json:
        args.json.write_text(json.dumps({"machine": describe_machine(), "weights": str(args.weights or "shipped"),
                                         "rows": rows}, indent=1))
        print(f"json: {args.json}")


if __name__ == "__main__":
    main()
