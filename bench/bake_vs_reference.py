"""Check: the exact-mode Cycles render of a baked table against the NumPy reference renderer.

Usage: ``python bench/bake_vs_reference.py TABLE.npz [TABLE.npz ...] [--resolution 48]``

Per table: bake it (default *Basis Tolerance*, then the complete basis, K = Λ), render a sphere
under one D65 sun in Cycles (exact mode, ``ops.render.SpectralRenderJob``) and with
``specgen_addon.render``, and print K, the per-band PSNR (every 4th band, peak = the reference's
99.9th percentile) and the mean CIEDE2000 of the sRGB projections (colour-science). The two
renderers share no code past the table, so agreement checks the bake (basis, shifted coefficients,
atlas) and the shader's lookup. Tables, e.g.: ``python -m specgen_addon infer examples/sphere.png
-o net.npz --no-refine`` and the same without ``--no-refine``.
"""

from __future__ import annotations

import argparse
import runpy
import tempfile
from importlib import import_module
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]
SUN = (0.35, 0.45, 0.82)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="+", type=Path)
    ap.add_argument("--resolution", type=int, default=48)
    args = ap.parse_args()

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry
    from specgen_addon.render.photo_reproduction import delta_e2000, photo_scale
    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
    from specgen_addon.render.spectral_exr import linear_srgb_preview
    from specgen_addon.brdf.table import BRDFTable

    pkg = batch.load_package()
    bake = import_module("specgen_addon.bake.lookup")
    render = import_module(f"{pkg.__name__}.ops.render")
    scene_mod = import_module(f"{pkg.__name__}.ops.scene")
    print(describe_machine())
    res = args.resolution
    with tempfile.TemporaryDirectory() as tmp:
        for path in args.tables:
            table = BRDFTable.load(path)
            wl = table.wavelengths
            ref = render_spectral(table, sphere_geometry(res), lights=[DistantLight(SUN, np.pi)],
                                  wavelengths_nm=wl).spectral
            mask = ref.sum(-1) > 0
            peak = np.percentile(ref[mask], 99.9)
            ref_rgb = linear_srgb_preview(ref, wl)
            for label, tol in (("default tolerance", bake.DEFAULT_TOLERANCE), ("complete basis", 0.0)):
                info = bake.bake_atlas(table, Path(tmp) / f"{path.stem}_{tol}.exr", tolerance=tol)
                sc, _ = scene_mod.new_reference_sphere_scene(lambda: render.make_material("check", info), SUN)
                got = render.SpectralRenderJob(sc, None, samples=2, resolution=(res, res)).run()
                psnr = [10 * np.log10(peak ** 2 / np.mean((got[..., b][mask] - ref[..., b][mask]) ** 2))
                        for b in range(0, wl.size, 4)]
                de = delta_e2000(ref_rgb[mask], linear_srgb_preview(got, wl)[mask], photo_scale(ref_rgb[mask]))
                print(f"{path.name}: {label}: K = {info.n_coeffs} ({info.n_renders} renders), basis error "
                      f"{info.rel_error:.1e}; band PSNR {np.round(psnr, 1).tolist()} dB; mean ΔE2000 {de:.2f}",
                      flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
