"""The compact material file against the full table: size on disk, write and rebuild seconds, and
the rendered difference (spectral PSNR, dB) under the protocol's two distant lights and the
``courtyard`` map, on a 128² sphere.

Targets: ≤ 10 MB per material, rebuilt (read) in ≤ 3 s, rendering within 60 dB of the full table.

Usage: ``.venv/bin/python bench/material_file.py [TABLE.npz ...]``. Without tables it makes them:
the network's refined table of examples/sphere.png (21 bands) and the first three real RGL files
of ../shared/data/rgl tabulated onto the MERL grid (RGB).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]

from specgen_addon.render import metrics
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, load_environment
from specgen_addon.render import Scene, sphere_geometry
from specgen_addon.brdf.table import BRDFTable


def _tables(tmp: Path) -> list[tuple[str, BRDFTable]]:
    from specgen_addon.brdf.formats.rgl import read_rgl, tabulate_rgl
    from specgen_addon.generate.pipeline import generate

    out = [("examples/sphere.png (network, refined)", generate(str(REPO / "examples" / "sphere.png")).table)]
    rgl = sorted((REPO.parent / "shared" / "data" / "rgl").glob("*.bsdf"))[:3]
    out += [(f"RGL {p.stem}", tabulate_rgl(read_rgl(p))) for p in rgl]
    return out


def _psnr(scene: Scene, full: BRDFTable, compact: BRDFTable) -> float:
    if full.is_spectral:
        a, b = (scene.render_spectral(t, full.wavelengths) for t in (full, compact))
        return metrics.spectral_metrics(a.spectral, b.spectral, a.mask).psnr_mean
    a, b = (scene.render_rgb(t) for t in (full, compact))
    return metrics.spectral_metrics(a.rgb, b.rgb, a.mask).psnr_mean


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="*", type=Path)
    args = ap.parse_args(argv)
    print(describe_machine())
    geometry = sphere_geometry(128)
    scenes = {"distant": Scene(geometry, DISTANT_LIGHTS),
              "courtyard": Scene(geometry, environment=load_environment("courtyard"))}
    with tempfile.TemporaryDirectory(dir=REPO / "bench") as tmp:
        tmp = Path(tmp)
        items = [(p.name, BRDFTable.load(p)) for p in args.tables] or _tables(tmp)
        print("| material | full table | compact | write s | rebuild s | PSNR distant dB | PSNR courtyard dB |")
        print("|---|---|---|---|---|---|---|")
        for name, table in items:
            full_path = table.save(tmp / "full.npz", overwrite=True)
            t0 = time.perf_counter()
            path = table.save(tmp / "compact.npz", overwrite=True, compact=True)
            t_write = time.perf_counter() - t0
            t0 = time.perf_counter()
            back = BRDFTable.load(path)
            t_read = time.perf_counter() - t0
            scores = [_psnr(s, table, back) for s in scenes.values()]
            print(f"| {name} | {full_path.stat().st_size / 1e6:.1f} MB | {path.stat().st_size / 1e6:.2f} MB | "
                  f"{t_write:.1f} | {t_read:.2f} | {scores[0]:.1f} | {scores[1]:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
