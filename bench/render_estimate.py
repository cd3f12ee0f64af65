"""Benchmark: the panel's time estimate against the render it estimates.

A new file's default scene (cube, light, camera; 1920×1080, Cycles' default samples with adaptive
sampling and denoising) with one photo's SpecGen material on the cube: the estimate at the scene's
own settings (not rendered: it runs for the better part of two hours here), and the estimate and
the real render of the Quick Preview (25 %, 16 samples, no denoising); then one plain render of the
default scene at 25 % with 1024 adaptive samples against its estimate; then the denoiser's
estimated cost per render against the difference of two renders of a sphere under a sun (640×480,
8 samples) with and without denoising (``--denoiser-only``: this last check alone).

Run: ``.venv/bin/python bench/render_estimate.py [--bands 21 --photo examples/sphere.png]``.
"""

from __future__ import annotations

import argparse
import runpy
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]


def denoiser_check(bpy, settings, scene_mod) -> None:
    """The denoiser's estimated seconds per render against a render with and without it."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    scene_mod.add_camera(sc)
    scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.3, -0.4, 0.8))
    sc.render.resolution_x, sc.render.resolution_y = 640, 480
    sc.cycles.samples, sc.cycles.use_adaptive_sampling, sc.cycles.use_denoising = 8, False, True
    cost = settings.measure_cost(sc)

    def timed() -> float:
        t = time.perf_counter()
        bpy.ops.render.render(write_still=False)
        return time.perf_counter() - t

    timed()                                            # kernels and the denoiser loaded
    denoised = min(timed() for _ in range(2))
    sc.cycles.use_denoising = False
    plain = min(timed() for _ in range(2))
    print(f"denoiser at 640x480, 8 samples: {denoised - plain:.1f} s per render (denoised "
          f"{denoised:.1f} s, plain {plain:.1f} s), estimated {cost.denoise_s(640 * 480):.1f} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bands", type=int, default=21)
    ap.add_argument("--photo", default=str(REPO / "examples" / "sphere.png"))
    ap.add_argument("--denoiser-only", action="store_true", help="only the denoiser's estimate")
    args = ap.parse_args(argv)

    import bpy

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    from importlib import import_module

    settings = import_module(f"{pkg.__name__}.ops.render_settings")
    if args.denoiser_only:
        denoiser_check(bpy, settings, import_module(f"{pkg.__name__}.ops.scene"))
        print(describe_machine())
        return 0
    bpy.ops.wm.read_factory_settings()
    pkg.register()
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    s = sc.specgen
    s.image_path, s.bands, s.lookup_resolution = args.photo, args.bands, "90"
    s.output_dir = tempfile.mkdtemp(prefix="specgen_estimate_")
    assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
    cube = bpy.data.objects["Cube"]
    bpy.context.view_layer.objects.active = cube
    cube.select_set(True)
    assert bpy.ops.specgen.apply() == {"FINISHED"}

    t = time.perf_counter()
    cost = settings.measure_cost(sc)
    measure_s = time.perf_counter() - t
    print(f"test renders: {measure_s:.1f} s; {cost}")
    print(f"scene settings: {settings.estimate(sc, args.bands, cost)[1]} (not rendered)")
    with settings.QuickPreview(sc):
        predicted, text = settings.estimate(sc, args.bands, settings.measure_cost(sc))
    print(f"quick preview: {text}")
    s.quick_preview = True
    t = time.perf_counter()
    assert bpy.ops.specgen.render_stack(estimate_time=False) == {"FINISHED"}
    took = time.perf_counter() - t
    print(f"quick preview rendered in {took:.1f} s, estimated {predicted:.1f} s "
          f"(ratio {predicted / took:.2f})")
    # adaptive sampling: the default scene (no SpecGen object) at 25 %, 1024 adaptive samples, one
    # plain render, estimated and rendered
    bpy.ops.wm.read_factory_settings()
    sc = bpy.context.scene
    sc.render.engine, sc.render.resolution_percentage = "CYCLES", 25
    sc.cycles.samples, sc.cycles.use_denoising = 1024, False
    cost = settings.measure_cost(sc)
    w, h = settings.render_size(sc)
    predicted = cost.render_s(w * h, sc.cycles.samples)
    t = time.perf_counter()
    bpy.ops.render.render(write_still=False)
    took = time.perf_counter() - t
    print(f"adaptive {w}x{h} at 1024 samples: rendered in {took:.1f} s, estimated {predicted:.1f} s "
          f"(share {cost.sample_fraction:.3f}; ratio {predicted / took:.2f})")
    denoiser_check(bpy, settings, import_module(f"{pkg.__name__}.ops.scene"))
    print(describe_machine())
    return 0


if __name__ == "__main__":
    sys.exit(main())
