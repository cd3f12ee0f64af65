"""Benchmark: the panel's Generate inside Blender (bpy module), inference + bake, per backend.

Usage: ``python bench/generate.py [IMAGE] [--bands 21] [--lookup 180] [--repeat 3]``

Registers the add-on as Blender does, then times ``bpy.ops.specgen.generate_brdf()`` (what the
button runs: image → network → spectral basis → lookup textures, then the material and its
preview) with the backend a stock Blender uses (onnxruntime), and :func:`specgen_addon.generate.pipeline.generate`
alone (inference + bake, target ≤ 5 s) for onnx and torch. Runs are interleaved
so a busy machine slows all alike; the load average is printed with the machine, and the
process CPU time (all threads) beside the wall time, which a shared machine inflates less.
"""

from __future__ import annotations

import argparse
import runpy
import sys
import tempfile
import time
from importlib import import_module
from pathlib import Path
from types import SimpleNamespace

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("image", nargs="?", type=Path, default=REPO / "examples" / "sphere.png")
    ap.add_argument("--bands", type=int, default=21)
    ap.add_argument("--lookup", choices=("180", "90", "45"), default="180")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    import bpy
    import numpy as np

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    pipeline = import_module("specgen_addon.generate.pipeline")
    from specgen_addon.spectral.spectra import wavelength_grid

    wl = wavelength_grid(380.0, 780.0, args.bands)
    out = Path(tempfile.mkdtemp(prefix="specgen_bench_"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg.register()
    s = bpy.context.scene.specgen
    s.image_path, s.output_dir, s.bands, s.lookup_resolution = str(args.image), str(out), args.bands, args.lookup
    s.overwrite = True
    s.refine = False  # Generate is timed without refinement (bench/refine.py times that)
    pipeline.generate(str(args.image), out_dir=out, wavelengths_nm=wl, n_phi_d=int(args.lookup), backend="onnx", refine=False)  # warm-up:
    pipeline.generate(str(args.image), out_dir=out, wavelengths_nm=wl, n_phi_d=int(args.lookup), backend="torch", refine=False)  # model loads
    times: dict[str, list[float]] = {"operator (onnx)": [], "onnx": [], "torch": []}
    cpu: dict[str, list[float]] = {k: [] for k in times}
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
        times["operator (onnx)"].append(time.perf_counter() - t0)
        cpu["operator (onnx)"].append(time.process_time() - c0)
        for backend in ("onnx", "torch"):
            t0, c0 = time.perf_counter(), time.process_time()
            pipeline.generate(str(args.image), out_dir=out, wavelengths_nm=wl, n_phi_d=int(args.lookup), backend=backend, refine=False)
            times[backend].append(time.perf_counter() - t0)
            cpu[backend].append(time.process_time() - c0)
    pkg.unregister()
    print(f"machine: {describe_machine()}")
    print(f"Generate: {args.bands} bands, lookup {args.lookup} φd, {args.image.name}")
    for name, t in times.items():
        what = "button: inference + bake + material + preview" if name.startswith("operator") \
            else "inference + bake"
        print(f"{name:16s} wall best {min(t):.2f} s, median {float(np.median(t)):.2f} s; "
              f"CPU best {min(cpu[name]):.2f} s  ({what})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
