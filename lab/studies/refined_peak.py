"""Where a refined table misses the truth most, scored at two render sizes (paper-tables protocol).

A refined lobe whose peak is narrower than a pixel can be wrong by a factor where no pixel of a
64² render lands on it and show at 128², where one does. For one of paper-tables' test materials
(``protocol.test_materials``), the network's and the refined table (refined against the photo that
shares no samples with the operator, ``input_image.render_independent_input``) are rendered under
the protocol's distant lights at each size; the spectral PSNR and the worst pixel are printed.

    cd bench && python refined_peak.py mat0004
"""

from __future__ import annotations

import argparse

import numpy as np



def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("material", help="a paper-tables test material, e.g. mat0004")
    ap.add_argument("--sizes", type=int, nargs="+", default=[64, 128], help="render sizes (default 64 128)")
    a = ap.parse_args(argv)
    from specgen_addon.model.runtime import inference as infer
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.evaluation import protocol
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.generate.refine import RefineOptions, refine_brdf
    from specgen_addon.render import render_spectral, sphere_geometry

    mats = [m for m in protocol.test_materials(10) if m.name == a.material]
    if not mats:
        ap.error(f"{a.material} is not one of the first ten test materials")
    mat = mats[0]
    photo = input_image.render_independent_input(mat)
    table = infer.generate_brdf(photo, wavelengths_nm=WAVELENGTHS_NM)
    refined = refine_brdf(table, photo.astype(np.float64), None, RefineOptions(clip_level=None)).table
    for size in a.sizes:
        geo = sphere_geometry(size)
        gt = render_spectral(mat, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral
        peak = float(np.percentile(gt[geo.mask], 99.9))
        for label, brdf in (("network", table), ("refined", refined)):
            pred = render_spectral(brdf, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS).spectral
            psnr = metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean
            err = ((pred - gt) ** 2).mean(-1) * geo.mask
            iy, ix = np.unravel_index(int(np.argmax(err)), err.shape)
            print(f"{size}² {label:8} {psnr:6.2f} dB; worst pixel (row {iy}, col {ix}): truth "
                  f"{gt[iy, ix].mean():.2f}, prediction {pred[iy, ix].mean():.2f} (99.9th percentile {peak:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
