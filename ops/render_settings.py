"""The scene's render settings as the Full Scene mode uses them: the quick preview, the time
estimate before a render, and band renders that Esc stops inside the render.

* :class:`QuickPreview`: 25 % resolution, at most 16 samples, no denoising, for one spectral render
  only (everything is put back afterwards).
* :func:`measure_cost` / :func:`estimate`: two tiny test renders of the scene as it is give the
  cost per render and per pixel-sample on this machine, and with adaptive sampling a third one the
  share of samples it takes (:mod:`specgen_addon.render.cycles_time_estimate`).
* :func:`band_render`: one Cycles render of a band group. From the panel it is started as Blender's
  own render job (``INVOKE_DEFAULT``), so the interface keeps running and Esc (or the status bar's
  cancel button) stops Cycles mid-render; Blender's ``render_cancel`` handler then tells the job,
  which writes nothing. Headless (and in ``execute``) it is the ordinary blocking render.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator

import bpy

from specgen_addon.bake import scene_uplift as uplift
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.render.cycles_time_estimate import RenderCost, fit_cost, format_duration

from .render import SavedAttributes, specgen_materials

PREVIEW_PERCENT = 25
PREVIEW_SAMPLES = 16
#: Test renders of the estimate: about this many pixels, at these two sample counts.
TEST_PIXELS = 16384
TEST_SAMPLES = (1, 8)
#: Seconds the adaptive-sampling test render may take at most (with all samples taken).
ADAPTIVE_TEST_S = 12.0
#: Polls (timer ticks) a started render job may take to show up as running.
START_POLLS = 50


class _Settings(SavedAttributes):
    def __init__(self, scene: bpy.types.Scene):
        self.scene = scene
        self.saved: list[tuple[object, str, object]] = []

    def __enter__(self) -> _Settings:
        return self

    def __exit__(self, *exc) -> None:
        self._restore_attributes()


class QuickPreview(_Settings):
    """25 % resolution, at most 16 samples, denoising off, while the context is open."""

    def __init__(self, scene: bpy.types.Scene, enabled: bool = True):
        super().__init__(scene)
        self.enabled = enabled

    def __enter__(self) -> QuickPreview:
        if self.enabled:
            r, c = self.scene.render, self.scene.cycles
            self._set(r, "resolution_percentage", min(r.resolution_percentage, PREVIEW_PERCENT))
            self._set(c, "samples", min(c.samples, PREVIEW_SAMPLES))
            self._set(c, "use_denoising", False)
        return self


class InteractiveRender(_Settings):
    """While band renders run as Blender render jobs: no render window pops up for them (they are
    false-colour band groups) and the scene is locked against edits."""

    def __enter__(self) -> InteractiveRender:
        self._set(bpy.context.preferences.view, "render_display_type", "NONE")
        self._set(self.scene.render, "use_lock_interface", True)
        return self


def render_size(scene: bpy.types.Scene) -> tuple[int, int]:
    """Width and height in pixels of the scene's render (resolution × percentage)."""
    r = scene.render
    f = r.resolution_percentage / 100.0
    return max(1, int(r.resolution_x * f)), max(1, int(r.resolution_y * f))


def planned_renders(scene: bpy.types.Scene, bands: int, exact_direct: bool = True) -> int:
    """Cycles renders of a Full Scene job: one per band group, twice when the direct light on
    SpecGen surfaces is recomputed exactly, plus that exact render."""
    groups = len(uplift.band_groups(bands))
    if exact_direct and specgen_materials(scene):
        return 2 * groups + 1
    return groups


def _timed_render(scene: bpy.types.Scene) -> float:
    t = time.perf_counter()
    bpy.ops.render.render(write_still=False, scene=scene.name)
    return time.perf_counter() - t


def denoised_renders(scene: bpy.types.Scene, bands: int, exact_direct: bool = True) -> int:
    """Cycles renders of a Full Scene job that run the scene's denoiser: the band groups and, with
    SpecGen surfaces, their direct-light pass (the exact render does not denoise)."""
    if not scene.cycles.use_denoising:
        return 0
    groups = len(uplift.band_groups(bands))
    return 2 * groups if exact_direct and specgen_materials(scene) else groups


def measure_cost(scene: bpy.types.Scene) -> RenderCost:
    """Cost model of the scene from tiny test renders (a few seconds for simple scenes): two at
    fixed samples for the overhead and the rate; with adaptive sampling on, one at the scene's
    own samples for the share adaptive sampling takes; with denoising on, two one-sample renders
    with the scene's denoiser at two sizes for its cost."""
    w, h = render_size(scene)
    scale = min(1.0, math.sqrt(TEST_PIXELS / (w * h)))
    r, c = scene.render, scene.cycles
    samples, adaptive, percent = c.samples, c.use_adaptive_sampling, r.resolution_percentage
    denoise = c.use_denoising
    with _Settings(scene) as s:
        s._set(r, "engine", "CYCLES")
        s._set(r, "resolution_percentage", max(1, int(percent * scale)))
        s._set(r, "use_persistent_data", False)
        s._set(r, "use_compositing", False)
        s._set(c, "use_denoising", False)
        s._set(c, "use_adaptive_sampling", False)
        s._set(c, "samples", TEST_SAMPLES[0])
        _timed_render(scene)                      # kernels and caches warm, as in the real job
        t1 = _timed_render(scene)
        c.samples = TEST_SAMPLES[1]
        t2 = _timed_render(scene)
        tw, th = render_size(scene)
        cost = fit_cost(tw * th, TEST_SAMPLES, (t1, t2))
        if denoise:
            c.use_denoising, c.samples = True, 1
            test_percent = r.resolution_percentage
            sizes, times = [], []
            for p in (max(1, test_percent // 2), test_percent):  # a quarter of the pixels, then all
                r.resolution_percentage = p
                if not sizes:
                    _timed_render(scene)           # the denoiser loaded, as in the real job
                times.append(_timed_render(scene))
                sizes.append(render_size(scene)[0] * render_size(scene)[1])
            if sizes[0] != sizes[1]:
                cost = cost.with_denoising(tuple(sizes), tuple(times))
            c.use_denoising = False
        if adaptive and samples > TEST_SAMPLES[1]:
            # as many pixels as fit ADAPTIVE_TEST_S at all samples (at least a 16-pixel square)
            pixels = max(256.0, ADAPTIVE_TEST_S / (cost.rate_s * samples))
            r.resolution_percentage = max(1, min(percent, int(percent * math.sqrt(pixels / (w * h)))))
            c.use_adaptive_sampling, c.samples = True, samples
            t3 = _timed_render(scene)
            aw, ah = render_size(scene)
            cost = cost.with_adaptive(aw * ah, samples, t3)
    return cost


def estimate(scene: bpy.types.Scene, bands: int, cost: RenderCost) -> tuple[float, str]:
    """Seconds of the Full Scene job with the scene's current settings, and one line saying so."""
    w, h = render_size(scene)
    n = planned_renders(scene, bands)
    samples = scene.cycles.samples
    denoised = denoised_renders(scene, bands)
    seconds = cost.predict(n, w * h, samples, denoised)
    extra = ""
    if denoised:
        extra = f", denoising {denoised} of them" + (
            f" (~{format_duration(cost.denoise_s(w * h))} each)" if cost.denoise_rate_s > 0 else
            " (not timed)")
    if cost.sample_fraction < 1.0:
        extra += f", adaptive sampling taking ~{100 * cost.sample_fraction:.0f} % of the samples"
    return seconds, (f"about {format_duration(seconds)}: {n} Cycles renders of {w}×{h} at "
                     f"{samples} samples{extra}")


def band_render(scene: bpy.types.Scene, layer: str | None, interactive: bool) -> Iterator[None]:
    """Render ``layer`` of ``scene`` once (None: every layer in use); as a cancellable render job
    when ``interactive`` and a window exists (yields ``None`` while it runs), else blocking.
    Raises Cancelled if the user stopped the render."""
    which = {"write_still": False, "scene": scene.name} | ({} if layer is None else {"layer": layer})
    if not interactive or bpy.app.background:
        bpy.ops.render.render(**which)
        return
    yield from render_job(lambda: bpy.ops.render.render("INVOKE_DEFAULT", **which))


def render_job(start: Callable[[], set[str]]) -> Iterator[None]:
    """Run ``start`` (which starts Blender's render job) and yield until Blender's
    ``render_complete`` or ``render_cancel`` handler fires (or the job ends without either);
    raises Cancelled when the render was cancelled."""
    state: dict[str, str] = {}

    def complete(*_args) -> None:
        state.setdefault("end", "complete")

    def cancel(*_args) -> None:
        state.setdefault("end", "cancel")

    handlers = bpy.app.handlers
    handlers.render_complete.append(complete)
    handlers.render_cancel.append(cancel)
    try:
        started = start()
        if "CANCELLED" in started and "end" not in state:
            raise SpecGenError("Blender did not start the band render (is another render running?)")
        seen_running, polls = False, 0
        while "end" not in state:
            running = bpy.app.is_job_running("RENDER")
            if (seen_running or polls > START_POLLS) and not running:
                break                              # ended (or never ran) without a handler call
            seen_running, polls = seen_running or running, polls + 1
            yield None
        if state.get("end") == "cancel":
            raise Cancelled("spectral render cancelled inside a band render; nothing was written")
    finally:
        for lst, fn in ((handlers.render_complete, complete), (handlers.render_cancel, cancel)):
            if fn in lst:
                lst.remove(fn)
