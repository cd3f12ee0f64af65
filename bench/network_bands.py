"""What Generate's band gap costs: the network at every band against bands 40 nm apart, the others
interpolated in λ.

    .venv/bin/python bench/network_bands.py [--backend onnx] [--limit N]

For the shipped example photo and the canonical input photo of each real RGL file in
../shared/data/rgl (as ``evaluate`` renders it), the network's table at the 21 default bands
(380–780 nm) is generated twice: every band evaluated, and only the bands
:func:`specgen_addon.model.runtime.inference.network_bands` keeps at
:data:`specgen_addon.generate.pipeline.NETWORK_BAND_GAP_NM` (the others filled by
:func:`~specgen_addon.model.runtime.inference.fill_bands`). Prints per input the network's wall
seconds both ways, the relative rms difference of the two tables (f_r, every grid node and band),
the PSNR of the gapped table's render against the full one's (a sphere under the protocol's distant
lights, 21-band spectral render projected to linear sRGB), and both tables' PSNR against the
truth in that scene (what the gap does to accuracy, in dB): for a real file its measurement (RGB);
for the first ``--synthetic`` materials of the synthetic test split their own spectral BRDF
(per-band PSNR of the 21-band spectral images, the protocol's measure).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
from machine import describe_machine  # bench/machine.py, beside this script

RGL = REPO.parent / "shared" / "data" / "rgl"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", choices=("onnx", "torch"), default="onnx",
                    help="the network's backend (default onnx: what the panel runs)")
    ap.add_argument("--limit", type=int, default=None, help="only the first N real files")
    ap.add_argument("--synthetic", type=int, default=8, help="synthetic test materials (default 8)")
    args = ap.parse_args()

    from specgen_addon.common.cache import cache_root
    from specgen_addon.corpus import generate_corpus
    from specgen_addon.evaluation.protocol import CORPUS_SEED, CORPUS_SIZE, DISTANT_LIGHTS
    from specgen_addon.evaluation.real_files import score_table
    from specgen_addon.generate.pipeline import NETWORK_BAND_GAP_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.sphere_image import render_input
    from specgen_addon.render import metrics, render_spectral, sphere_geometry
    from specgen_addon.spectral.spectra import wavelength_grid
    from specgen_addon.train.real_rgb import canonical_photo

    wl = wavelength_grid(380.0, 780.0, 21)
    geo = sphere_geometry(64)
    inputs: list[tuple[str, object, object]] = [("example photo", str(REPO / "examples" / "sphere.png"), None)]
    if RGL.is_dir():
        files = sorted(RGL.glob("*.bsdf"))[:args.limit]
        inputs += [(f.stem, canonical_photo(f, cache_root() / "train-data", log=lambda _m: None), f) for f in files]
    else:
        print(f"(no real files: {RGL} is absent)")
    test = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == "test"][:args.synthetic]
    inputs += [(f"synthetic {m.name}", render_input(m), m) for m in test]

    print(describe_machine())
    print(f"backend {args.backend}; 21 bands; the network at bands ≤ {NETWORK_BAND_GAP_NM:g} nm apart")
    generate_brdf(inputs[0][1], wavelengths_nm=wl, backend=args.backend)      # warm-up: sessions load
    print(f"{'input':28s} {'every s':>8s} {'gap s':>6s} {'rel rms':>8s} {'render dB':>9s} "
          f"{'vs file: every':>14s} {'gap':>6s}")
    rows = []
    for name, image, truth in inputs:
        t0 = time.perf_counter()
        full = generate_brdf(image, wavelengths_nm=wl, backend=args.backend)
        t1 = time.perf_counter()
        gapped = generate_brdf(image, wavelengths_nm=wl, backend=args.backend, band_gap_nm=NETWORK_BAND_GAP_NM)
        t2 = time.perf_counter()
        diff = gapped.values - full.values
        rel = float(np.sqrt(np.mean(diff ** 2) / np.mean(full.values ** 2)))
        renders = [render_spectral(t, geo, wavelengths_nm=wl, lights=DISTANT_LIGHTS).rgb for t in (full, gapped)]
        render_db = float(metrics.spectral_metrics(renders[0], renders[1], geo.mask).psnr_mean)
        vs = ["", ""]
        if isinstance(truth, Path):                                           # a measured file: RGB
            scene = [("distant", {"lights": DISTANT_LIGHTS})]
            vs = [f"{score_table(truth, t, 64, scene)['psnr_distant']:.2f}" for t in (full, gapped)]
        elif truth is not None:                                               # a spectral BRDF: per band
            gt = render_spectral(truth, geo, wavelengths_nm=wl, lights=DISTANT_LIGHTS).spectral
            vs = [f"{metrics.spectral_metrics(gt, render_spectral(t, geo, wavelengths_nm=wl, lights=DISTANT_LIGHTS).spectral, geo.mask).psnr_mean:.2f}"
                  for t in (full, gapped)]
        rows.append((t1 - t0, t2 - t1, rel, render_db, *(float(v) if v else np.nan for v in vs)))
        print(f"{name:28s} {t1 - t0:8.2f} {t2 - t1:6.2f} {100 * rel:7.3f}% {render_db:9.1f} {vs[0]:>14s} {vs[1]:>6s}",
              flush=True)
    a = np.array(rows)
    print(f"{'mean':28s} {a[:, 0].mean():8.2f} {a[:, 1].mean():6.2f} {100 * a[:, 2].mean():7.3f}% "
          f"{a[:, 3].mean():9.1f}; largest rel rms {100 * a[:, 2].max():.3f}%, lowest render {a[:, 3].min():.1f} dB")
    for label, sel in (("real files", [isinstance(t, Path) for _n, _i, t in inputs]),
                       ("synthetic", [t is not None and not isinstance(t, Path) for _n, _i, t in inputs])):
        if any(sel):
            b = a[np.array(sel)]
            print(f"{label}: against the truth {b[:, 4].mean():.2f} dB every band, {b[:, 5].mean():.2f} dB "
                  f"with the gap ({b[:, 5].mean() - b[:, 4].mean():+.2f}; {int(np.sum(b[:, 5] < b[:, 4]))} "
                  f"of {len(b)} lower)")
    print(describe_machine())
    return 0


if __name__ == "__main__":
    sys.exit(main())
