"""Blender's colour management for the spectral preview, through its bundled OpenColorIO config.

Blender shows a render through the scene's *view transform* (AgX by default), *look*, exposure and
gamma, all defined by the OpenColorIO config it ships (``datafiles/colormanagement/config.ocio``)
and applied by OpenColorIO. Running the same config through PyOpenColorIO (bundled with Blender)
turns the spectral render's linear sRGB (Blender's scene-linear space, ``Linear Rec.709``) into the
display values F12 would show for the same pixels; the preview PNG is written from those.

The pipeline follows Blender's own display transform: exposure (``2^exposure``, scene linear),
then the display/view transform with the look, then the display gamma (``x^(1/gamma)``). Curve
mapping and white balance of the view settings are not reproduced (:attr:`ViewSettings.unsupported`
names them so that a caller can warn).

No ``bpy``: the config path and the settings are passed in (:mod:`ops` reads them from the scene).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import SpecGenError

#: Blender's scene-linear colour space (the linear sRGB of the spectral EXR's RGB channels).
SCENE_LINEAR = "Linear Rec.709"
CONFIG_NAME = "config.ocio"


class ViewTransformError(SpecGenError):
    """The colour-managed preview cannot be made (no OpenColorIO, no config, unknown view)."""


@dataclass(frozen=True)
class ViewSettings:
    """A scene's display and view settings as Blender stores them (``scene.display_settings`` and
    ``scene.view_settings``); ``look`` is Blender's identifier (``"None"`` or e.g.
    ``"AgX - Punchy"``); ``exposure`` in stops."""

    display: str = "sRGB"
    view: str = "AgX"
    look: str = "None"
    exposure: float = 0.0
    gamma: float = 1.0
    unsupported: tuple[str, ...] = field(default=())

    def label(self) -> str:
        look = "" if self.look in ("", "None") else f", look {self.look}"
        exp = "" if self.exposure == 0.0 else f", exposure {self.exposure:+g}"
        gam = "" if self.gamma == 1.0 else f", gamma {self.gamma:g}"
        return f"{self.view} ({self.display}{look}{exp}{gam})"


def _ocio(extra_paths: tuple[str, ...] = ()):
    """PyOpenColorIO, looked for on ``sys.path`` and then in ``extra_paths`` (Blender's bundled
    site-packages, which the bpy module does not put on the path)."""
    try:
        import PyOpenColorIO
        return PyOpenColorIO
    except ImportError:
        pass
    for path in extra_paths:
        if path and os.path.isdir(os.path.join(path, "PyOpenColorIO")) and path not in sys.path:
            sys.path.append(path)
            try:
                import PyOpenColorIO
                return PyOpenColorIO
            except ImportError:
                continue
    raise ViewTransformError("PyOpenColorIO is not available (it ships with Blender), so the "
                             "preview cannot use Blender's view transform")


def find_config(colormanagement_dir: str | os.PathLike | None) -> Path:
    """Blender's ``config.ocio`` in ``colormanagement_dir`` (``bpy.utils.system_resource(
    'DATAFILES', path='colormanagement')``), or the one named by ``$OCIO`` as Blender honours it."""
    candidates = []
    if os.environ.get("OCIO"):
        candidates.append(Path(os.environ["OCIO"]))
    if colormanagement_dir:
        candidates.append(Path(colormanagement_dir) / CONFIG_NAME)
    for path in candidates:
        if path.is_file():
            return path
    raise ViewTransformError("Blender's colour-management config (config.ocio) was not found")


class ViewTransform:
    """Scene-linear Rec.709 → display values in ``settings`` (one OpenColorIO CPU processor)."""

    def __init__(self, settings: ViewSettings, config: str | os.PathLike,
                 ocio_paths: tuple[str, ...] = ()):
        oc = _ocio(ocio_paths)
        self.settings = settings
        try:
            cfg = oc.Config.CreateFromFile(str(config))
        except oc.Exception as exc:  # OpenColorIO's own exception type
            raise ViewTransformError(f"{config}: not a readable OpenColorIO config ({exc})") from None
        if settings.display not in list(cfg.getDisplays()):
            raise ViewTransformError(f"display {settings.display!r} is not in Blender's colour config")
        if settings.view not in list(cfg.getViews(settings.display)):
            raise ViewTransformError(f"view transform {settings.view!r} is not in Blender's colour "
                                     f"config for display {settings.display!r}")
        look = "" if settings.look in ("", "None") else settings.look
        if look and cfg.getLook(look) is None:
            raise ViewTransformError(f"look {look!r} is not in Blender's colour config")
        dvt = oc.DisplayViewTransform(src=SCENE_LINEAR, display=settings.display, view=settings.view)
        pipe = oc.LegacyViewingPipeline()
        pipe.setDisplayViewTransform(dvt)
        if look:
            pipe.setLooksOverrideEnabled(True)
            pipe.setLooksOverride(look)
        if settings.exposure != 0.0:
            g = float(2.0 ** settings.exposure)
            pipe.setLinearCC(oc.MatrixTransform([g, 0, 0, 0, 0, g, 0, 0, 0, 0, g, 0, 0, 0, 0, 1]))
        if settings.gamma != 1.0:
            e = 1.0 / float(settings.gamma)
            pipe.setDisplayCC(oc.ExponentTransform([e, e, e, 1.0]))
        try:
            self._cpu = pipe.getProcessor(cfg).getDefaultCPUProcessor()
        except oc.Exception as exc:
            raise ViewTransformError(f"view transform {settings.label()} failed to build ({exc})") from None

    def __call__(self, linear_rgb: np.ndarray) -> np.ndarray:
        """Display-encoded RGB (H, W, 3) in [0, 1] of scene-linear Rec.709 ``linear_rgb``."""
        rgb = np.ascontiguousarray(np.asarray(linear_rgb, dtype=np.float32)[..., :3]).copy()
        shape = rgb.shape
        flat = rgb.reshape(-1, 3)
        self._cpu.applyRGB(flat)
        return np.clip(flat.reshape(shape), 0.0, 1.0)


def to_display(linear_rgb: np.ndarray, settings: ViewSettings, config: str | os.PathLike,
               ocio_paths: tuple[str, ...] = ()) -> np.ndarray:
    """One-shot :class:`ViewTransform`: display values in [0, 1] of scene-linear ``linear_rgb``."""
    return ViewTransform(settings, config, ocio_paths)(linear_rgb)
