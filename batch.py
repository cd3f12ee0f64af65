"""Headless SpecGen: photo of a sphere -> spectral BRDF -> spectral OpenEXR render of a scene.

Runs inside Blender or on the ``bpy`` module, with the same arguments::

    blender --background --python batch.py -- --image IMG --mesh sphere --env studio --out DIR
    python batch.py --image IMG --mesh suzanne --env courtyard --out DIR [--bands 21 ...]

Writes ``DIR/<image>_<mesh>_<env>.exr`` (Fichet et al. 2021 spectral layout with an RGB preview)
and ``…_preview.png``, plus the generated BRDF table and its baked lookups under ``DIR/lookup/``.
Bad input (missing file, image without a sphere, unknown environment, unwritable output) exits
with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parent
PACKAGE = "specgen"
EXIT_BAD_INPUT = 2


def load_package(name: str = PACKAGE):
    """Import this repository as the package ``name`` (as Blender imports the installed extension,
    ``bl_ext.<repo>.specgen``), so ``ops`` reaches the core with the same relative imports."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO / "__init__.py",
                                                  submodule_search_locations=[str(REPO)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="batch.py",
        description="Generate a spectral BRDF from a photo of a sphere and render a spectral "
                    "OpenEXR (Fichet et al. 2021 layout) of a mesh lit by an environment map.",
        epilog="Inside Blender pass the arguments after '--': "
               "blender --background --python batch.py -- --image IMG ...")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--image", help="photo of a sphere of the material (EXR/PNG/JPEG)")
    src.add_argument("--brdf", help="render this spectral BRDF table (.npz from "
                     "`python -m specgen_addon`) instead of generating one from an image")
    ap.add_argument("--mesh", default="sphere", help="'sphere', 'suzanne' or a path to an .obj file")
    ap.add_argument("--env", default="studio",
                    help="environment map name from Blender's studio lights (e.g. studio, courtyard)")
    ap.add_argument("--out", required=True, help="output folder (created if missing)")
    ap.add_argument("--bands", type=int, default=21, help="number of wavelength bands (default 21)")
    ap.add_argument("--wl-min", type=float, default=380.0, help="shortest wavelength, nm (default 380)")
    ap.add_argument("--wl-max", type=float, default=780.0, help="longest wavelength, nm (default 780)")
    ap.add_argument("--samples", type=int, default=16, help="Cycles samples per pixel (default 16)")
    ap.add_argument("--resolution", type=int, default=256, help="image width = height in pixels (default 256)")
    ap.add_argument("--env-samples", type=int, default=2,
                    help="environment directions per Cycles sample in the shader (default 2)")
    ap.add_argument("--sun", action="store_true", help="add a sun from the upper left (irradiance π)")
    ap.add_argument("--weights", default=None, help="network weights (.pt); default: the shipped ones")
    ap.add_argument("--backend", choices=("onnx", "torch"), default=None,
                    help="inference backend (default: onnx if onnxruntime is installed)")
    ap.add_argument("--overwrite", action="store_true", help="replace existing output files")
    ap.add_argument("--verbose", action="store_true",
                    help="let Blender's own log lines (e.g. 'Saved: ...') through to stdout")
    return ap


def _script_argv(argv: list[str] | None) -> list[str]:
    if argv is not None:
        return argv
    if "--" in sys.argv:  # blender --background --python batch.py -- ARGS
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:]


def run(args) -> Path:
    """Generate, bake, build the scene, render; returns the spectral EXR path."""
    pkg = load_package()
    from importlib import import_module

    errors = import_module(f"{pkg.__name__}.specgen_addon.errors")
    lighting = import_module(f"{pkg.__name__}.specgen_addon.lighting")
    spectra = import_module(f"{pkg.__name__}.specgen_addon.spectra")

    source = Path(args.image or args.brdf)
    if not source.is_file():
        kind = "input image" if args.image else "BRDF table"
        raise errors.ImageInputError(f"{source}: {kind} not found")
    if args.mesh not in ("sphere", "suzanne") and not Path(args.mesh).is_file():
        raise errors.SpecGenError(f"{args.mesh}: mesh file not found (use sphere, suzanne or an .obj path)")
    if args.image:
        input_image = import_module(f"{pkg.__name__}.specgen_addon.input_image")
        with warnings.catch_warnings():  # keep a bad image to the one error line
            warnings.simplefilter("ignore")
            input_image.load_sphere_image(source)  # no sphere / unreadable -> ImageInputError, early
    env = lighting.load_environment(args.env)  # unknown name -> LightingAssetError with the list
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise errors.SpecGenError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK):
        raise errors.SpecGenError(f"{out}: output folder is not writable")
    mesh_tag = args.mesh if args.mesh in ("sphere", "suzanne") else Path(args.mesh).stem
    target = out / f"{source.stem}_{mesh_tag}_{args.env}.exr"
    for p in (target, target.with_name(target.stem + "_preview.png")):
        if p.exists() and not args.overwrite:
            raise errors.OutputExistsError(f"{p}: already exists (pass --overwrite to replace it)")
    wavelengths = spectra.wavelength_grid(args.wl_min, args.wl_max, args.bands)

    bake = import_module(f"{pkg.__name__}.ops.bake")
    t0 = time.perf_counter()
    last = [-1]

    def progress(f: float) -> None:
        pct = int(100 * f)
        if pct // 10 != last[0] // 10:
            print(f"  generate: {pct}%", flush=True)
        last[0] = pct

    if args.image:
        info = bake.generate_lookup(str(source), out / "lookup", wavelengths, weights=args.weights,
                                    backend=args.backend, name=source.stem, progress=progress,
                                    save_table=True)
    else:
        table_mod = import_module(f"{pkg.__name__}.specgen_addon.table")
        table = table_mod.BRDFTable.load(source)
        info = bake.bake_atlas(table, out / "lookup" / f"{source.stem}_lookup.exr",
                               wavelengths_nm=wavelengths, progress=progress)
    print(f"BRDF ready and baked in {time.perf_counter() - t0:.1f} s "
          f"({info.n_coeffs} basis coefficients, max error {info.rel_error:.1e})", flush=True)

    import bpy
    import numpy as np

    render = import_module(f"{pkg.__name__}.ops.render")
    scene_mod = import_module(f"{pkg.__name__}.ops.scene")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene_mod.add_camera(scene)
    obj = scene_mod.add_mesh(scene, args.mesh)
    env_file = out / "lookup" / f"env_{args.env}.exr"
    _write_rgb_exr(env_file, env.rgb)  # the reference renderer's normalised map, as Cycles sees it
    scene_mod.set_world_environment(scene, env_file, 1.0)
    if args.sun:
        scene_mod.add_sun(scene, (-0.5, 0.6, 0.62), float(np.pi))
    obj.data.materials.clear()
    obj.data.materials.append(render.make_material(f"SpecGen {source.stem}", info))

    t0 = time.perf_counter()
    job = render.SpectralRenderJob(scene, target, samples=args.samples,
                                   resolution=(args.resolution, args.resolution),
                                   overwrite=args.overwrite, env_samples=args.env_samples,
                                   attributes={"specgenSource": str(source), "specgenMesh": args.mesh,
                                               "specgenEnvironment": args.env},
                                   warn=lambda m: print(m, file=sys.stderr))
    quiet = import_module(f"{pkg.__name__}.specgen_addon.quiet")
    with quiet.native_stdout_silenced(not args.verbose):  # Cycles' "Saved: ..." lines
        job.run(lambda f: None)
    print(f"spectral render ({args.bands} bands, {args.resolution}², {args.samples} spp) in "
          f"{time.perf_counter() - t0:.1f} s", flush=True)
    print(f"wrote {target}")
    print(f"wrote {target.with_name(target.stem + '_preview.png')}")
    return target


def _write_rgb_exr(path: Path, rgb) -> None:
    from importlib import import_module

    image_io = import_module(f"{load_package().__name__}.specgen_addon.image_io")  # OpenEXR or OIIO
    image_io.write_exr(path, {c: rgb[..., i] for i, c in enumerate("RGB")}, overwrite=True)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(_script_argv(argv))
    try:
        run(args)
    except Exception as exc:
        # SpecGenError from the package (loaded as ``specgen``) or from a plain ``specgen_addon``
        # import: the user gets its one-line message, anything else stays a traceback.
        if not any(c.__name__ == "SpecGenError" for c in type(exc).__mro__):
            raise
        print(f"batch.py: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.exit(code)
