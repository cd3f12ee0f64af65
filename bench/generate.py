"""Benchmark: the panel's Generate inside Blender (bpy module), inference + bake, per backend.

Usage: ``python bench/generate.py [IMAGE] [--bands 21] [--lookup 180] [--repeat 3]``
       ``python bench/generate.py --given-light [--repeat 3]``

Registers the add-on as Blender does, then times ``bpy.ops.specgen.generate_brdf()`` (what the
button runs: image → network → spectral basis → lookup textures, then the material and its
preview) with the backend a stock Blender uses (onnxruntime), and :func:`specgen_addon.generate.pipeline.generate`
alone (inference + bake, target ≤ 5 s) for onnx and torch. Runs are interleaved
so a busy machine slows all alike; the load average is printed with the machine, and the
process CPU time (all threads) beside the wall time, which a shared machine inflates less.

``--given-light``: the button as a user presses it on a real photo under a known light, with the
panel's defaults otherwise (refinement on, *Export Table* on): ``gray.0`` of the shared grey-ball
photos (../shared/data/photos/psm_gray_chrome), *Encoding* linear, *Lighting* one light at the
dataset's direction (its azimuth and elevation in the camera's frame). Target ≤ 6 s on 2 cores.
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
    ap.add_argument("--given-light", action="store_true",
                    help="the button on the shared grey-ball photo gray.0 under its light, refinement on")
    args = ap.parse_args()
    if args.given_light:
        return given_light(args.repeat)

    import bpy
    import numpy as np

    pkg = registered_addon()
    pipeline = import_module("specgen_addon.generate.pipeline")
    from specgen_addon.spectral.spectra import wavelength_grid

    wl = wavelength_grid(380.0, 780.0, args.bands)
    out = Path(tempfile.mkdtemp(prefix="specgen_bench_"))
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


def registered_addon():
    """The add-on package, loaded by the headless entry (batch.py) and registered as Blender does
    in a factory-fresh empty file."""
    import bpy

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))
    pkg = batch.load_package()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg.register()
    return pkg


def given_light(repeat: int) -> int:
    """The button, refinement and Export Table on, on ``gray.0`` under the dataset's light."""
    import math

    import bpy
    import numpy as np

    data = REPO.parent / "shared" / "data" / "photos" / "psm_gray_chrome"
    if not data.is_dir():
        print(f"needs the shared photos at {data}", file=sys.stderr)
        return 2
    x, y, z = np.loadtxt(data / "lights.txt", skiprows=1)[0]
    pkg = registered_addon()
    s = bpy.context.scene.specgen
    s.image_path, s.output_dir, s.overwrite = str(data / "gray" / "gray.0.tga"), tempfile.mkdtemp(), True
    photo = s.photo
    photo.encoding, photo.lighting = "linear", "LIGHTS"
    light = photo.lights.add()
    light.azimuth, light.elevation = math.atan2(x, z), math.asin(y)     # camera frame, radians
    print(f"machine: {describe_machine()}")
    print(f"the button on gray.0, light az {math.degrees(light.azimuth):.1f}° el "
          f"{math.degrees(light.elevation):.1f}°; refine {s.refine}, Export Table {s.export_table}, "
          f"{s.bands} bands, lookup {s.lookup_resolution} φd")
    assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}     # warm-up: the model loads
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        print(f"  {wall[-1]:.2f} s wall, {cpu[-1]:.2f} s CPU", flush=True)
    pkg.unregister()
    print(f"button, light given: wall best {min(wall):.2f} s, median {float(np.median(wall)):.2f} s; "
          f"CPU best {min(cpu):.2f} s; target ≤ 6 s")
    print(f"machine: {describe_machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
