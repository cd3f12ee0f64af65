"""How well the native closure stack (Lambert + GGX lobes) fits spectral BRDF tables, with a
lobe roughness shared by all bands and with per-band roughness r_l(λ) (specgen_addon.bake.closure_fit.closures).

Per material: the fit error (relative RMS of ``f cos θi cos θo``, worst band), the seconds the fit
takes, how many lobes vary per band, and a sphere under a sun, fit vs table, with the numpy
reference renderer (spectral PSNR, mean over bands, for two sun directions). Materials: corpus
``mat0000``–``mat0005`` (``generate_corpus(6, 0)``), a few of the mixed-family corpus
(``generate_mixed_corpus(12, 0)``: thin films, car paints, GTR lobes, sheen, tinted coat), and an
analytic Lambert + GGX table whose roughness grows 0.15 → 0.5 over 400–700 nm.

Usage: ``.venv/bin/python bench/closure_fit.py [--resolution 96] [--classic 6] [--mixed 0 1 3 4 6 8 11]``
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from machine import describe_machine  # bench/machine.py, beside this script


from specgen_addon.render import metrics  # noqa: E402
from specgen_addon.spectral import spectra  # noqa: E402
from specgen_addon.corpus import generate_corpus  # noqa: E402
from specgen_addon.corpus.generate import generate_mixed_corpus  # noqa: E402
from specgen_addon.bake.closure_fit import fit_closures, ggx_lobe  # noqa: E402
from specgen_addon.render import DistantLight, render_spectral, sphere_geometry  # noqa: E402
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402

WL = spectra.DEFAULT_WAVELENGTHS_NM
SUNS = [(0.3, 0.4, 1.0), (1.0, 0.2, 0.35)]  # near the camera, and grazing from the side


class _FitBRDF:
    """A :class:`~specgen_addon.bake.closure_fit.ClosureFit` as the renderer's spectral BRDF."""

    def __init__(self, fit):
        self.fit = fit

    def eval(self, wi, wo, wavelengths_nm):
        return self.fit.eval(wi, wo)


def per_band_lobe_table() -> BRDFTable:
    rough = np.geomspace(0.15, 0.5, WL.size)
    rho, spec = np.interp(WL, [400, 700], [0.1, 0.5]), np.interp(WL, [400, 700], [0.8, 0.3])

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * rho / np.pi + np.stack([ggx_lobe(wi, wo, r) for r in rough], -1) * spec
    return BRDFTable.tabulate(fn, WL)


def sphere_psnr(table: BRDFTable, fit, resolution: int) -> list[float]:
    geo = sphere_geometry(resolution)
    out = []
    for sun in SUNS:
        light = [DistantLight(sun)]
        gt = render_spectral(table, geo, lights=light, wavelengths_nm=WL).spectral
        pred = render_spectral(_FitBRDF(fit), geo, lights=light, wavelengths_nm=WL).spectral
        out.append(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=96, help="sphere image size (pixels)")
    ap.add_argument("--classic", type=int, default=6, help="corpus materials mat0000… to fit")
    ap.add_argument("--mixed", type=int, nargs="*", default=[0, 1, 3, 4, 6, 8, 11],
                    help="indices into generate_mixed_corpus(12, 0)")
    args = ap.parse_args(argv)
    print(f"machine: {describe_machine()}")
    materials = [(m.name, m.kind, m.tabulate) for m in generate_corpus(args.classic, 0)]
    mixed = generate_mixed_corpus(max(args.mixed, default=0) + 1, 0)
    materials += [(f"mixed #{i}", mixed[i].kind, mixed[i].tabulate) for i in args.mixed]
    materials.append(("analytic", "GGX, r 0.15→0.5 over λ", per_band_lobe_table))
    print(f"\n{WL.size} bands, sphere {args.resolution}², suns {SUNS}, PSNR = mean over bands\n")
    print("| material | kind | shared r: fit error | s | sphere dB | per-band r: fit error | s | "
          "lobes per band | sphere dB |")
    print("|---|---|---:|---:|---|---:|---:|---:|---|")
    for name, kind, tabulate in materials:
        table = tabulate()
        row = [name, kind]
        for per_band in (False, True):
            t0 = time.perf_counter()
            fit = fit_closures(table, per_band=per_band)
            seconds = time.perf_counter() - t0
            db = sphere_psnr(table, fit, args.resolution)
            row += [f"{100 * fit.max_error:.2f} %", f"{seconds:.1f}"]
            if per_band:
                row.append(f"{int(fit.per_band_lobes.sum())}/{len(fit.per_band_lobes)}")
            row.append("–".join(f"{v:.1f}" for v in sorted(db)))
        print("| " + " | ".join(row) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
