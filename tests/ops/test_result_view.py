"""The spectral result as Blender shows it: the scene's view transform through Blender's bundled
OpenColorIO config, the preview PNG and the "SpecGen Result" image.

Truths: Blender's own colour management (an image saved "as render" through the scene's view
settings) and Blender's own F12 picture of the same scene.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module, psnr  # after the bpy skip

fullscene = addon_module("ops.render_fullscene")
result_view = addon_module("ops.result_view")
render = addon_module("ops.render")
bake = addon_module("specgen_addon.bake.lookup")
demo = addon_module("ops.demo_scenes")
vt = addon_module("specgen_addon.render.view_transform")

from specgen_addon.spectral import spectra
from specgen_addon.bake.closure_fit import ggx_lobe
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

RGB_WL = spectra.wavelength_grid(380.0, 780.0, 21)
pytestmark = pytest.mark.blender


def _png_pixels(path: Path) -> np.ndarray:
    """8-bit PNG as display values in [0, 1] (H, W, 3), row 0 on top, no colour conversion."""
    img = bpy.data.images.load(str(path))
    try:
        img.colorspace_settings.name = "Non-Color"
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, 4)[::-1, :, :3].copy()
    finally:
        bpy.data.images.remove(img)


def _save_as_render(image, scene, path: Path) -> np.ndarray:
    """What Blender writes for ``image`` through the scene's colour management (8-bit PNG)."""
    im = scene.render.image_settings
    im.file_format, im.color_depth, im.color_mode = "PNG", "8", "RGB"
    image.save_render(str(path), scene=scene)
    return _png_pixels(path)


@pytest.mark.parametrize("view,look,exposure,gamma", [("AgX", "None", 0.0, 1.0),
                                                      ("Standard", "None", 0.0, 1.0),
                                                      ("AgX", "AgX - Punchy", 0.5, 1.2),
                                                      ("Filmic", "None", -0.5, 1.0)])
def test_view_transform_matches_blenders_own_colour_management(blank_scene, tmp_path, view, look, exposure, gamma):
    sc = bpy.context.scene
    vs = sc.view_settings
    vs.view_transform, vs.look, vs.exposure, vs.gamma = view, look, exposure, gamma
    rng = np.random.default_rng(1)
    linear = (rng.random((9, 14, 3)) ** 2 * 4.0).astype(np.float32)   # past 1: the tone curve matters
    img = result_view.show_result(linear, name="view test")
    blender = _save_as_render(img, sc, tmp_path / "b.png")
    ours = result_view.scene_view_transform(sc)(linear)
    assert np.abs(np.round(ours * 255) / 255 - blender).max() <= 1.5 / 255


def test_unknown_view_or_look_is_one_sentence():
    config = vt.find_config(bpy.utils.system_resource("DATAFILES", path="colormanagement"))
    paths = (result_view._bundled_site_packages(),)
    with pytest.raises(vt.ViewTransformError, match="view transform 'Nope'"):
        vt.ViewTransform(vt.ViewSettings(view="Nope"), config, paths)
    with pytest.raises(vt.ViewTransformError, match="look 'Nope'"):
        vt.ViewTransform(vt.ViewSettings(look="Nope"), config, paths)
    with pytest.raises(vt.ViewTransformError, match="config.ocio"):
        vt.find_config(Path("/nonexistent"))


@pytest.fixture(scope="module")
def white_material_info(tmp_path_factory):
    """A white SpecGen BRDF (flat 0.8 Lambert + faint GGX) baked at 21 bands."""
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.full(RGB_WL.size, 0.8 / np.pi) + ggx_lobe(wi, wo, 0.25)[:, None] * 0.04
    return bake.bake_atlas(BRDFTable.tabulate(fn, RGB_WL), tmp_path_factory.mktemp("w") / "w.exr")


def _object_mask(sc, obj, shape) -> np.ndarray:
    """Pixels inside the camera-space bounding rectangle of ``obj`` (grown by two pixels)."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    h, w = shape
    pts = [world_to_camera_view(sc, sc.camera, obj.matrix_world @ Vector(c)) for c in obj.bound_box]
    x0, x1 = min(p.x for p in pts) * w - 2, max(p.x for p in pts) * w + 2
    y0, y1 = (1 - max(p.y for p in pts)) * h - 2, (1 - min(p.y for p in pts)) * h + 2
    yy, xx = np.mgrid[:h, :w] + 0.5
    return (xx >= x0) & (xx <= x1) & (yy >= y0) & (yy <= y1)


@pytest.mark.slow
def test_preview_png_is_the_shown_result_and_matches_f12_in_the_scenes_view_transform(blank_scene,
        white_material_info, tmp_path):
    mat = render.make_material("SpecGen white", white_material_info)
    sc = demo.ordinary_scene(samples=128, size=(60, 40), specgen_material=mat)
    assert sc.view_settings.view_transform == "AgX"           # Blender's default
    # F12: Blender's own picture, saved through the scene's view transform
    bpy.ops.render.render(write_still=False, scene=sc.name)
    f12 = _save_as_render(bpy.data.images["Render Result"], sc, tmp_path / "f12.png")

    job = fullscene.FullSceneRenderJob(sc, tmp_path / "s.exr", RGB_WL)
    job.run()
    preview = _png_pixels(tmp_path / "s_preview.png")
    shown = _save_as_render(job.result_image, sc, tmp_path / "shown.png")
    assert job.result_image.name == result_view.RESULT_IMAGE
    assert np.abs(shown - preview).max() <= 1.5 / 255         # the image in Blender = the PNG

    keep = ~_object_mask(sc, bpy.data.objects["SpecGen"], f12.shape[:2])
    assert 0.2 < keep.mean() < 0.98
    score = psnr(preview[keep], f12[keep])
    linear = spectra.spectral_to_linear_srgb(job.spectral, RGB_WL)
    plain = psnr(spectra.srgb_encode(np.clip(linear, 0.0, 1.0))[keep], f12[keep])
    print(f"preview vs F12 (AgX, non-SpecGen pixels): {score:.1f} dB; plain sRGB curve {plain:.1f} dB")
    assert score >= 40.0, score
    assert plain < score                                     # the plain sRGB curve is not F12's
