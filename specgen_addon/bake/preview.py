"""A preview sphere of a generated BRDF, rendered from its table with numpy (no Cycles).

The sphere of the canonical input (:mod:`specgen_addon.photo.sphere_image`: orthographic unit sphere, D65
key light of irradiance π from the upper left front) plus a dimmer fill light from the camera, so
the panel shows at a glance the colour and gloss the table encodes. Rendered with the reference
renderer (:func:`specgen_addon.render.render_spectral`), spectra → linear sRGB through the CIE 1931
CMFs, exposure 0.5 as the inputs, written as an 8-bit sRGB PNG.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from specgen_addon.photo.sphere_image import EXPOSURE, KEY_LIGHT_DIRECTION, KEY_LIGHT_IRRADIANCE
from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
from specgen_addon.render.spectral_exr import write_preview_png

PREVIEW_SIZE = 96
FILL_IRRADIANCE = 0.3 * np.pi


def preview_rgb(table, size: int = PREVIEW_SIZE) -> np.ndarray:
    """Linear sRGB (size, size, 3) of ``table`` (a spectral :class:`BRDFTable`) on the preview sphere."""
    lights = [DistantLight(KEY_LIGHT_DIRECTION, KEY_LIGHT_IRRADIANCE), DistantLight((0.0, 0.0, 1.0), FILL_IRRADIANCE)]
    result = render_spectral(table, sphere_geometry(size), lights=lights, wavelengths_nm=table.wavelengths)
    return np.clip(result.rgb, 0.0, None) * EXPOSURE


def write_preview(table, path: str | os.PathLike, size: int = PREVIEW_SIZE, overwrite: bool = True) -> Path:
    """Render :func:`preview_rgb` and write it as an sRGB PNG, atomically."""
    return write_preview_png(path, preview_rgb(table, size), overwrite=overwrite)
