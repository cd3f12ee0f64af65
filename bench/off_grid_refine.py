"""Network alone and refined, on inputs framed exactly and moved off the pixel grid.

For each of N held-out materials per family (the mixed corpus's test split), the canonical input
is scored as it is and moved by ``--shift`` pixels inside a black border
(:func:`specgen_addon.evaluation.trained_network.displaced_input`, as ``evaluate --input-shift``). Each version
goes through the user's pipeline: the sphere is found and cropped, the network runs, and refinement
(the default) fits the photo. The table is rendered under the protocol's distant lights and
compared with the truth (spectral PSNR, as ``evaluate --families``).

With ``--independent``, a third input: the exactly framed photo rendered with other environment
samples (sampling seed 1, twice the directions) than the refinement's own operator uses. The
canonical input shares the operator's samples, so its refined figure is a best case ("inverse
crime"); this one is not.

    cd bench && python off_grid_refine.py --per-family 1 --shift 0.5 --independent
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np



def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1, help="held-out materials per family (default 1)")
    ap.add_argument("--shift", type=float, default=0.5, help="pixels off the grid (default 0.5)")
    ap.add_argument("--weights", type=Path, default=None,
                    help="weights (.pt); default: the shipped networks, chosen by how the sphere was cut")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    ap.add_argument("--independent", action="store_true",
                    help="also score the exact photo rendered with other environment samples")
    a = ap.parse_args(argv)
    if a.per_family < 1 or not (np.isfinite(a.shift) and abs(a.shift) <= 8):
        ap.error("--per-family must be ≥ 1 and --shift a number of pixels in [-8, 8]")

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.generate.pipeline import generate
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_test_materials

    geo = sphere_geometry(64)
    rows = []
    print(f"{'material':10} {'family':12} {'framing':9} {'network':>8} {'refined':>8}  (dB, distant lights)"
          "   self-reproduction of the photo: network → refined (dB, ΔE2000)")
    for mat in mixed_test_materials(a.per_family):
        gt = render_spectral(mat, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral
        canonical = input_image.render_input(mat)
        inputs = [("exact", canonical), (f"+{a.shift:g} px", displaced_input(canonical, a.shift))]
        if a.independent:
            inputs.append(("exact, other samples", independent_photo(mat)))
        for label, image in inputs:
            row = {"material": mat.name, "family": material_family(mat), "framing": label}
            for arm, refine in (("network", False), ("refined", True)):
                generated = generate(image, refine=refine, weights=a.weights, wavelengths_nm=WAVELENGTHS_NM)
                table = generated.table
                pred = render_spectral(table, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral
                row[arm] = float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean)
                row[f"{arm}_weights"] = Path(table.metadata.get("weights", "")).name
                if generated.refinement is not None:  # the refinement scores both tables against the photo
                    for when, rep in (("network", generated.refinement.before),
                                      ("refined", generated.refinement.after)):
                        row[f"self_psnr_{when}"], row[f"self_de2000_{when}"] = rep.psnr_db, rep.delta_e2000
            rows.append(row)
            de = [row.get(f"self_de2000_{w}") for w in ("network", "refined")]
            de_text = "" if None in de else f", ΔE {de[0]:.2f} → {de[1]:.2f}"
            print(f"{row['material']:10} {row['family']:12} {label:9} {row['network']:8.2f} "
                  f"{row['refined']:8.2f}   {row['self_psnr_network']:.1f} → {row['self_psnr_refined']:.1f} dB"
                  f"{de_text}  [{row['network_weights']}]",
                  flush=True)
    for label in dict.fromkeys(r["framing"] for r in rows):
        sel = [r for r in rows if r["framing"] == label]
        print(f"mean {label} ({len(sel)} materials): network {np.mean([r['network'] for r in sel]):.2f}, "
              f"refined {np.mean([r['refined'] for r in sel]):.2f} dB; self-reproduction network "
              f"{np.mean([r['self_psnr_network'] for r in sel]):.2f} → refined "
              f"{np.mean([r['self_psnr_refined'] for r in sel]):.2f} dB")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


def independent_photo(material, sampling=None) -> np.ndarray:
    """The canonical photo of ``material`` rendered with other environment samples than the
    refinement's operator: ``sampling``, by default
    :func:`specgen_addon.photo.sphere_image.independent_sampling` (seed 1, twice the input renders'
    directions)."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.photo.photo_lighting import InputLighting

    if sampling is None:
        return input_image.render_independent_input(material)
    scene = InputLighting().scene().with_sampling(sampling)
    return input_image.photo_in_scene(material, scene, input_image.EXPOSURE)


def truth_scorer(material, resolution: int = 64):
    """The protocol's score of a predicted table against ``material``: spectral PSNR (dB, mean
    over the 20 bands) over a ``resolution``² sphere under the distant lights, the truth rendered
    once. Returns ``score(table) -> float``."""
    from specgen_addon.render import metrics
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.render import render_spectral, sphere_geometry

    geo = sphere_geometry(resolution)
    gt = render_spectral(material, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral

    def score(table) -> float:
        pred = render_spectral(table, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral
        return float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean)

    return score


if __name__ == "__main__":
    raise SystemExit(main())
