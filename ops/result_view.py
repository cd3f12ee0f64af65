"""The spectral render's picture in Blender: the scene's view transform and a result image.

The spectral EXR's RGB channels are linear sRGB (Blender's scene-linear space). For the preview
PNG they go through the scene's own colour management (view transform, look, exposure, gamma) with
Blender's bundled OpenColorIO config (:mod:`specgen_addon.render.view_transform`), so the PNG shows what
F12 would show for the same pixels. In Blender the same linear pixels become a float image
datablock (:data:`RESULT_IMAGE`), which the Image Editor draws through that same transform.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

import bpy
import numpy as np

from specgen_addon.render.view_transform import (
    SCENE_LINEAR,
    ViewSettings,
    ViewTransform,
    ViewTransformError,
    find_config,
)

#: The image datablock that holds the last spectral render's linear sRGB.
RESULT_IMAGE = "SpecGen Result"


def _bundled_site_packages() -> str:
    """Blender's bundled Python modules (PyOpenColorIO, OpenImageIO): on ``sys.path`` in Blender,
    inside the wheel for the bpy module."""
    return os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib",
                        f"python{sys.version_info.major}.{sys.version_info.minor}", "site-packages")


def scene_view_settings(scene: bpy.types.Scene) -> ViewSettings:
    """The scene's display device, view transform, look, exposure and gamma."""
    vs = scene.view_settings
    unsupported = tuple(name for name, attr in (("curve mapping", "use_curve_mapping"),
                                                ("white balance", "use_white_balance"))
                        if getattr(vs, attr, False))
    return ViewSettings(display=scene.display_settings.display_device, view=vs.view_transform,
                        look=vs.look, exposure=float(vs.exposure), gamma=float(vs.gamma),
                        unsupported=unsupported)


def scene_view_transform(scene: bpy.types.Scene) -> ViewTransform:
    """The scene's view transform as an OpenColorIO processor (raises ViewTransformError)."""
    config = find_config(bpy.utils.system_resource("DATAFILES", path="colormanagement"))
    return ViewTransform(scene_view_settings(scene), config, (_bundled_site_packages(),))


def preview_transform(scene: bpy.types.Scene,
                      warn: Callable[[str], None]) -> Callable[[np.ndarray], np.ndarray] | None:
    """The scene's view transform for the preview PNG, or None (plain sRGB) with a warning."""
    try:
        view = scene_view_transform(scene)
    except ViewTransformError as exc:
        warn(f"SpecGen: {exc}; the preview PNG uses the plain sRGB curve instead")
        return None
    if view.settings.unsupported:
        warn(f"SpecGen: the preview PNG leaves out the scene's {' and '.join(view.settings.unsupported)}")
    return view


def show_result(linear_rgb: np.ndarray, alpha: np.ndarray | None = None,
                name: str = RESULT_IMAGE) -> bpy.types.Image:
    """Put linear sRGB (H, W, 3), row 0 on top, into the float image ``name`` (scene linear, drawn
    through the scene's view transform) and show it in every Image Editor that shows nothing or the Render Result (the last band
    render's false colours)."""
    h, w = linear_rgb.shape[:2]
    img = bpy.data.images.get(name)
    if img is not None and (tuple(img.size) != (w, h) or not img.is_float):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = SCENE_LINEAR
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = linear_rgb[..., :3]
    if alpha is not None:
        px[..., 3] = alpha
    img.pixels.foreach_set(px[::-1].ravel())            # Blender's rows run bottom to top
    img.update()
    wm = getattr(bpy.context, "window_manager", None)
    for window in (wm.windows if wm is not None else ()):
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                space = area.spaces.active
                if space.image is None or space.image.type == "RENDER_RESULT":
                    space.image = img   # the band renders' false colours give way to the result
                area.tag_redraw()
    return img
