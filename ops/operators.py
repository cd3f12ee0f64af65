"""Operators of the SpecGen panel: Generate BRDF, Apply to selected objects, Render spectral stack,
Estimate render time.

The two long steps are modal: they show progress in the status bar and the window-manager progress
indicator, Esc cancels, and the UI keeps running. *Generate* runs the network and the bake on a
worker thread (bpy-free numerics); *Render* advances the render job one step per timer tick, each
band render running as Blender's own render job so that Esc stops it inside the render
(:func:`ops.render_settings.band_render`). Before a Full Scene render two tiny test renders give
a time estimate (reported), and the quick preview (25 %, 16 samples, no denoising) applies to that
render only. Both also have a blocking ``execute`` (used headless, e.g. by tests and scripts).
Failures reach the user through ``self.report`` as one line, never a traceback.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from specgen_addon.common.atomic_io import file_identity, make_output_dir
from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.spectral.spectra import wavelength_grid
from specgen_addon.bake import lookup as bake
from specgen_addon.generate.pipeline import generate
from specgen_addon.photo.image_checks import check_pixel_count
from specgen_addon.render.cycles_time_estimate import format_duration
from . import naming
from .photo_inputs import balanced_to_the_light, balances_to_the_light, lighting_job, photo_source
from .properties import output_dir
from .render_settings import PREVIEW_PERCENT, PREVIEW_SAMPLES, band_render
from .scene_lighting import ball_position
from .travel import load_image, owns_set, scene_atlas_json
from .reporting import check_generate_settings, check_render_settings, report_exception

TIMER_STEP_S = 0.1


def _image_input(settings):
    """The input image as a path (preferred: the core decodes files itself) or a linear array.

    An image whose pixels were edited (or that has no file) is read from Blender's pixels, decoded
    by the panel's *Encoding* as its file would be: 8-bit pixels as sRGB or linear, float pixels
    (linear in Blender) as they are. The image's Color Space setting plays no part either way."""
    img = settings.image
    if img is not None:
        path = bpy.path.abspath(img.filepath) if img.filepath else ""
        if path and os.path.isfile(path) and not img.is_dirty:
            return path
        w, h = img.size
        check_pixel_count(w, h, f"image {img.name!r}")   # before copying its pixels (16 bytes each here)
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        rgb = px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
        if not img.is_float and settings.photo.encoding != "linear":
            from specgen_addon.spectral.spectra import srgb_decode

            rgb = srgb_decode(rgb)
        return rgb
    if settings.image_path:
        path = bpy.path.abspath(settings.image_path)
        if not os.path.isfile(path):
            raise SpecGenError(f"{path}: input image not found")
        return path
    raise SpecGenError("choose an input image (datablock or file) first")


def _wavelengths(settings) -> np.ndarray:
    return wavelength_grid(settings.wl_min, settings.wl_max, settings.bands)


def _set_status(context, text: str | None) -> None:
    workspace = getattr(context, "workspace", None)
    if workspace is not None:
        workspace.status_text_set(text)
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class _Modal:
    """Timer, progress indicator and status text shared by the modal operators."""

    _timer = None
    label = "SpecGen"

    def _start(self, context) -> None:
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_STEP_S, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        context.scene.specgen.running = self.label
        self._progress(context, 0.0)

    def _progress(self, context, fraction: float) -> None:
        context.scene.specgen.progress = fraction
        context.window_manager.progress_update(int(100 * fraction))
        _set_status(context, f"{self.label}: {100 * fraction:.0f}%  (Esc to cancel)")

    def _finish(self, context) -> None:
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.scene.specgen.running = ""
        _set_status(context, None)


@dataclass
class GenerateRun:
    """What one Generate made: the baked lookup, the photo's lighting, what the run says about
    that lighting, and the circle preview written (or None)."""

    info: bake.AtlasInfo
    lighting: object
    notes: list[str]
    circle_png: Path | None = None


def generate_with_photo_lighting(args: dict, lighting, circle_png: Path | None = None,
                                 balance_to_light: bool = False, **kwargs) -> GenerateRun:
    """Make the photo's lighting (:func:`.photo_inputs.lighting_job`'s job: an estimate or a
    chrome ball take seconds), then generate and bake; runs on the worker thread, without bpy.
    Whatever it wrote is removed if any step fails or is cancelled."""
    from specgen_addon.common.atomic_io import make_dirs
    from specgen_addon.common.interrupts import OutputGuard
    from specgen_addon.photo.sphere_image import write_circle_preview

    # replacing a set: its files this run does not write again (the table with Export Table off,
    # a circle preview, a lookup group fewer) are the old run's, removed once the new set is made
    earlier = _file_stamps(args["out_dir"], args["name"]) if args["overwrite"] else {}
    with OutputGuard([args["out_dir"]]):
        make_dirs(Path(args["out_dir"]))
        photo_lighting, notes = lighting(args["image"])
        if balance_to_light:   # the white patch balanced to a white surface under the given light
            args = {**args, "image": balanced_to_the_light(args["image"], photo_lighting)}
        info = generate(**args, lighting=photo_lighting, backend=None, **kwargs).lookup
        if circle_png is not None and info.crop is not None and info.crop.circle is not None:
            write_circle_preview(circle_png, args["image"], info.crop.circle, overwrite=args["overwrite"])
        else:
            circle_png = None
    now = _file_stamps(args["out_dir"], args["name"]) if earlier else {}
    for path, stamp in earlier.items():
        if now.get(path) == stamp:          # not written again: the replaced run's
            path.unlink(missing_ok=True)
    return GenerateRun(info, photo_lighting, notes, circle_png)


def _file_stamps(out_dir, stem: str) -> dict[Path, tuple | None]:
    """The identity of each file of the set ``stem`` (:func:`~specgen_addon.common.atomic_io.file_identity`):
    every output is written to a new file and moved into place, so a file written again has another."""
    return {p: file_identity(p) for p in naming.files_of(out_dir, stem)}


class SPECGEN_OT_generate_brdf(_Modal, bpy.types.Operator):
    """Predict the spectral BRDF of the material in the input image and bake its lookup textures"""

    bl_idname = "specgen.generate_brdf"
    bl_label = "Generate BRDF"
    # one undo step: Ctrl-Z removes what Generate made (material, node group, preview image), and
    # nothing the user did before it
    bl_options = {"REGISTER", "UNDO"}
    label = "Generating BRDF"

    def _job_args(self, context) -> dict:
        s = context.scene.specgen
        check_generate_settings(s)
        weights = bpy.path.abspath(s.weights_path) if s.weights_path else None
        image = _image_input(s)
        out = output_dir(s)
        source = s.image.name if s.image is not None else bpy.path.basename(s.image_path)
        self._stem = naming.stem_for_generate(source, out, s.overwrite,
                                              [m.name for m in bpy.data.materials],
                                              [g.name for g in bpy.data.node_groups],
                                              owned=lambda stem: owns_set(out, stem))
        self._out = out
        self._lighting = lighting_job(s.photo, context.scene, out, self._stem, s.overwrite,
                                      ball_position(context))
        self._circle_png = naming.circle_png(out, self._stem) if s.photo.circle_preview else None
        self._balance = balances_to_the_light(s.photo)
        return dict(image=photo_source(s.photo, image), out_dir=out, wavelengths_nm=_wavelengths(s),
                    weights=weights, n_phi_d=int(s.lookup_resolution), tolerance=s.basis_tolerance,
                    name=self._stem, save_table=s.export_table, preview=True, refine=s.refine,
                    overwrite=s.overwrite, model=s.model)

    def _run(self, args: dict, **kwargs) -> GenerateRun:
        return generate_with_photo_lighting(args, self._lighting, self._circle_png, self._balance, **kwargs)

    def _done(self, context, run: GenerateRun) -> None:
        from .render import make_material

        s = context.scene.specgen
        info = run.info
        s.atlas_json = str(naming.lookup_json(self._out, self._stem))
        mat = make_material(naming.material_name(self._stem), info)
        mat["specgen_stem"] = self._stem
        png = naming.preview_png(self._out, self._stem)
        if png.is_file():
            name = naming.preview_name(self._stem)
            img = bpy.data.images.get(name)
            if img is not None:   # replaced (Replace Materials): read the new file afresh
                bpy.data.images.remove(img)
            img = load_image(png, name)
            img.use_fake_user = True   # only the material names it: kept when the .blend is saved
            mat["specgen_preview"] = img.name
        s.material = mat
        self._report_photo(s.photo, mat, run)
        ref, fit = info.refinement, info.film_fit
        s.refine_summary = "" if ref is None else (
            f"Photo match: {ref.after.text()}, network's lobe kept (within the renderer's sampling error)"
            if ref.within_noise and ref.improved else f"Photo match: {ref.after.text()} (network {ref.before.text()})")
        if fit is not None:
            note = fit.blur_note()
            blur = f", {note}" if note else ""
            s.refine_summary = f"Thin-film fit, photo match: {fit.reproduction.text()}{blur}"
        s.refine_residual = -1.0 if ref is None else ref.after.psnr_db
        for warning in ([] if ref is None else ref.warnings) + ([] if fit is None else fit.warnings):
            self.report({"WARNING"}, f"SpecGen: {warning}")
        self.report({"INFO"}, f"SpecGen: material {mat.name!r} generated, {info.n_coeffs} spectral "
                              f"basis coefficients (max error {info.rel_error:.1e})")

    def _report_photo(self, photo, mat, run: GenerateRun) -> None:
        """The lighting and the circle used, on the material, in the panel and in the reports."""
        lines = [f"photo lighting: {run.lighting.label}"]
        mat["specgen_lighting"] = run.lighting.label
        crop = run.info.crop
        if crop is not None:
            lines.append(crop.describe())
            mat["specgen_sphere"] = crop.describe()
        if run.circle_png is not None:
            lines.append(f"{run.circle_png}: the photo with the circle used")
        lines += run.notes
        photo.report = "\n".join(lines)
        for line in lines:
            if line.startswith("warning: "):
                self.report({"WARNING"}, f"SpecGen: {line.removeprefix('warning: ')}")
            else:
                self.report({"INFO"}, f"SpecGen: {line}")

    def execute(self, context):
        try:
            self._done(context, self._run(self._job_args(context)))
        except BaseException as exc:  # Ctrl-C in a headless run included: one sentence, no traceback
            return report_exception(self, exc, "BRDF generation")
        return {"FINISHED"}

    def invoke(self, context, event):
        try:
            args = self._job_args(context)
        except Exception as exc:
            return report_exception(self, exc, "BRDF generation")
        self._fraction = 0.0
        self._cancel = threading.Event()
        self._result: list = []

        def work() -> None:
            try:
                self._result.append(self._run(
                    args, progress=lambda f: setattr(self, "_fraction", f), cancel=self._cancel.is_set))
            except BaseException as exc:  # handed to the main thread, reported there
                self._result.append(exc)

        self._thread = threading.Thread(target=work, name="specgen-generate", daemon=True)
        self._thread.start()
        self._start(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._cancel.set()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        self._progress(context, self._fraction)
        if self._thread.is_alive():
            return {"RUNNING_MODAL"}
        self._finish(context)
        result = self._result[0] if self._result else SpecGenError("generation stopped unexpectedly")
        if isinstance(result, BaseException):
            return report_exception(self, result, "BRDF generation")
        try:
            self._done(context, result)
        except Exception as exc:
            return report_exception(self, exc, "BRDF generation")
        return {"FINISHED"}


class SPECGEN_OT_apply(bpy.types.Operator):
    """Give the selected objects a material that renders the generated spectral BRDF"""

    bl_idname = "specgen.apply"
    bl_label = "Apply to Selected"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        s = context.scene.specgen
        return s.material is not None or bool(s.atlas_json)

    def execute(self, context):
        from .render import make_material

        s = context.scene.specgen
        try:
            targets = [o for o in context.selected_objects if o.type in {"MESH", "CURVE", "SURFACE", "META", "FONT"}]
            if not targets:
                raise SpecGenError("select at least one mesh object")
            mat = s.material
            if mat is None:  # a lookup baked elsewhere (e.g. by batch.py): build its material
                info = bake.load_atlas_info(scene_atlas_json(s))
                mat = make_material(f"SpecGen {Path(info.path).stem}", info)
        except Exception as exc:
            return report_exception(self, exc, "Apply")
        for obj in targets:  # the active slot gets it; other slots keep their materials
            if obj.material_slots:
                obj.material_slots[obj.active_material_index].material = mat
            else:
                obj.data.materials.append(mat)
        self.report({"INFO"}, f"SpecGen: {mat.name!r} applied to {len(targets)} object(s)")
        return {"FINISHED"}


class SPECGEN_OT_render_stack(_Modal, bpy.types.Operator):
    """Render the scene's SpecGen materials per band with Cycles into a spectral OpenEXR"""

    bl_idname = "specgen.render_stack"
    bl_label = "Render Spectral Stack"
    bl_options = {"REGISTER"}
    label = "Rendering spectral stack"

    filename: bpy.props.StringProperty(name="File Name", default="", options={"SKIP_SAVE"},
                                       description="Name of the spectral EXR; empty: "
                                       "<scene>_<camera>_f<frame>.exr")
    estimate_time: bpy.props.BoolProperty(name="Estimate Time", default=True, options={"SKIP_SAVE"},
                                          description="Time two tiny test renders first and say "
                                          "how long the Full Scene render will take")

    def _job(self, context):
        from .render import SpectralRenderJob

        s, sc = context.scene.specgen, context.scene
        name = self.filename or naming.render_output_name(
            sc.name, sc.camera.name if sc.camera else None, sc.frame_current)
        check_render_settings(s, name)  # a plain .exr name: never outside the folder
        folder = make_output_dir(output_dir(s))
        if s.render_mode == "FULL_SCENE":
            from .render_fullscene import FullSceneRenderJob

            return FullSceneRenderJob(sc, folder / name, _wavelengths(s),
                                      overwrite=s.overwrite_outputs,
                                      warn=lambda msg: self.report({"WARNING"}, msg),
                                      log=lambda msg: self.report({"INFO"}, msg))
        res = s.resolution if not s.quick_preview else max(8, s.resolution * PREVIEW_PERCENT // 100)
        samples = s.samples if not s.quick_preview else min(s.samples, PREVIEW_SAMPLES)
        return SpectralRenderJob(sc, folder / name, samples=samples, resolution=(res, res),
                                 overwrite=s.overwrite_outputs, env_samples=s.env_samples,
                                 warn=lambda msg: self.report({"WARNING"}, msg))

    def _begin(self, context, interactive: bool):
        """The job, with the quick preview (and the render-job settings) applied until _end."""
        from .render_settings import InteractiveRender, QuickPreview

        sc, s = context.scene, context.scene.specgen
        job = self._job(context)
        self._contexts = [QuickPreview(sc, s.quick_preview and s.render_mode == "FULL_SCENE")]
        if interactive:
            self._contexts.append(InteractiveRender(sc))
        for ctx in self._contexts:
            ctx.__enter__()
        try:
            try:
                job._check_outputs()   # before any test render: a name taken is one sentence now
            except OutputExistsError as exc:
                raise OutputExistsError(str(exc).replace("pass overwrite", "turn on Replace "
                                                         "Outputs")) from None
            if s.render_mode == "FULL_SCENE":
                job._preflight()        # camera, view layer, band grid: before the test renders
                job.interactive = interactive
                if self.estimate_time:
                    self._estimate(context)
            elif interactive:
                # each Exact render as Blender's render job: Esc stops it inside the render
                job.render_call = lambda: band_render(sc, None, True)
        except BaseException:
            self._end()
            raise
        self._t0 = time.perf_counter()
        return job

    def _estimate(self, context) -> None:
        from .render_settings import estimate, measure_cost

        sc, s = context.scene, context.scene.specgen
        seconds, text = estimate(sc, s.bands, measure_cost(sc))
        self._estimated = seconds
        s.estimate = f"Last estimate: {text}"
        self.report({"INFO"}, f"SpecGen: Full Scene render, {text}")

    def _end(self) -> None:
        for ctx in reversed(getattr(self, "_contexts", [])):
            ctx.__exit__(None, None, None)
        self._contexts = []

    def _wrote(self, job) -> None:
        took = time.perf_counter() - self._t0
        est = getattr(self, "_estimated", None)
        guess = "" if est is None else f", estimated {format_duration(est)}"
        self.report({"INFO"}, f"SpecGen: wrote {job.output} in {format_duration(took)}{guess}")

    def execute(self, context):
        try:
            job = self._begin(context, interactive=False)
            try:
                job.run()
            finally:
                self._end()
        except BaseException as exc:  # Ctrl-C in a headless run included
            return report_exception(self, exc, "Spectral render")
        self._wrote(job)
        return {"FINISHED"}

    def invoke(self, context, event):
        try:
            self._job_obj = self._begin(context, interactive=True)
        except Exception as exc:
            return report_exception(self, exc, "Spectral render")
        self._steps = self._job_obj.steps()
        self._fraction = 0.0
        self._start(context)
        return {"RUNNING_MODAL"}

    def _finish(self, context) -> None:
        self._end()
        super()._finish(context)

    def modal(self, context, event):
        if event.type == "ESC":
            self._job_obj.cancel()
            if bpy.app.is_job_running("RENDER"):  # inside a band render: Blender's render job
                return {"PASS_THROUGH"}           # stops Cycles, its render_cancel ends the job
            self._steps.close()  # runs the job's cleanup; nothing was written
            self._finish(context)
            self.report({"WARNING"}, "SpecGen: render cancelled, nothing written")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            fraction = next(self._steps)  # at most one Cycles render (None: a render job runs)
        except StopIteration:
            self._finish(context)
            self._wrote(self._job_obj)
            return {"FINISHED"}
        except BaseException as exc:  # a render stopped by Esc inside it arrives as Cancelled
            self._finish(context)
            return report_exception(self, exc, "Spectral render")
        if fraction is not None:
            self._fraction = fraction
        self._progress(context, self._fraction)
        if self._fraction > 0.05:
            left = (time.perf_counter() - self._t0) * (1.0 - self._fraction) / self._fraction
            _set_status(context, f"{self.label}: {100 * self._fraction:.0f}%, about "
                                 f"{format_duration(left)} left  (Esc to cancel)")
        return {"RUNNING_MODAL"}


class SPECGEN_OT_estimate_time(bpy.types.Operator):
    """Time two tiny test renders of the scene and estimate its Full Scene spectral render"""

    bl_idname = "specgen.estimate_time"
    bl_label = "Estimate Render Time"
    bl_options = {"REGISTER"}

    def execute(self, context):
        from .render_settings import QuickPreview, estimate, measure_cost

        sc, s = context.scene, context.scene.specgen
        try:
            check_render_settings(s, "estimate.exr")
            with QuickPreview(sc, s.quick_preview):
                _, text = estimate(sc, s.bands, measure_cost(sc))
        except BaseException as exc:
            return report_exception(self, exc, "Time estimate")
        s.estimate = f"Estimate: {text}"
        self.report({"INFO"}, f"SpecGen: Full Scene render, {text}")
        return {"FINISHED"}


CLASSES = (SPECGEN_OT_generate_brdf, SPECGEN_OT_apply, SPECGEN_OT_render_stack,
           SPECGEN_OT_estimate_time)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
