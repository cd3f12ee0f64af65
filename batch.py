"""Headless SpecGen: photo of a sphere -> spectral BRDF -> spectral OpenEXR render of a scene.

Runs inside Blender or on the ``bpy`` module, with the same arguments::

    blender --background --python batch.py -- --image IMG --mesh sphere --env studio --out DIR
    python batch.py --image IMG --mesh suzanne --env courtyard --out DIR [--bands 21 ...]
    python batch.py --scene FILE.blend --out DIR [--bands 21 ...]        # full-scene spectral
    python batch.py --scene FILE.blend --apply photo.png:Cube photo2.jpg:Suzanne:env=forest \
        --frames 1-10 --out DIR
    blender --background FILE.blend --python batch.py -- --scene --out DIR

Writes ``DIR/<image>_<mesh>_<env>.exr`` (Fichet et al. 2021 spectral layout with an RGB preview)
and ``…_preview.png``; with ``--keep-lookups`` also the generated BRDF (compact material file) and
its baked lookups under ``DIR/lookup/``, which are otherwise removed after the render.
With ``--scene``: ``DIR/<scene>_<camera>_f<frame>.exr`` per frame (preview through the scene's
view transform), after ``--apply`` has given each photo's material to its object.
Bad input (missing file, image without a sphere, unknown environment, unwritable output) exits
with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parent
if str(REPO) not in sys.path:  # the core is the top-level package specgen_addon in every entry
    sys.path.insert(0, str(REPO))
PACKAGE = "specgen"
EXIT_BAD_INPUT = 2


def check_settings(args: argparse.Namespace) -> None:
    """batch.py's settings that need neither its input nor the network (sizes, wavelengths,
    weights, mesh, environment name, the photo options): what ``batch-many`` checks once for all
    its items before any runs; each run checks its photo with them (:func:`run`)."""
    from importlib import import_module

    import_module("specgen_addon.scale.preflight").check_batch_settings(args)
    import_module("specgen_addon.cli.photo_args").check_photo_options(args)


def load_package(name: str = PACKAGE):
    """Import this repository as the package ``name`` (as Blender imports the installed extension,
    ``bl_ext.<repo>.specgen``) for the Blender tier ``ops``; the core is ``specgen_addon`` itself."""
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
    src.add_argument("--scene", nargs="?", const="", metavar="FILE.blend",
                     help="full-scene spectral render of this .blend (its camera, frame, "
                     "resolution, samples, lights and world; SpecGen materials already applied); "
                     "without FILE: the .blend Blender was started with")
    ap.add_argument("--mesh", default="sphere", help="'sphere', 'suzanne' or a path to an .obj file")
    ap.add_argument("--env", default="studio",
                    help="environment map name from Blender's studio lights (e.g. studio, courtyard)")
    ap.add_argument("--out", required=True, help="output folder (created if missing)")
    ap.add_argument("--bands", type=int, default=21,
                    help="number of wavelength bands, 1–128 (default 21; one band renders at --wl-min)")
    ap.add_argument("--wl-min", type=float, default=380.0, help="shortest wavelength, nm (default 380)")
    ap.add_argument("--wl-max", type=float, default=780.0, help="longest wavelength, nm (default 780)")
    ap.add_argument("--samples", type=int, default=None,
                    help="Cycles samples per pixel (default 16; --scene: the scene's)")
    ap.add_argument("--resolution", type=int, default=None,
                    help="image width = height in pixels (default 256; --scene: the scene's)")
    ap.add_argument("--env-samples", type=int, default=2,
                    help="environment directions per Cycles sample in the shader (default 2)")
    ap.add_argument("--sun", action="store_true",
                    help="add a sun from the upper left (irradiance π; D65, of unit luminance over the rendered bands)")
    ap.add_argument("--weights", default=None, help="network weights (.pt); default: the shipped ones")
    ap.add_argument("--backend", choices=("onnx", "torch"), default=None,
                    help="inference backend (default: onnx if onnxruntime is installed)")
    ap.add_argument("--every-band", action="store_true",
                    help="the network evaluates every band (default: bands at most 40 nm apart, the "
                         "others interpolated in λ: about 1 s faster, the table within 1 %% rms)")
    ap.add_argument("--overwrite", action="store_true", help="replace existing output files")
    ap.add_argument("--keep-lookups", action="store_true",
                    help="keep the generated BRDF (compact material, a few MB) and its baked lookups "
                         "(about 47 MB a material) in OUT/lookup/; by default only the renders stay")
    sc = ap.add_argument_group("whole scene (--scene)")
    sc.add_argument("--apply", nargs="+", metavar="IMG:OBJECT[:OPTS]",
                    help="before rendering, generate each photo's material and give it to that "
                    "mesh object of the scene; OPTS: that photo's own photo options, any of the "
                    "ones below without their '--' (env, rotation, exposure, key-light for the "
                    "map), e.g. env=forest,rotation=30 or light=30,20,2,3200K,ambient=0.05,linear=on "
                    "(default: the command's own)")
    sc.add_argument("--frames", metavar="LIST",
                    help="frames to render, e.g. 1-10 or 1,3,5-7 (default: the scene's current "
                    "frame); one <scene>_<camera>_f<frame>.exr each")
    sc.add_argument("--preview", action="store_true",
                    help="quick preview: 25%% resolution, at most 16 samples, no denoising")
    ap.add_argument("--verbose", action="store_true",
                    help="print the traceback of an error, and let Blender's own log lines "
                         "(e.g. 'Saved: ...') through to stdout")
    from importlib import import_module

    import_module("specgen_addon.cli.photo_args").add_photo_arguments(ap)
    return ap


def _script_argv(argv: list[str] | None) -> list[str]:
    if argv is not None:
        return argv
    if "--" in sys.argv:  # blender --background --python batch.py -- ARGS
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:]


def run(args) -> Path:
    """Generate, bake, build the scene, render; returns the spectral EXR path."""
    if args.scene is not None:
        return run_scene(args)
    for flag, value in (("--apply", args.apply), ("--frames", args.frames), ("--preview", args.preview)):
        if value:
            from importlib import import_module

            errors = import_module("specgen_addon.common.errors")
            raise errors.SpecGenError(f"{flag} needs --scene")
    args.samples = 16 if args.samples is None else args.samples
    args.resolution = 256 if args.resolution is None else args.resolution
    pkg = load_package()
    from importlib import import_module

    errors = import_module("specgen_addon.common.errors")
    lighting = import_module("specgen_addon.render.environment_maps")
    spectra = import_module("specgen_addon.spectral.spectra")
    interrupts = import_module("specgen_addon.common.interrupts")

    import_module("specgen_addon.scale.preflight").check_batch(args)  # all checks, up front
    source = Path(args.image or args.brdf)
    if not source.is_file():
        kind = "input image" if args.image else "BRDF table"
        raise errors.ImageInputError(f"{source}: {kind} not found")
    if args.mesh not in ("sphere", "suzanne") and not Path(args.mesh).is_file():
        raise errors.SpecGenError(f"{args.mesh}: mesh file not found (use sphere, suzanne or an .obj path)")
    photo_args = import_module("specgen_addon.cli.photo_args")
    out = Path(args.out)
    mesh_tag = args.mesh if args.mesh in ("sphere", "suzanne") else Path(args.mesh).stem
    target = out / f"{source.stem}_{mesh_tag}_{args.env}.exr"
    if args.image:
        outputs = {"the render": target,
                   "the render's preview": target.with_name(target.stem + "_preview.png")}
        if args.light_probe is not None:
            outputs["the unwrapped chrome ball"] = out / "lookup" / f"{source.stem}_probe.exr"
        with warnings.catch_warnings():  # keep a bad image to the one error line
            warnings.simplefilter("ignore")
            # no sphere / unreadable / bad light, patch, probe or preview -> one sentence, early
            photo_args.check_photo_args(args, source, outputs, out_dir=out)
    env = lighting.load_environment(args.env)  # unknown name -> LightingAssetError with the list
    try:
        import_module("specgen_addon.common.atomic_io").make_dirs(out)  # removed if the run fails
    except OSError as exc:
        raise errors.SpecGenError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK):
        raise errors.SpecGenError(f"{out}: output folder is not writable")
    for p in (target, target.with_name(target.stem + "_preview.png")):
        import_module("specgen_addon.common.limits").refuse_existing(p, args.overwrite)
    wavelengths = spectra.wavelength_grid(args.wl_min, args.wl_max, args.bands)

    bake = import_module("specgen_addon.bake.lookup")
    pipeline = import_module("specgen_addon.generate.pipeline")
    t0 = time.perf_counter()
    last = [-1]

    def progress(f: float) -> None:
        pct = int(100 * f)
        if pct // 10 != last[0] // 10:
            print(f"  generate: {pct}%", flush=True)
        last[0] = pct

    PHASE[0] = "BRDF generation"
    before = _files_in(out / "lookup")
    if args.image:
        photo, photo_lighting = photo_args.photo_inputs(args, source,
                                                        out / "lookup" / f"{source.stem}_probe.exr")
        generated = pipeline.generate(photo, out_dir=out / "lookup", wavelengths_nm=wavelengths,
                                      weights=args.weights, backend=args.backend, name=source.stem,
                                      progress=progress, lighting=photo_lighting, refine=args.refine,
                                      save_table=args.keep_lookups, model=args.model,
                                      latent_fit=args.latent_fit, every_band=args.every_band)
        info = generated.lookup
        _report_generated(generated, args, photo, photo_lighting)
    else:
        table_mod = import_module("specgen_addon.brdf.table")
        table = table_mod.BRDFTable.load(source)
        info = bake.bake_atlas(table, out / "lookup" / f"{source.stem}_lookup.exr",
                               wavelengths_nm=wavelengths, progress=progress)
    print(f"BRDF ready and baked in {time.perf_counter() - t0:.1f} s "
          f"({info.n_coeffs} basis coefficients, max error {info.rel_error:.1e})", flush=True)
    PHASE[0] = "scene set-up"

    import bpy
    import numpy as np

    render = import_module(f"{pkg.__name__}.ops.render")
    scene_mod = import_module(f"{pkg.__name__}.ops.scene")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene_mod.add_camera(scene)
    obj = scene_mod.add_mesh(scene, args.mesh)
    # the reference renderer's normalised map, as Cycles sees it, read from the run's private
    # temporary folder (Blender takes a backslash in a POSIX path for a separator); lookup/ keeps
    # a copy with --keep-lookups
    env_file = Path(tempfile.gettempdir()) / f"env_{args.env}.exr"
    _write_rgb_exr(env_file, env.rgb)
    if args.keep_lookups:
        _write_rgb_exr(out / "lookup" / env_file.name, env.rgb)
    scene_mod.set_world_environment(scene, env_file, 1.0)
    if args.sun:
        scene_mod.add_sun(scene, (-0.5, 0.6, 0.62), float(np.pi))
    obj.data.materials.clear()
    obj.data.materials.append(render.make_material(f"SpecGen {source.stem}", info))

    t0 = time.perf_counter()
    PHASE[0] = "spectral render"
    job = render.SpectralRenderJob(scene, target, samples=args.samples,
                                   resolution=(args.resolution, args.resolution),
                                   overwrite=args.overwrite, env_samples=args.env_samples,
                                   attributes={"specgenSource": str(source), "specgenMesh": args.mesh,
                                               "specgenEnvironment": args.env},
                                   warn=lambda m: print(m, file=sys.stderr))
    quiet = import_module("specgen_addon.common.quiet")
    with quiet.native_stdout_silenced(not args.verbose):  # Cycles' "Saved: ..." lines
        job.run(lambda f: interrupts.raise_if_stopped())  # between band renders
    print(f"spectral render ({args.bands} bands, {args.resolution}², {args.samples} spp) in "
          f"{time.perf_counter() - t0:.1f} s", flush=True)
    _report_outputs([target, target.with_name(target.stem + "_preview.png")], out / "lookup", before,
                    args.keep_lookups)
    return target


def run_scene(args) -> Path:
    """Full-scene spectral render of a .blend file (or the one already open), after giving the
    ``--apply`` photos' materials to their objects; one EXR per frame. Returns the last EXR."""
    pkg = load_package()
    from importlib import import_module

    def core(name: str):
        return import_module(f"specgen_addon.{name}")

    errors, spectra, scene_args = core("common.errors"), core("spectral.spectra"), core("cli.scene_args")
    import bpy

    # everything that can be checked without the scene, before opening it
    frames = scene_args.parse_frames(args.frames) if args.frames else None
    applies = [scene_args.parse_apply(a) for a in args.apply or ()]
    wavelengths = spectra.wavelength_grid(args.wl_min, args.wl_max, args.bands)
    photos = _check_photos(applies, args) if applies else []
    if args.scene:
        blend = Path(args.scene).resolve()
        if blend.suffix.lower() != ".blend" or not blend.is_file():
            raise errors.SpecGenError(f"{args.scene}: no such .blend file")
    elif bpy.data.filepath:
        blend = Path(bpy.data.filepath)
    else:
        raise errors.SpecGenError("--scene needs a .blend file (or start Blender with one)")
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise errors.SpecGenError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    if Path(bpy.data.filepath or "").resolve() != blend:
        quiet = core("common.quiet")
        try:
            with quiet.native_stdout_silenced(not args.verbose):  # Blender's "Read blend: ..." lines
                bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
        except RuntimeError as exc:
            reason = " ".join(str(exc).split()).removeprefix("Error: ")  # Blender's text ends in "\n"
            raise errors.SpecGenError(f"{blend}: cannot open the .blend file ({reason})") from None
    scene = bpy.context.scene
    scene_args.check_objects(applies, {o.name: o.type for o in scene.objects}, scene.name)
    targets = _scene_targets(scene, frames or [scene.frame_current], out, args.overwrite)
    renders = {f"frame {f}'s {what}": p for f, t in targets
               for what, p in (("render", t), ("preview", t.with_name(t.stem + "_preview.png")))}
    for spec, ns in zip(applies, photos):   # a circle preview named like a frame's render
        core("cli.photo_args").check_circle_preview(ns, spec.image, renders)
    stems = _lookup_stems(applies, out / "lookup", args.overwrite)
    before = _files_in(out / "lookup")

    interrupts = core("common.interrupts")
    render = import_module(f"{pkg.__name__}.ops.render")
    for spec, ns, stem in zip(applies, photos, stems):
        PHASE[0] = f"BRDF generation for {spec.object_name!r}"
        info = _generate(spec, ns, stem, out / "lookup", wavelengths, args)
        _assign(scene.objects[spec.object_name], render.make_material(f"SpecGen {stem}", info))
        print(f"material 'SpecGen {stem}' applied to {spec.object_name!r}", flush=True)
    if args.samples is not None:
        scene.cycles.samples = args.samples
    if args.resolution is not None:
        scene.render.resolution_x = scene.render.resolution_y = args.resolution
        scene.render.resolution_percentage = 100
    fullscene = import_module(f"{pkg.__name__}.ops.render_fullscene")
    settings = import_module(f"{pkg.__name__}.ops.render_settings")
    PHASE[0] = "spectral render"
    for frame, target in targets:
        scene.frame_set(frame)
        t0 = time.perf_counter()
        # Cycles' "Saved: ..." lines kept off stdout unless --verbose; the job's own lines are said
        with settings.QuickPreview(scene, args.preview), \
                core("common.quiet").native_stdout_silenced(not args.verbose) as say:
            job = fullscene.FullSceneRenderJob(scene, target, wavelengths, overwrite=args.overwrite,
                                               attributes={"specgenScene": str(blend),
                                                           "specgenFrame": str(frame)},
                                               warn=lambda m: print(m, file=sys.stderr),
                                               log=say, show_result=False)
            job.run(lambda f: interrupts.raise_if_stopped())  # between band renders
            h, w = job.spectral.shape[:2]
            spp = scene.cycles.samples
        print(f"full-scene spectral render of {blend.name}, frame {frame} ({args.bands} bands, "
              f"{w}x{h}, {spp} spp, {len(job.timings['render_s'])} Cycles renders) in "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        _report_outputs([target, target.with_name(target.stem + "_preview.png")])
    _report_outputs([], out / "lookup", before, args.keep_lookups)
    return targets[-1][1]


def _files_in(folder: Path) -> dict[Path, tuple | None]:
    """The files in ``folder`` now, each with its identity (none when the folder does not exist),
    so a file this run rewrote in place is told from one it left alone; hidden files are the
    run's own bookkeeping and are left out."""
    from importlib import import_module

    identity = import_module("specgen_addon.common.atomic_io").file_identity
    return {p: identity(p) for p in folder.iterdir()     # hidden: staging files, locks, kept copies
            if p.is_file() and not p.name.startswith(".")} if folder.is_dir() else {}


def _report_outputs(files: list[Path], lookup: Path | None = None, before: dict | None = None,
                    keep: bool = True) -> None:
    """Print each output written with its size; then either report the lookups this run wrote in
    ``lookup`` (``keep``: new or rewritten files; a replaced set's group files that this run did
    not write again are removed, so a kept set is one run's) or remove them (and the folder, left
    empty), so only the renders stay."""
    from importlib import import_module

    size_text = import_module("specgen_addon.brdf.formats.export").size_text
    for f in files:
        print(f"wrote {f} ({size_text(f.stat().st_size)})")
    if lookup is None:
        return
    before = before or {}
    now = _files_in(lookup)
    made = sorted(p for p, ident in now.items() if before.get(p) != ident)
    def set_of(path: Path) -> str | None:   # ``<stem>_lookup.gNN.exr`` → ``<stem>``
        return path.name.rsplit("_lookup.g", 1)[0] if "_lookup.g" in path.name and path.suffix == ".exr" else None

    sets = {set_of(p) for p in made} - {None}
    stale = [p for p in now if p not in made and set_of(p) in sets]
    for p in stale:            # group files of the set this run replaced, left from a larger basis
        p.unlink(missing_ok=True)
    if keep:
        total = sum(p.stat().st_size for p in made)
        print(f"kept {len(made)} lookup files in {lookup} ({size_text(total)})")
        return
    for p in made:
        p.unlink(missing_ok=True)
    if lookup.is_dir() and not any(lookup.iterdir()):
        lookup.rmdir()


def _check_photos(applies, args) -> list:
    """Each ``--apply`` photo: readable, holds a sphere, and its own options (over the command's)
    valid; returns each photo's options as a namespace."""
    from importlib import import_module

    preflight = import_module("specgen_addon.scale.preflight")
    photo_args = import_module("specgen_addon.cli.photo_args")
    preflight.check_weights_file(args.weights)
    photos = []
    previews: dict[str, Path] = {}   # no two photos write one circle preview
    for spec in applies:
        preflight.check_image_file(spec.image)
        ns = spec.namespace(args)
        with warnings.catch_warnings():  # keep a bad image to the one error line
            warnings.simplefilter("ignore")
            # no sphere / bad light / preview in the way ... -> one sentence
            photo_args.check_photo_args(ns, spec.image, previews, out_dir=Path(args.out))
        if ns.circle_preview is not None:
            previews[f"{spec.image.name}'s circle preview"] = Path(ns.circle_preview)
        photos.append(ns)
    return photos


def _scene_targets(scene, frames: list[int], out: Path, overwrite: bool) -> list[tuple[int, Path]]:
    """``(frame, <scene>_<camera>_fNNNN.exr)`` for each frame; refuses existing outputs (unless
    ``overwrite``) and frames without a camera, before any work."""
    from importlib import import_module

    pkg = load_package()
    errors = import_module("specgen_addon.common.errors")
    naming = import_module(f"{pkg.__name__}.ops.naming")
    limits = import_module("specgen_addon.common.limits")
    targets = []
    current = scene.frame_current
    try:
        for frame in frames:
            scene.frame_set(frame)           # camera markers can switch the camera per frame
            if scene.camera is None:
                raise errors.SpecGenError(f"scene {scene.name!r} has no camera at frame {frame}")
            target = out / naming.render_output_name(scene.name, scene.camera.name, frame)
            for p in (target, target.with_name(target.stem + "_preview.png")):
                limits.check_name_length(p)
                limits.refuse_existing(p, overwrite)
            targets.append((frame, target))
    finally:
        scene.frame_set(current)
    return targets


def _lookup_stems(applies, lookup: Path, overwrite: bool) -> list[str]:
    """A distinct lookup name per photo (``photo``, ``photo.001`` …); existing lookups of those
    names are refused unless ``overwrite``."""
    from importlib import import_module

    pkg = load_package()
    naming = import_module(f"{pkg.__name__}.ops.naming")
    errors = import_module("specgen_addon.common.errors")
    stems: list[str] = []
    for spec in applies:
        stem = naming.unique_stem(naming.clean_stem(spec.image.name), lambda s: s in stems)
        found = naming.files_of(lookup, stem)
        if found and not overwrite:
            raise errors.OutputExistsError(f"{found[0]}: already exists (pass --overwrite to "
                                           "replace it)")
        stems.append(stem)
    return stems


def _generate(spec, ns, stem: str, lookup: Path, wavelengths, args):
    """Generate and bake one ``--apply`` photo's BRDF with its options ``ns`` (printing the circle
    used and what refinement reached)."""
    from importlib import import_module

    pipeline = import_module("specgen_addon.generate.pipeline")
    photo_args = import_module("specgen_addon.cli.photo_args")
    t0 = time.perf_counter()
    print(f"{spec.image.name}:", flush=True)
    photo, lighting = photo_args.photo_inputs(ns, spec.image, lookup / f"{stem}_probe.exr")
    generated = pipeline.generate(photo, out_dir=lookup, wavelengths_nm=wavelengths, weights=args.weights,
                                  backend=args.backend, name=stem, lighting=lighting,
                                  refine=ns.refine, model=ns.model, overwrite=args.overwrite,
                                  latent_fit=ns.latent_fit, every_band=args.every_band)
    info = generated.lookup
    _report_generated(generated, ns, photo, lighting)
    print(f"{spec.image.name}: BRDF generated and baked in {time.perf_counter() - t0:.1f} s",
          flush=True)
    return info


def _report_generated(generated, ns, photo, lighting) -> None:
    """What ``infer`` prints about a generated BRDF: the circle used (and its preview), the
    network's or the refined table's self-reproduction, a thin-film fit, the warnings."""
    from importlib import import_module

    photo_args = import_module("specgen_addon.cli.photo_args")
    cli_model = import_module("specgen_addon.cli.model")
    photo_args.print_photo_report(generated, ns, photo)
    if generated.film_fit is not None:
        print(cli_model.film_fit_summary(generated.film_fit, lighting.label), flush=True)
    photo_args.print_refinement(generated)


def _assign(obj, material) -> None:
    """``material`` in the object's active slot (other slots keep theirs), as Apply does."""
    if obj.material_slots:
        obj.material_slots[obj.active_material_index].material = material
    else:
        obj.data.materials.append(material)


def _write_rgb_exr(path: Path, rgb) -> None:
    from importlib import import_module

    image_io = import_module("specgen_addon.common.image_io")  # OpenEXR or OIIO
    image_io.write_exr(path, {c: rgb[..., i] for i, c in enumerate("RGB")}, overwrite=True)


#: What batch.py is doing, for the one-line message of a stopped run.
PHASE = ["input checks"]


def main(argv: list[str] | None = None) -> int:
    """Exit 0, 2 with one error line, or 130/143 on SIGINT/SIGTERM; new files removed on failure
    and temporary files (Cycles' OSL builds) kept in a folder removed on every exit path."""
    from importlib import import_module

    signed = import_module("specgen_addon.photo.photo_lighting").attach_signed_values   # --light -30,20
    args = build_parser().parse_args(signed(_script_argv(argv)))
    cli = import_module("specgen_addon.cli.app")
    interrupts = import_module("specgen_addon.common.interrupts")
    PHASE[0] = "input checks"
    with interrupts.private_tempdir("specgen_batch_"):
        return cli.run_guarded(lambda: f"batch.py {PHASE[0]}", lambda: run(args) and 0,
                               ([Path(args.out)], []), args.verbose, prog="batch.py: error")


if __name__ == "__main__":
    try:
        code = main()
    except KeyboardInterrupt:   # while loading, before the run's clean stop was in place
        print("cancelled: batch.py stopped by SIGINT while starting; nothing was written", file=sys.stderr)
        code = 130
    sys.stdout.flush()
    sys.exit(code)
