"""Benchmark: spectral renders vs one plain RGB Cycles render of the same scene.

* ``--mode fullscene`` (default): the full-scene mode on an ordinary scene (floor,
  Principled spheres, area light, sun, HDRI world, one SpecGen sphere), the whole job (scene
  conversion, ceil(bands/3) Cycles renders with persistent data, restore, EXR + PNG) against one
  plain RGB render (fresh, as F12) of the same file, resolution and samples.
  Target: ratio ≤ bands/3 + 1.
* ``--mode exact``: the exact mode (SpecGen OSL, unit sphere, one sun) against an RGB render of a
  Principled sphere. Target: ratio ≤ 3.

Run: ``.venv/bin/python bench/render.py [--mode fullscene|exact --resolution 256 --samples 16 --bands 21]``.
"""

from __future__ import annotations

import argparse
import statistics
import runpy
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--bands", type=int, default=21)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--env", default=None, help="light by this studio-light world instead of a sun")
    ap.add_argument("--tolerance", type=float, default=1e-3,
                    help="spectral basis tolerance (0 = complete basis: the worst case, most renders)")
    ap.add_argument("--mode", choices=("fullscene", "exact"), default="fullscene")
    args = ap.parse_args(argv)
    if args.mode == "fullscene":
        return bench_fullscene(args)

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    import bpy
    import numpy as np
    from importlib import import_module

    render = import_module(f"{pkg.__name__}.ops.render")
    bake = import_module("specgen_addon.bake.lookup")
    scene_mod = import_module(f"{pkg.__name__}.ops.scene")
    from specgen_addon.corpus import generate_corpus

    wl = np.linspace(380.0, 780.0, args.bands)
    material = generate_corpus(n=1, seed=0)[0]  # a physically based spectral corpus material
    table = material.tabulate()
    work = Path(tempfile.mkdtemp(prefix="specgen_bench_"))
    t = time.perf_counter()
    atlas = bake.bake_atlas(table, work / "atlas.exr", wavelengths_nm=wl, tolerance=args.tolerance)
    bake_s = time.perf_counter() - t

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    scene_mod.add_camera(sc)
    obj = scene_mod.add_mesh(sc, "sphere")
    if args.env:
        from specgen_addon.render.environment_maps import load_environment

        env_file = work / "env.exr"
        batch._write_rgb_exr(env_file, load_environment(args.env).rgb)
        scene_mod.set_world_environment(sc, env_file, 1.0)
    else:
        scene_mod.add_sun(sc, (0.3, 0.5, 0.8), np.pi)
    res = args.resolution
    sc.render.resolution_x = sc.render.resolution_y = res
    sc.render.resolution_percentage = 100
    sc.cycles.samples = args.samples
    sc.cycles.use_denoising = False

    # Plain RGB render: Principled BSDF, Cycles defaults (SVM), same samples/resolution.
    plain = bpy.data.materials.new("plain")
    obj.data.materials.append(plain)
    sc.render.filepath = str(work / "rgb.png")
    rgb_times = []
    for _ in range(args.repeats + 1):
        t = time.perf_counter()
        bpy.ops.render.render(write_still=False)
        rgb_times.append(time.perf_counter() - t)
    rgb_times = rgb_times[1:]  # first run pays one-off kernel/BVH warm-up

    mat = render.make_material("SpecGen bench", atlas)
    obj.data.materials[0] = mat
    job_times, cycles_times = [], []
    for i in range(args.repeats + 1):
        job = render.SpectralRenderJob(sc, work / f"stack{i}.exr", samples=args.samples,
                                       resolution=(res, res), overwrite=True)
        t = time.perf_counter()
        job.run()
        job_times.append(time.perf_counter() - t)
        cycles_times.append(job.timings["cycles_s"])
    job_times, cycles_times = job_times[1:], cycles_times[1:]  # drop the OSL JIT/texture warm-up

    rgb = statistics.median(rgb_times)
    full = statistics.median(job_times)
    cyc = statistics.median(cycles_times)
    print(f"machine: {describe_machine()}; bpy {bpy.app.version_string}")
    print(f"scene: unit sphere, {'env ' + args.env if args.env else 'one sun'}, {res}x{res}, "
          f"{args.samples} spp, {args.bands} bands; material {material.name}")
    print(f"spectral basis: {atlas.n_coeffs} coefficients (tolerance {args.tolerance:g}, max error "
          f"{atlas.rel_error:.1e}) -> {atlas.n_renders} Cycles render(s); bake {bake_s:.2f} s (once per BRDF)")
    print(f"plain RGB Cycles render (Principled): {rgb:.3f} s  (median of {args.repeats})")
    print(f"spectral stack, Cycles renders only:  {cyc:.3f} s  -> ratio {cyc / rgb:.2f}x")
    print(f"spectral stack, full job (+bake/EXR): {full:.3f} s  -> ratio {full / rgb:.2f}x  (target <= 3x)")
    return 0


def bench_fullscene(args) -> int:
    """Full-scene job vs one plain RGB render of the ordinary scene (see the module docstring)."""
    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    import bpy
    import numpy as np
    from importlib import import_module

    bake = import_module("specgen_addon.bake.lookup")
    render = import_module(f"{pkg.__name__}.ops.render")
    fullscene = import_module(f"{pkg.__name__}.ops.render_fullscene")
    demo = import_module(f"{pkg.__name__}.ops.demo_scenes")
    from specgen_addon.corpus import generate_corpus

    wl = np.linspace(380.0, 780.0, args.bands)
    work = Path(tempfile.mkdtemp(prefix="specgen_bench_"))
    material = generate_corpus(n=2, seed=0)[1]
    atlas = bake.bake_atlas(material.tabulate(), work / "atlas.exr", wavelengths_nm=wl)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = render.make_material("SpecGen bench", atlas)
    res = (args.resolution, args.resolution * 2 // 3)
    sc = demo.ordinary_scene(samples=args.samples, size=res, specgen_material=mat)
    sc.render.use_persistent_data = False

    def rgb_once() -> float:
        t = time.perf_counter()
        bpy.ops.render.render(write_still=False)       # F12: sync (BVH) + render, RGB
        return time.perf_counter() - t

    rgb_once()                                        # kernel/image warm-up
    rgb_times, job_times, render_times = [], [], []
    for i in range(args.repeats):
        rgb_times.append(rgb_once())
        job = fullscene.FullSceneRenderJob(sc, work / f"stack{i}.exr", wl, overwrite=True,
                                           log=lambda m: None)
        t = time.perf_counter()
        job.run()
        job_times.append(time.perf_counter() - t)
        render_times.append(sum(job.timings["render_s"]))
    rgb, full, cyc = (statistics.median(x) for x in (rgb_times, job_times, render_times))
    groups = -(-args.bands // 3)
    print(f"machine: {describe_machine()}; bpy {bpy.app.version_string}")
    print(f"scene: ordinary scene (floor, 3 Principled spheres, area light, sun, HDRI world, one "
          f"SpecGen sphere {material.name}), {res[0]}x{res[1]}, {args.samples} spp, {args.bands} bands "
          f"-> {groups} Cycles renders (3 bands each, persistent data)")
    print(f"plain RGB Cycles render (F12, fresh sync): {rgb:.3f} s  (median of {args.repeats})")
    print(f"full-scene spectral, Cycles renders only:  {cyc:.3f} s  -> ratio {cyc / rgb:.2f}x")
    print(f"full-scene spectral, whole job (+EXR/PNG): {full:.3f} s  -> ratio {full / rgb:.2f}x  "
          f"(target <= bands/3 + 1 = {args.bands / 3 + 1:.1f}x)")
    t = job.timings["render_s"]  # the last job: band renders, then the closures' direct light
    print(f"  of which (last run): {groups} band renders {sum(t[:groups]):.3f} s, {len(t) - groups} "
          f"direct-light renders {sum(t[groups:]):.3f} s, "
          f"exact direct light {job.timings.get('exact_s', 0):.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
