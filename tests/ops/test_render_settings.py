"""Full Scene render settings as the panel uses them: the quick preview (applied for one render,
then restored), the time estimate from two test renders, the result image, and band renders run
as Blender render jobs whose cancel reaches the spectral job."""

from __future__ import annotations

import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module  # after the bpy skip

scene_mod = addon_module("ops.scene")
settings = addon_module("ops.render_settings")
result_view = addon_module("ops.result_view")
naming = addon_module("ops.naming")

from specgen_addon.common.errors import Cancelled
from specgen_addon.render.spectral_exr import read_spectral_exr

pytestmark = pytest.mark.blender


def _scene(tmp_path):
    """A plain scene (sphere, sun, grey world) at 64×48, 64 samples, denoising on."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    scene_mod.add_camera(sc)
    scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.3, -0.4, 0.8))
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 48, 100
    sc.cycles.samples, sc.cycles.use_denoising = 64, True
    sc.specgen.output_dir = str(tmp_path / "out")
    sc.specgen.bands = 4
    return sc


def test_quick_preview_renders_small_and_leaves_the_scene_settings_alone(tmp_path):
    PKG.register()
    try:
        sc = _scene(tmp_path)
        sc.specgen.quick_preview = True
        assert bpy.ops.specgen.render_stack(estimate_time=False) == {"FINISHED"}
        exr = tmp_path / "out" / naming.render_output_name(sc.name, sc.camera.name, sc.frame_current)
        image = read_spectral_exr(exr)
        assert image.values.shape == (12, 16, 4)                    # 25 % of 64×48
        assert image.header["specgenSamples"] == str(settings.PREVIEW_SAMPLES)
        assert (sc.render.resolution_percentage, sc.cycles.samples, sc.cycles.use_denoising) == \
            (100, 64, True)                                          # the scene's own, restored
        shown = bpy.data.images[result_view.RESULT_IMAGE]            # the result, shown in Blender
        assert tuple(shown.size) == (16, 12)
        px = np.empty(16 * 12 * 4, np.float32)
        shown.pixels.foreach_get(px)
        np.testing.assert_allclose(px.reshape(12, 16, 4)[::-1, :, :3], image.rgb, atol=1e-5)
    finally:
        PKG.unregister()


@pytest.mark.slow
def test_time_estimate_is_told_before_the_render_and_is_of_the_right_size(tmp_path):
    PKG.register()
    try:
        sc = _scene(tmp_path)
        sc.cycles.use_denoising = False
        assert bpy.ops.specgen.estimate_time() == {"FINISHED"}
        assert "2 Cycles renders of 64×48 at 64 samples" in sc.specgen.estimate   # 4 bands
        cost = settings.measure_cost(sc)
        predicted, _ = settings.estimate(sc, sc.specgen.bands, cost)
        t = time.perf_counter()
        assert bpy.ops.specgen.render_stack(estimate_time=False) == {"FINISHED"}
        took = time.perf_counter() - t
        print(f"estimated {predicted:.2f} s, rendered in {took:.2f} s")
        assert 0.2 < predicted / took < 5.0, (predicted, took)
    finally:
        PKG.unregister()


def test_render_job_waits_for_blenders_handlers_and_a_cancel_becomes_cancelled(blank_scene):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    scene_mod.add_camera(sc)
    sc.render.resolution_x = sc.render.resolution_y = 8
    sc.cycles.samples = 1
    before = (len(bpy.app.handlers.render_complete), len(bpy.app.handlers.render_cancel))
    # a real render job start (headless Blender runs it at once and calls render_complete)
    steps = list(settings.render_job(lambda: bpy.ops.render.render("INVOKE_DEFAULT",
                                                                   write_still=False)))
    assert steps == []

    def cancelled_start():             # what Blender does when Esc stops the render job
        for handler in list(bpy.app.handlers.render_cancel):
            handler(sc, None)
        return {"RUNNING_MODAL"}

    with pytest.raises(Cancelled, match="inside a band render"):
        list(settings.render_job(cancelled_start))
    assert (len(bpy.app.handlers.render_complete), len(bpy.app.handlers.render_cancel)) == before


def test_render_jobs_open_no_window_and_lock_the_scene_only_while_the_job_runs():
    prefs, sc = bpy.context.preferences.view, bpy.context.scene
    before = (prefs.render_display_type, sc.render.use_lock_interface)
    with settings.InteractiveRender(sc):
        assert (prefs.render_display_type, sc.render.use_lock_interface) == ("NONE", True)
    assert (prefs.render_display_type, sc.render.use_lock_interface) == before
