"""Self-reproduction and novel-lighting study of the refinement; prints a table, writes JSON.

    python bench/self_reproduction.py [--limit N] [--lightings canonical forest:30 sunset:0]
                                      [--no-novel] [--json out/bench/self_reproduction.json]

For every held-out corpus test material (and the real RGL files in ../shared/data/rgl): its photo
under each input lighting, the network's table, the refined table; self-reproduction RGB PSNR and
ΔE2000 of both against the photo; for the first lighting, spectral PSNR of both against the truth
under the protocol's distant lights and the held-out maps. See docs/refinement.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


from bench.machine import describe_machine  # noqa: E402
from specgen_addon.evaluation.self_reproduction import run_study, study_items, summarise  # noqa: E402
from specgen_addon.photo.photo_lighting import parse_lighting  # noqa: E402
from specgen_addon.render.environment_maps import HELDOUT_ENVS  # noqa: E402

RGL_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limit", type=int, default=None, help="first N test materials (default: all)")
    ap.add_argument("--lightings", nargs="+", default=["canonical", "forest:30", "sunset:0"],
                    help="input lightings: 'canonical' or MAP:ROTATION_DEG (default: %(default)s)")
    ap.add_argument("--no-rgl", action="store_true", help="leave out the real RGL files")
    ap.add_argument("--no-novel", action="store_true",
                    help="self-reproduction only (no novel-lighting renders: about 4× faster)")
    ap.add_argument("--json", type=Path, default=None, help="write rows and summary as JSON")
    args = ap.parse_args()
    lightings = []
    for spec in args.lightings:
        name, _, rot = spec.partition(":")
        lightings.append(parse_lighting(name, float(rot or 0.0)))
    items = study_items(args.limit, None if args.no_rgl else RGL_DIR)
    t0 = time.perf_counter()
    rows = run_study(items, lightings, novel_envs=HELDOUT_ENVS, novel=not args.no_novel)
    summary = summarise(rows)
    print(f"\n{describe_machine()}; {len(items)} materials × {len(lightings)} lightings in "
          f"{time.perf_counter() - t0:.0f} s")
    for light, s in summary["by_lighting"].items():
        print(f"{light:<34} network {s['psnr_network_mean']:.2f} dB → refined mean {s['psnr_refined_mean']:.2f} "
              f"min {s['psnr_refined_min']:.2f} dB; ΔE2000 mean {s['de_refined_mean']:.2f} max {s['de_refined_max']:.2f}")
    for scene, s in summary["novel"].items():
        print(f"novel {scene:<16} spectral PSNR network {s['network']:.2f} dB → refined {s['refined']:.2f} dB")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "summary": summary, "machine": describe_machine()},
                                        indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
