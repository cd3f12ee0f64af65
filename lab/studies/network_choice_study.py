"""Which shipped network for which photo: the cut's choice against the photo's self-reproduction.

A sphere cut from a photo goes to one of two shipped networks by how it was cut
(:func:`specgen_addon.model.shipped_weights`: copied from a canonical frame → the default network,
resampled → the resampled-input network). For N validation materials per family, two photos that
share no samples with the refinement's operator (``independent``: exactly framed; ``shifted``: half a
pixel off, so resampled) go through both networks. Each table is scored against the truth under the
protocol's distant lights (spectral PSNR, network alone) and by its self-reproduction: its render under
the input lighting against the photo (RGB PSNR over the refinement's observed pixels, clipped at 1 like
an 8-bit photo, no blur model). The summary compares three choices: by the cut (shipped), by
self-reproduction, and always one network.

    cd bench && python network_choice_study.py --skip 12 --json ../out/choice_12.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


NETWORKS = ("default", "resampled")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("val", "test"), default="val", help="corpus split (default val)")
    ap.add_argument("--per-family", type=int, default=1, help="materials per family (default 1)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first K materials of each family")
    ap.add_argument("--resolution", type=int, default=128, help="truth render size in pixels (default 128)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    a = ap.parse_args(argv)
    if not 1 <= a.per_family <= 20 or a.skip < 0 or not 16 <= a.resolution <= 512:
        ap.error("--per-family must be in 1..20, --skip ≥ 0 and --resolution in 16..512")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.sphere_image import SphereCrop
    from specgen_addon.photo.photo_lighting import InputLighting
    from specgen_addon.model import DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS
    from specgen_addon.generate.pipeline import load_photo_crop
    from specgen_addon.generate.refine import render_under
    from specgen_addon.generate.refine.operator import PhotoOperator
    from specgen_addon.render.photo_reproduction import reproduction
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_split_materials

    weights = {"default": DEFAULT_WEIGHTS, "resampled": RESAMPLED_WEIGHTS}
    light = InputLighting()
    rows = []
    for mat in mixed_split_materials(a.per_family, None, a.split, skip=a.skip):
        fam = material_family(mat)
        score = truth_scorer(mat, a.resolution)
        independent = independent_photo(mat)
        for kind, image in (("independent", independent), ("shifted", displaced_input(independent, 0.5))):
            crop, linear = load_photo_crop(image)
            photo = crop.image.astype(np.float64)
            scene = light.scene(photo.shape[0])
            op = PhotoOperator(scene, WAVELENGTHS_NM, light.image_exposure)
            observed = op.observe(photo)
            row = {"material": mat.name, "family": fam, "photo": kind, "copied": bool(crop.copied)}
            for label in NETWORKS:
                t0 = time.perf_counter()
                table = generate_brdf(SphereCrop(photo * light.network_gain(), crop.copied),
                                      weights=weights[label], wavelengths_nm=WAVELENGTHS_NM)
                img = render_under(table, scene, light.image_exposure)
                rep = reproduction(observed, op.observe(img if linear else np.minimum(img, 1.0)))
                row[label] = {"truth_db": score(table),
                              "self_db": rep.psnr_db, "self_de": rep.delta_e2000,
                              "seconds": time.perf_counter() - t0}
            rows.append(row)
            print(f"{mat.name:8} {fam:11} {kind:11} cut: {'copied' if row['copied'] else 'resampled':9} | "
                  + " | ".join(f"{n} {row[n]['truth_db']:6.2f} (self {row[n]['self_db']:.1f})" for n in NETWORKS),
                  flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    if not rows:
        print("no materials left after --skip", file=sys.stderr)
        return 2
    by_cut = np.array([r["default" if r["copied"] else "resampled"]["truth_db"] for r in rows])
    by_self = np.array([max((r[n] for n in NETWORKS), key=lambda s: s["self_db"])["truth_db"] for r in rows])
    print(f"{len(rows)} photos, network alone, truth dB: by the cut (shipped) {by_cut.mean():.2f}; "
          f"by self-reproduction {by_self.mean():.2f} (worst photo {np.min(by_self - by_cut):+.2f}); "
          + "; ".join(f"always {n} {np.mean([r[n]['truth_db'] for r in rows]):.2f}" for n in NETWORKS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
