"""The canonical re-render on synthetic materials photographed under a map: does it cost them?

Test materials of the mixed corpus (``--per-family`` of each family), each photographed under a
held-out map plus the canonical key light (:func:`specgen_addon.evaluation.protocol.input_under_environment`,
as the robustness table does), given to the network two ways: photo × ``network_gain`` (before
2026-12-07) and the canonical re-render (:mod:`specgen_addon.generate.canonical_input`); each table
scored against the truth under the protocol's distant lights (spectral PSNR, 64², network alone).

Usage: ``.venv/bin/python lab/studies/canonical_input_synthetic.py [--per-family 1] [--env courtyard]``
(notes: lab/notebook/real-photos-network.md).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv=None) -> int:
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import (
        DISTANT_LIGHTS,
        WAVELENGTHS_NM,
        input_lighting_under,
        input_under_environment,
    )
    from specgen_addon.evaluation.trained_network import mixed_test_materials
    from specgen_addon.generate.canonical_input import network_crop
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.sphere_image import SphereCrop
    from specgen_addon.render import Scene, metrics, sphere_geometry

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-family", type=int, default=1)
    ap.add_argument("--env", default="courtyard")
    args = ap.parse_args(argv)
    geo = sphere_geometry(64)
    scene = Scene(geo, DISTANT_LIGHTS)
    lighting = input_lighting_under(args.env)
    rows = []
    for m in mixed_test_materials(args.per_family):
        photo = input_under_environment(m, args.env).astype(np.float64)
        crop = SphereCrop(photo.astype(np.float32), True)
        gt = scene.render_spectral(m, WAVELENGTHS_NM).spectral
        row = {"material": m.name, "family": material_family(m)}
        for how, given in (("photo", SphereCrop(photo * lighting.network_gain(), True)),
                           ("re-render", network_crop(crop, photo, lighting)[0])):
            table = generate_brdf(given)
            pred = scene.render_spectral(table, WAVELENGTHS_NM).spectral
            row[how] = round(float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean), 2)
        print(json.dumps(row), flush=True)
        rows.append(row)
    for how in ("photo", "re-render"):
        print(how, round(float(np.mean([r[how] for r in rows])), 2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
