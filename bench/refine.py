"""Refinement speed and peak memory at the default table size (90 × 90 × 180 × 21).

    python bench/refine.py [--image examples/sphere.png] [--input-env canonical] [--repeat 3]

Generates the network's table once (not timed), then times :func:`specgen_addon.generate.refine.refine_brdf`
(operator, design, solve, apply, and the two verification renders) ``--repeat`` times, each with a
fresh lighting operator, in wall and CPU seconds. Peak memory is the largest traced allocation
(``tracemalloc``; numpy reports its buffers) during one refinement, above what was held before it.
Target: ≤ 15 s on 2 cores.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

from machine import describe_machine  # noqa: E402  (bench/machine.py, beside this script)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--image", type=Path, default=REPO / "examples" / "sphere.png")
    ap.add_argument("--input-env", default="canonical", help="'canonical', a bundled map or a file")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from specgen_addon.photo import photo_lighting as input_lighting
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.generate.pipeline import load_photo
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf

    light = input_lighting.parse_lighting(args.input_env)
    photo, linear = load_photo(args.image)
    table = generate_brdf(photo * light.network_gain())
    options = RefineOptions(clip_level=None if linear else CLIP_LEVEL)
    print(describe_machine())
    print(f"table {table.values.shape}, {table.values.nbytes / 2**20:.0f} MiB; lighting {light.label}")
    walls, cpus = [], []
    for i in range(args.repeat):
        input_lighting._scene.cache_clear()          # a fresh lighting operator each time
        from specgen_addon.photo import sphere_image as input_image
        input_image._scene.cache_clear()
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        t0, c0 = time.perf_counter(), time.process_time()
        res = refine_brdf(table, photo, light, options)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        print(f"run {i + 1}: {walls[-1]:.2f} s wall, {cpus[-1]:.2f} s CPU, peak +{peak / 2**20:.0f} MiB; "
              f"{res.summary()}")
    print(f"refinement: median {sorted(walls)[len(walls) // 2]:.2f} s wall "
          f"(CPU {sorted(cpus)[len(cpus) // 2]:.2f} s); target ≤ 15 s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
