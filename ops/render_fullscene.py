"""Full-scene spectral render: Cycles path-traces the whole scene, three bands per render.

Everything Cycles computes for a pixel is per colour channel, so with every RGB input of the
scene replaced by its values at three wavelengths (:class:`.scene_convert.SceneConversion`), one
ordinary Cycles render yields three monochromatic renders in R, G, B: all objects, lights, the
world, global illumination, motion blur, depth of field and volumes, exactly as Cycles renders
them. ``ceil(Λ/3)`` renders make the stack; ``use_persistent_data`` keeps the scene (and its BVH)
in Cycles between them, so only shaders and lights are re-synced.

Output follows the scene: camera, frame, resolution and percentage, pixel aspect, border,
view layer (the active one), film transparency (alpha channel), samples and the rest of the
Cycles settings; the band grid comes from the panel. The stack is written as a Fichet et al.
(2021) spectral EXR (with ``A``; its RGB is the CIE 1931 projection, D65 white, linear sRGB)
plus a PNG preview through the scene's view transform (:mod:`.result_view`), and the linear sRGB
is shown in Blender as the image ``SpecGen Result``.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Generator, Iterator

import bpy
import numpy as np

from specgen_addon.bake import scene_uplift as uplift
from specgen_addon.common.errors import SpecGenError
from .exact_direct import (DirectOnlySettings, compose, exact_direct_steps, has_specgen, report_fit,
                           world_light)
from .render import RenderJobOutputs, SavedAttributes, specgen_materials
from .render_settings import band_render
from .result_view import preview_transform, show_result
from .scene_convert import SceneConversion


def _render_layer(scene: bpy.types.Scene) -> bpy.types.ViewLayer:
    vl = bpy.context.view_layer
    if vl is not None and vl.id_data == scene and vl.use:
        return vl
    for layer in scene.view_layers:
        if layer.use:
            return layer
    raise SpecGenError(f"scene {scene.name!r} has no view layer enabled for rendering")


def _read_combined(path: Path) -> np.ndarray:
    """RGBA (H, W, 4) float32 of an EXR written by ``save_render``, row 0 on top (OpenEXR, or
    Blender's bundled OpenImageIO in a stock Blender)."""
    from specgen_addon.common.image_io import read_exr

    ch, _ = read_exr(path)
    names = sorted(ch)

    def pick(c: str):
        return next((ch[n] for n in names if n == c or n.endswith("." + c)), None)

    rgb = [pick(c) for c in "RGB"]
    alpha = pick("A")
    return np.stack(rgb + [np.ones_like(rgb[0]) if alpha is None else alpha], -1)


class _RenderSettings(SavedAttributes):
    """Cycles + linear EXR output for the band renders; restored on exit."""

    def __init__(self, scene: bpy.types.Scene):
        self.scene = scene
        self.saved: list[tuple[object, str, object]] = []

    def __enter__(self) -> "_RenderSettings":
        sc = self.scene
        self._set(sc.render, "engine", "CYCLES")
        self._set(sc.render, "use_persistent_data", True)   # BVH built once for all band groups
        self._set(sc.render, "use_compositing", False)       # the raw Combined pass, linear
        self._set(sc.render, "use_sequencer", False)
        uses_osl = any(n.type == "SCRIPT" for m in bpy.data.materials if m.node_tree
                       for n in m.node_tree.nodes if not m.get("specgen"))
        self._set(sc.cycles, "shading_system", uses_osl)    # SpecGen's stack is native: SVM
        im = sc.render.image_settings
        for attr, value in (("media_type", "IMAGE"), ("file_format", "OPEN_EXR"),
                            ("color_depth", "32"), ("color_mode", "RGBA"), ("exr_codec", "NONE")):
            if hasattr(im, attr):
                self._set(im, attr, value)
        return self

    def __exit__(self, *exc) -> None:
        self._restore_attributes()


@dataclass
class FullSceneRenderJob(RenderJobOutputs):
    """Render the whole ``scene`` per band group and write a spectral EXR (+ PNG preview).

    Iterate :meth:`steps` (one Cycles render per step, yields progress in [0, 1], or None while
    an ``interactive`` band render runs as Blender's render job) or call :meth:`run`;
    :meth:`cancel` stops before the next render, and a render job cancelled by the user stops the
    job inside that render; either way the scene is restored and nothing is written.
    """

    scene: bpy.types.Scene
    output: Path | None
    wavelengths_nm: np.ndarray
    overwrite: bool = False
    preview_png: bool = True
    attributes: dict = field(default_factory=dict)
    warn: Callable[[str], None] = print
    log: Callable[[str], None] = print
    #: direct light on SpecGen surfaces from the exact lookups (:mod:`.exact_direct`)
    exact_direct: bool = True
    show_result: bool = True   # a render to a file also fills the image "SpecGen Result"
    interactive: bool = False  # band renders as Blender render jobs that Esc stops (the panel)
    result_image: object = field(default=None, init=False)
    spectral: np.ndarray | None = field(default=None, init=False)
    alpha: np.ndarray | None = field(default=None, init=False)
    fit_errors: dict = field(default_factory=dict, init=False)
    timings: dict = field(default_factory=dict, init=False)
    _cancelled: bool = field(default=False, init=False)

    def _preflight(self) -> None:
        self.wavelengths_nm = np.asarray(self.wavelengths_nm, np.float64).reshape(-1)
        if self.wavelengths_nm.size < 1 or np.any(np.diff(self.wavelengths_nm) <= 0):
            raise SpecGenError("the band grid must be one or more increasing wavelengths (nm)")
        self._check_outputs()
        if self.scene.camera is None:
            raise SpecGenError(f"scene {self.scene.name!r} has no camera")
        _render_layer(self.scene)
        if self.exact_direct:
            self._check_lookups()

    def _check_lookups(self) -> None:
        """The scene's SpecGen materials' lookups, as the exact render checks them: missing ones
        baked again from the compact material (beside them or packed); still missing, or another
        Generate's, the render refuses in the same sentence rather than show the stand-in alone."""
        from .travel import check_lookups

        check_lookups([m for m in specgen_materials(self.scene) if "specgen_atlas_groups" in m], self.warn)

    def steps(self) -> Iterator[float]:
        """Generator: convert the scene, one Cycles render per band group, restore, write."""
        t0 = time.perf_counter()
        self._preflight()
        wl = self.wavelengths_nm
        groups = uplift.band_groups(wl.size)
        layer = _render_layer(self.scene).name
        work = Path(tempfile.mkdtemp(prefix="specgen_fullscene_"))
        conversion = SceneConversion(self.scene, wl, self.warn)
        images, direct = [], []
        exact = self.exact_direct and has_specgen(self.scene, self.warn)
        world = exact and world_light(self.scene, self.warn)
        try:
            with _RenderSettings(self.scene):
                conversion.prepare()
                shown = {m.name for m in specgen_materials(self.scene)}   # on render-visible objects
                if not shown:
                    self.warn("SpecGen: no render-visible object uses a SpecGen material, so the render "
                              "shows none (Apply one to an object first)")
                for mat, fit in conversion.specgen_fits():  # ΔE2000 of the closures (None: not measured)
                    if mat.name in shown:
                        self.fit_errors[mat.name] = report_fit(mat.name, fit, exact, self.warn, self.log)
                self.timings["convert_s"] = time.perf_counter() - t0
                yield 0.02
                t_render = []
                passes = [("group", images)] + ([("direct", direct)] if exact else [])
                n_renders, done = len(passes) * len(groups), 0
                for tag, out in passes:  # the whole scene, then the closures' direct light
                    with DirectOnlySettings(self.scene, world) if tag == "direct" else nullcontext():
                        for g, group in enumerate(groups):
                            self._check()
                            conversion.set_group(group)
                            t = time.perf_counter()
                            yield from band_render(self.scene, layer, self.interactive)
                            t_render.append(time.perf_counter() - t)
                            path = work / f"{tag}{g:02d}.exr"
                            bpy.data.images["Render Result"].save_render(str(path), scene=self.scene)
                            out.append(_read_combined(path))
                            done += 1
                            yield 0.02 + (0.8 if exact else 0.93) * done / n_renders
                self.timings["render_s"] = t_render
        finally:
            conversion.restore()
            shutil.rmtree(work, ignore_errors=True)
        self._check()
        stack = np.stack(images)                                  # (G, H, W, 4)
        self.alpha = stack[0, :, :, 3].copy()
        self.spectral = uplift.unpack_groups(stack[..., :3], wl.size)
        if exact:
            t = time.perf_counter()
            exact_light = yield from self._exact_steps(wl, world)
            self.timings["exact_s"] = time.perf_counter() - t
            self._check()
            if exact_light is not None:
                closure_light = uplift.unpack_groups(np.stack(direct)[..., :3], wl.size)
                self.spectral = compose(self.spectral, closure_light, exact_light)
            exact = exact_light is not None
            yield 0.95
        from specgen_addon.render.spectral_exr import (linear_srgb_preview, write_preview_png,
                                                write_spectral_exr)

        rgb = linear_srgb_preview(self.spectral, wl)
        outs = self._outputs()
        if outs is not None:
            view = preview_transform(self.scene, self.warn) if self.preview_png else None
            shown = "plain sRGB curve" if view is None else view.settings.label()
            attrs = {"specgenRenderer": "SpecGen full-scene Cycles (3 bands per render)",
                     "specgenPreviewTransform": "RGB = CIE 1931 2deg projection, D65 white, linear "
                                                f"sRGB (Blender's scene linear); PNG: {shown}",
                     "specgenSamples": str(self.scene.cycles.samples),
                     # whether SpecGen surfaces' direct light is the exact lookups' or the closures'
                     "specgenExactDirect": "yes" if exact else "no",
                     **{k: str(v) for k, v in self.attributes.items()}}
            write_spectral_exr(outs[0], self.spectral, wl, overwrite=self.overwrite, rgb=rgb,
                               attributes=attrs, alpha=self.alpha)
            if self.preview_png:
                write_preview_png(outs[1], rgb, overwrite=self.overwrite, view=view)
        if self.show_result and outs is not None:   # a render to a file: the user's
            self.result_image = show_result(rgb, self.alpha)
        self.timings["total_s"] = time.perf_counter() - t0
        yield 1.0

    def _exact_steps(self, wl: np.ndarray, world: bool) -> Generator[float | None, None, np.ndarray | None]:
        """The exact direct light (:func:`.exact_direct.exact_direct_steps`), its progress mapped
        to 0.82–0.95 of the job's, a cancel checked after each of its renders."""
        steps = exact_direct_steps(self.scene, wl, self.spectral.shape[:2], self.warn, world,
                                   self.interactive)
        try:
            while True:
                try:
                    fraction = next(steps)
                except StopIteration as done:
                    return done.value
                self._check()
                yield None if fraction is None else 0.82 + 0.13 * fraction
        finally:
            steps.close()   # on a cancel: the shader's sockets and the held-out slots put back

    def run(self, progress: Callable[[float], None] | None = None) -> np.ndarray:
        """Run all steps; returns the spectral stack (H, W, Λ)."""
        for fraction in self.steps():
            if progress is not None and fraction is not None:   # None: a render job runs
                progress(fraction)
        return self.spectral
