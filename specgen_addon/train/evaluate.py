"""``evaluate``: SpecGen on the corpus' held-out test split (paper §4.1 protocol, distant lights).

For each test material: render its canonical sphere input image, generate the spectral BRDF
from it, and render the sphere from the predicted table and from the true analytic BRDF under
the protocol's distant lights at its 20 wavelengths (:mod:`specgen_addon.evaluation.protocol`).
PSNR/SSIM come from :mod:`specgen_addon.metrics` (one normalisation used project-wide).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

RESOLUTION = 128


def evaluate_test_split(weights: str | Path | None = None, limit: int | None = None,
                        backend: str = "torch", resolution: int = RESOLUTION,
                        progress: Callable[[float], None] | None = None) -> dict[str, Any]:
    """Per-material and mean PSNR (dB) / SSIM over the test split; returns a JSON-able dict."""
    from .. import input_image, metrics
    from ..corpus import generate_corpus
    from ..evaluation.protocol import CORPUS_SEED, CORPUS_SIZE, DISTANT_LIGHTS, WAVELENGTHS_NM
    from ..infer import generate_brdf
    from ..render import render_spectral, sphere_geometry

    test = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == "test"]
    if limit is not None:
        test = test[:limit]
    geo = sphere_geometry(resolution)
    rows = []
    t_infer = []
    for i, mat in enumerate(test):
        image = input_image.render_input(mat)
        t0 = time.perf_counter()
        table = generate_brdf(image, weights=weights, wavelengths_nm=WAVELENGTHS_NM, backend=backend)
        t_infer.append(time.perf_counter() - t0)
        gt = render_spectral(mat, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        res = metrics.spectral_metrics(gt, pred, geo.mask)
        rows.append({"material": mat.name, "kind": mat.kind, "psnr": float(res.psnr_mean),
                     "ssim": float(res.ssim_mean)})
        if progress is not None:
            progress((i + 1) / len(test))
    psnr = np.array([r["psnr"] for r in rows])
    ssim = np.array([r["ssim"] for r in rows])
    return {"materials": rows, "psnr_mean": float(psnr.mean()), "ssim_mean": float(ssim.mean()),
            "psnr_median": float(np.median(psnr)), "n": len(rows),
            "wavelengths_nm": [float(w) for w in WAVELENGTHS_NM], "resolution": resolution,
            "weights": str(weights) if weights else "default", "backend": backend,
            "mean_infer_seconds": float(np.mean(t_infer)) if t_infer else None,
            "metrics": getattr(metrics, "NORMALISATION_TEXT", "")}


def format_results(res: dict[str, Any]) -> str:
    """A plain table: material, kind, PSNR, SSIM, then the means."""
    lines = [f"{'material':<12} {'kind':<20} {'PSNR dB':>8} {'SSIM':>7}"]
    for r in res["materials"]:
        lines.append(f"{r['material']:<12} {r['kind']:<20} {r['psnr']:8.2f} {r['ssim']:7.4f}")
    lines.append(f"{'mean':<12} {'':<20} {res['psnr_mean']:8.2f} {res['ssim_mean']:7.4f}   "
                 f"({res['n']} test materials, {len(res['wavelengths_nm'])} bands, distant lights)")
    return "\n".join(lines)
