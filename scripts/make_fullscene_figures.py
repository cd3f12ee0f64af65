"""Figures of the full-scene spectral mode (docs/blender.md).

* ``docs/figures/fullscene_cornell.png``: a Cornell box with a white SpecGen sphere, full-scene
  spectral render projected to sRGB, beside Blender's RGB render of the same file, and the
  sphere's spectra on its red-wall and green-wall sides (colour bleeding).
* ``docs/figures/fullscene_ordinary.png``: an ordinary scene (floor, Principled
  spheres, area light, sun, HDRI through a rotated Mapping + a second Background, one SpecGen
  sphere made from corpus material ``mat0001``), spectral → sRGB beside Blender's RGB render
  (which shows the SpecGen material's RGB stand-in).

Run: ``.venv/bin/python scripts/make_fullscene_figures.py [--samples 128 --width 192]``.
Prints the closure-fit errors, the projection PSNRs and the timings.
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

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _srgb8(linear: np.ndarray) -> np.ndarray:
    from specgen_addon.spectral.spectra import srgb_encode

    return (np.clip(srgb_encode(np.clip(linear, 0, 1)), 0, 1) * 255 + 0.5).astype(np.uint8)


def _psnr(a, ref) -> float:
    return float(10 * np.log10(ref.max() ** 2 / np.mean((a - ref) ** 2)))


def white_table(wl: np.ndarray):
    """A white dielectric-like spectral BRDF: flat 0.8 Lambert + a faint GGX lobe."""
    from specgen_addon.bake.closure_fit import ggx_lobe
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.full(wl.size, 0.8 / np.pi) + ggx_lobe(wi, wo, 0.25)[:, None] * 0.04
    return BRDFTable.tabulate(fn, wl)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=128)
    ap.add_argument("--width", type=int, default=192)
    ap.add_argument("--out", default=str(REPO / "docs" / "figures"))
    args = ap.parse_args(argv)

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    import bpy
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from bpy_extras.object_utils import world_to_camera_view

    bake = import_module("specgen_addon.bake.lookup")
    render = import_module(f"{pkg.__name__}.ops.render")
    fullscene = import_module(f"{pkg.__name__}.ops.render_fullscene")
    demo = import_module(f"{pkg.__name__}.ops.demo_scenes")
    from specgen_addon.spectral import spectra
    from specgen_addon.corpus import generate_corpus

    wl = spectra.wavelength_grid(380.0, 780.0, 21)
    work = Path(tempfile.mkdtemp(prefix="specgen_fig_"))
    out = Path(args.out)

    def rgb_render(sc) -> np.ndarray:
        with fullscene._RenderSettings(sc):
            bpy.ops.render.render(write_still=False)
            bpy.data.images["Render Result"].save_render(str(work / "rgb.exr"), scene=sc)
        return fullscene._read_combined(work / "rgb.exr")[..., :3]

    # --------------------------------------------------------------- Cornell box
    info = bake.bake_atlas(white_table(wl), work / "white.exr")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = render.make_material("SpecGen white", info)
    sc = demo.cornell_box(mat, samples=args.samples, size=(args.width, args.width))
    t = time.perf_counter()
    job = fullscene.FullSceneRenderJob(sc, None, wl)
    stack = job.run()
    full_s = time.perf_counter() - t
    t = time.perf_counter()
    rgb = rgb_render(sc)
    rgb_s = time.perf_counter() - t
    proj = spectra.spectral_to_linear_srgb(stack, wl)
    cam = sc.camera
    h, w = stack.shape[:2]
    sides = {}
    for name, offset in (("red-wall side", (-0.32, -0.25, 0.0)), ("green-wall side", (0.32, -0.25, 0.0))):
        from mathutils import Vector

        p = world_to_camera_view(sc, cam, Vector((0.0, 0.1, 0.45)) + Vector(offset))
        x, y = int(p.x * w), int((1 - p.y) * h)
        sides[name] = stack[y - 1:y + 2, x - 1:x + 2].reshape(-1, wl.size).mean(0)
    fig, ax = plt.subplots(1, 3, figsize=(11, 3.6), gridspec_kw={"width_ratios": [1, 1, 1.3]})
    ax[0].imshow(_srgb8(proj))
    ax[0].set_title("full-scene spectral → sRGB")
    ax[1].imshow(_srgb8(rgb))
    ax[1].set_title("Blender RGB render (stand-in)")
    for a in ax[:2]:
        a.axis("off")
    for (name, s), c in zip(sides.items(), ("tab:red", "tab:green")):
        ax[2].plot(wl, s / s.max(), c, label=name)
    ax[2].set_xlabel("wavelength (nm)")
    ax[2].set_ylabel("radiance (normalised)")
    ax[2].set_title("white SpecGen sphere: colour bleeding")
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(out / "fullscene_cornell.png", dpi=90)
    red, green = sides["red-wall side"], sides["green-wall side"]
    long_short = lambda s: s[wl >= 620].mean() / s[wl <= 480].mean()  # noqa: E731
    print(f"Cornell box {w}x{h}, {args.samples} spp: closure fit error {100 * info.closures.max_error:.2f} %; "
          f"projection vs RGB render {_psnr(proj, rgb):.1f} dB; long/short-wave ratio on the sphere: "
          f"red-wall side {long_short(red):.2f}, green-wall side {long_short(green):.2f}; "
          f"full-scene {full_s:.1f} s vs RGB {rgb_s:.1f} s")

    # --------------------------------------------------------------- ordinary scene
    table = generate_corpus(n=2, seed=0)[1].tabulate()
    info = bake.bake_atlas(table, work / "mat.exr", wavelengths_nm=wl)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = render.make_material("SpecGen mat0001", info)
    sc = demo.ordinary_scene(samples=args.samples, size=(args.width, args.width * 2 // 3),
                             specgen_material=mat)
    t = time.perf_counter()
    job = fullscene.FullSceneRenderJob(sc, None, wl)
    stack = job.run()
    full_s = time.perf_counter() - t
    t = time.perf_counter()
    rgb = rgb_render(sc)
    rgb_s = time.perf_counter() - t
    proj = spectra.spectral_to_linear_srgb(stack, wl)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].imshow(_srgb8(proj))
    ax[0].set_title("full-scene spectral (21 bands) → sRGB")
    ax[1].imshow(_srgb8(rgb))
    ax[1].set_title("Blender's RGB render (SpecGen: RGB stand-in)")
    for a in ax:
        a.axis("off")
    fig.tight_layout()
    fig.savefig(out / "fullscene_ordinary.png", dpi=90)
    print(f"ordinary scene {stack.shape[1]}x{stack.shape[0]}, {args.samples} spp: closure fit error "
          f"{100 * info.closures.max_error:.2f} %; projection vs RGB render {_psnr(proj, rgb):.1f} dB "
          f"(the SpecGen sphere differs: RGB stand-in vs spectral fit); full-scene {full_s:.1f} s "
          f"vs RGB {rgb_s:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
