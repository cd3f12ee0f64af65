"""How close the network comes to the best table: each test material's own MERL-grid table, scored.

The network outputs a table on the MERL grid (90 θh × 90 θd × 180 φd, trilinear lookups), and
`evaluate --families` scores its renders against renders of the *analytic* material. Part of any
table's error is therefore the grid's: a lobe a few tenths of a degree wide falls between θh nodes.
This oracle tabulates each material's true BRDF at the grid nodes (``BRDFTable.tabulate``, the
same wavelengths) and scores it exactly as the network's table is scored: a sphere under the
protocol's two distant lights, 20 bands, spectral PSNR over the sphere, at 64² (`evaluate`'s
default) and 128² renders (docs/results.md table (g)). The network alone is scored beside it
(canonical input, the shipped weights).

Usage: ``.venv/bin/python bench/table_ceiling.py [--per-family 3] [--families lobes sheen]
[--resolutions 64 128] [--supersample 4] [--no-network] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py
from rows import family_groups  # bench/rows.py

REPO = Path(__file__).resolve().parents[2]


def main() -> int:
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.corpus.families import FAMILY_NAMES
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=3, help="test materials per family (default 3)")
    ap.add_argument("--families", nargs="+", choices=FAMILY_NAMES, default=None)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[64, 128])
    ap.add_argument("--weights", type=Path, default=None, help="weights (.pt); default: shipped")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--supersample", type=int, default=1,
                    help="render N×N samples per pixel and average them, as a camera's pixel or Cycles "
                         "integrates its area (default 1: one sample at the pixel centre, evaluate's protocol)")
    ap.add_argument("--no-network", action="store_true",
                    help="score the materials' own tables only (the network's figures come from evaluate)")
    args = ap.parse_args()
    if args.per_family < 1 or any(not 16 <= r <= 512 for r in args.resolutions):
        ap.error("--per-family must be ≥ 1 and every resolution 16–512")
    if not 1 <= args.supersample <= 8:
        ap.error("--supersample must be 1–8")
    if args.weights is not None and not args.weights.is_file():
        ap.error(f"{args.weights}: weights file not found")

    n = args.supersample
    geos = {r: sphere_geometry(r * n) for r in args.resolutions}
    masks = {r: sphere_geometry(r).mask for r in args.resolutions}

    def render(brdf, r: int) -> np.ndarray:
        """The sphere under the protocol's lights at r², each pixel the mean of its n×n samples."""
        img = render_spectral(brdf, geos[r], lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        return img.reshape(r, n, r, n, -1).mean(axis=(1, 3)) if n > 1 else img

    labels = ["table"] if args.no_network else ["table", "network"]
    names = {"table": "own table", "network": "network"}
    rows = []
    t0 = time.perf_counter()
    for mat in mixed_test_materials(args.per_family, args.families):
        def true_f(th, td, pd, mat=mat):
            wi, wo = io_from_half_diff(th, td, pd)
            return mat.eval(wi, wo, WAVELENGTHS_NM)

        own = BRDFTable.tabulate(true_f, WAVELENGTHS_NM)
        tables = {"table": own}
        if "network" in labels:
            tables["network"] = generate_brdf(input_image.render_input(mat), weights=args.weights,
                                              wavelengths_nm=WAVELENGTHS_NM)
        row = {"material": mat.name, "family": material_family(mat)}
        for r in args.resolutions:
            gt = render(mat, r)
            for label, table in tables.items():
                row[f"{label}_{r}"] = float(metrics.spectral_metrics(gt, render(table, r), masks[r]).psnr_mean)
        rows.append(row)
        print(f"{mat.name} {row['family']:<12} " + "  ".join(
            f"{r}²: " + ", ".join(f"{names[label]} {row[f'{label}_{r}']:.2f} dB" for label in labels)
            for r in args.resolutions), flush=True)

    print(f"\n{describe_machine()}; {len(rows)} test materials, {n}×{n} samples per pixel, "
          f"{time.perf_counter() - t0:.0f} s")
    header = " | ".join(f"{names[label]} {r}²" for r in args.resolutions for label in labels)
    print(f"| family | n | {header} |")
    print("| --- | ---: |" + " ---: |" * (len(labels) * len(args.resolutions)))
    summary = {}
    for fam, sel in family_groups(rows, total="mean"):
        summary[fam] = {k: float(np.mean([r[k] for r in sel])) for k in sel[0] if k not in ("material", "family")}
        cells = " | ".join(f"{summary[fam][f'{label}_{r}']:.2f}" for r in args.resolutions for label in labels)
        print(f"| {fam} | {len(sel)} | {cells} |")
    if args.json is not None:
        args.json.write_text(json.dumps({"materials": rows, "families": summary}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
