"""Make docs/img/two_networks.png: why a photo's sphere gets its own network.

    python scripts/make_resampled_figure.py [--out docs/img/two_networks.png] [--resolution 96]

For the first held-out test material of three families, the input a camera gives (area-sampled,
half a pixel off the grid: ``evaluate --input-antialias --input-shift 0.5``), the truth under the
protocol's distant lights, and the predictions of the two shipped networks from that same input:
the one for spheres copied from a canonical frame, and the one for resampled spheres, which the
pipeline picks for this input. Each caption carries the spectral PSNR against the truth (as
``evaluate --families``). Panels are sRGB, each row normalised by its truth's 99.9th percentile.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

FAMILIES = ("sheen", "lobes", "car_paint")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img" / "two_networks.png")
    ap.add_argument("--resolution", type=int, default=96, help="render size in pixels (default 96)")
    a = ap.parse_args(argv)
    if not 32 <= a.resolution <= 512:
        ap.error("--resolution must be 32–512")

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.spectral import spectra
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.plots import _plt, _save
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.model import DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import antialiased_input, mixed_test_materials

    geo = sphere_geometry(a.resolution)
    plt = _plt()
    mats = mixed_test_materials(1, list(FAMILIES))
    fig, axes = plt.subplots(len(mats), 4, figsize=(10, 2.7 * len(mats)), squeeze=False)
    titles = ["camera-like input\n(area-sampled, ½ px off)", "truth (distant lights)",
              "network for copied spheres", "network for resampled spheres\n(the pipeline's choice)"]
    for i, mat in enumerate(mats):
        family = material_family(mat).replace("_", " ")
        photo = antialiased_input(mat, 0.5)
        crop = input_image.crop_sphere(photo)
        truth = render_spectral(mat, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS)
        scale = float(np.percentile(truth.rgb[geo.mask], 99.9)) or 1.0
        panels = [(np.clip(crop.image / max(float(np.percentile(crop.image, 99.9)), 1e-6), 0, 1), ""),
                  (truth.rgb / scale, mat.name)]
        for w in (DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS):
            table = generate_brdf(photo, weights=w, wavelengths_nm=WAVELENGTHS_NM)
            pred = render_spectral(table, geo, wavelengths_nm=WAVELENGTHS_NM, lights=DISTANT_LIGHTS)
            psnr = float(metrics.spectral_metrics(truth.spectral, pred.spectral, geo.mask).psnr_mean)
            panels.append((pred.rgb / scale, f"{psnr:.1f} dB"))
            print(f"{mat.name} ({family}): {w.name} {psnr:.2f} dB", flush=True)
        for j, (img, caption) in enumerate(panels):
            ax = axes[i, j]
            ax.imshow(spectra.srgb_encode(np.clip(img, 0, 1)))
            ax.set_xticks([]), ax.set_yticks([])
            if i == 0:
                ax.set_title(titles[j], fontsize=9)
            ax.set_xlabel(caption if j != 1 else f"{mat.name} ({family})", fontsize=9)
    fig.tight_layout()
    print(_save(fig, a.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
