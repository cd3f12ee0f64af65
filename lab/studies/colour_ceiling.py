"""What metamerism costs the spectral PSNR: each test material against its colour twin, scored.

The test split holds out whole spectra, and SpecGen sees only an RGB photo. A method
that got every colour right but guessed each spectrum from its colour would render the material's
colour twin (``specgen_addon.corpus.colour_twin``: every reflectance replaced by the Otsu 2018
spectrum of its own colour; metals kept). This bench
renders each test material and its twin exactly as ``evaluate --families`` scores the network (a
sphere under the protocol's two distant lights, 20 bands, spectral PSNR over the sphere) and prints
the twin's PSNR per family (a twin identical in render counts as 100 dB). With ``--network A.json [B.json]`` (``evaluate --families … --json``
files) it puts the network's PSNR of the same materials beside it.

Usage: ``.venv/bin/python bench/colour_ceiling.py [--per-family 3] [--families sheen classic]
[--resolution 128] [--network out/a.json out/b.json] [--json out.json]``
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


#: A twin that renders exactly as its material (nothing held out to lose) scores infinite PSNR; means
#: use this value instead.
PSNR_CAP_DB = 100.0


def network_rows(paths: list[Path]) -> dict[str, float]:
    """Material → the network's distant-light PSNR from ``evaluate --families … --json`` files."""
    out = {}
    for p in paths:
        for r in json.loads(p.read_text())["by_family"]["materials"]:
            out[r["material"]] = float(r["psnr_distant"])
    return out


def main() -> int:
    from specgen_addon.render import metrics
    from specgen_addon.corpus.colour_twin import colour_twin
    from specgen_addon.corpus.families import FAMILY_NAMES
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=3, help="test materials per family (default 3)")
    ap.add_argument("--families", nargs="+", choices=FAMILY_NAMES, default=None)
    ap.add_argument("--resolution", type=int, default=128, help="sphere size in px (default 128)")
    ap.add_argument("--network", type=Path, nargs="+", default=[],
                    help="evaluate --families JSON files whose network PSNRs to put beside the twin's")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.per_family < 1 or not 16 <= args.resolution <= 512:
        ap.error("--per-family must be ≥ 1 and --resolution 16–512")
    for p in args.network:
        if not p.is_file():
            ap.error(f"{p}: file not found")
    if args.json is not None and not args.json.parent.is_dir():
        ap.error(f"{args.json.parent}: folder not found")
    network = network_rows(args.network)

    geometry = sphere_geometry(args.resolution)

    def render(brdf) -> np.ndarray:
        return render_spectral(brdf, geometry, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral

    rows = []
    t0 = time.perf_counter()
    for mat in mixed_test_materials(args.per_family, args.families):
        twin = colour_twin(mat)
        psnr = float(metrics.spectral_metrics(render(mat), render(twin), geometry.mask).psnr_mean)
        row = {"material": mat.name, "family": material_family(mat), "twin": min(psnr, PSNR_CAP_DB)}
        if mat.name in network:
            row["network"] = network[mat.name]
        rows.append(row)
        print(f"{mat.name} {row['family']:<12} twin {row['twin']:.2f} dB"
              + (f", network {row['network']:.2f} dB" if "network" in row else ""), flush=True)

    paired = all("network" in r for r in rows)
    print(f"\n{describe_machine()}; {len(rows)} test materials, {args.resolution}², "
          f"{time.perf_counter() - t0:.0f} s")
    print("| family | n | colour twin (mean / median) | twins under 38 dB |"
          + (" network | network above its twin |" if paired else ""))
    print("| --- | ---: | ---: | ---: |" + (" ---: | ---: |" if paired else ""))
    summary = {}
    for fam, sel in family_groups(rows):
        twin = np.array([r["twin"] for r in sel])
        s = {"n": len(sel), "twin_mean": float(twin.mean()), "twin_median": float(np.median(twin)),
             "twin_under_38": int((twin < 38.0).sum())}
        cells = f"{s['twin_mean']:.2f} / {s['twin_median']:.2f} | {s['twin_under_38']}"
        if paired:
            net = np.array([r["network"] for r in sel])
            s.update(network_mean=float(net.mean()), network_above_twin=int((net > twin).sum()))
            cells += f" | {s['network_mean']:.2f} | {s['network_above_twin']}"
        summary[fam] = s
        print(f"| {fam} | {len(sel)} | {cells} |")
    if args.json is not None:
        args.json.write_text(json.dumps({"materials": rows, "families": summary, "resolution": args.resolution},
                                        indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
