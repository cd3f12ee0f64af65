"""Self-reproduction: how well a BRDF, rendered under the input's lighting, matches the photo.

Both images are divided by the photo's 99.9th percentile over the observed pixels (the
normalisation of :mod:`specgen_addon.render.metrics`). PSNR is the mean over R, G, B of
``10 log10(1 / MSE)`` (numpy, so it is available inside Blender). ΔE2000 is the mean CIEDE2000
difference over the observed pixels, from colour-science (linear sRGB → XYZ → CIELAB with the D65
white at the normalised level 1); it is ``None`` where colour-science is not installed (a stock
Blender).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.metrics import normalisation_scale


@dataclass(frozen=True)
class Reproduction:
    """RGB PSNR (dB) and mean ΔE2000 (``None`` without colour-science) of a render vs the photo."""

    psnr_db: float
    delta_e2000: float | None

    def text(self) -> str:
        de = "" if self.delta_e2000 is None else f", ΔE2000 {self.delta_e2000:.2f}"
        return f"{self.psnr_db:.1f} dB{de}"


def checked_photo(photo) -> np.ndarray:
    """The photo a fit reproduces as float64 (S, S, 3), refused with one sentence unless it is a
    square linear RGB sphere crop of finite values (refinement, latent fit, thin-film fit)."""
    photo = np.asarray(photo, dtype=np.float64)
    if photo.ndim != 3 or photo.shape[2] != 3 or photo.shape[0] != photo.shape[1]:
        raise SpecGenError(f"photo must be a square S×S×3 sphere crop, got {photo.shape}")
    if not np.all(np.isfinite(photo)):
        raise SpecGenError("photo holds NaN or Inf values")
    return photo


def photo_scale(photo_rows: np.ndarray) -> float:
    """The normalising level: :func:`specgen_addon.render.metrics.normalisation_scale` of the photo's
    observed pixels (its 99.9th percentile), or 1 for a black photo (nothing to normalise)."""
    try:
        return normalisation_scale(np.asarray(photo_rows, dtype=np.float64))
    except SpecGenError:
        return 1.0


def rgb_psnr(photo_rows: np.ndarray, render_rows: np.ndarray, scale: float | None = None) -> float:
    """Mean over channels of PSNR (dB) of observed-pixel rows (P, 3), normalised by ``scale``."""
    s = photo_scale(photo_rows) if scale is None else scale
    err = (np.asarray(render_rows, np.float64) - np.asarray(photo_rows, np.float64)) / s
    mse = np.mean(err * err, axis=0)
    return float(np.mean([math.inf if m == 0 else -10.0 * math.log10(m) for m in mse]))


def delta_e2000(photo_rows: np.ndarray, render_rows: np.ndarray, scale: float | None = None) -> float | None:
    """Mean CIEDE2000 (colour-science) between observed-pixel rows (P, 3) of linear sRGB."""
    try:
        import colour
    except ImportError:
        return None
    s = photo_scale(photo_rows) if scale is None else scale
    space = colour.RGB_COLOURSPACES["sRGB"]

    def lab(rows: np.ndarray) -> np.ndarray:
        xyz = colour.RGB_to_XYZ(np.clip(np.asarray(rows, np.float64) / s, 0.0, None), space,
                                illuminant=space.whitepoint)
        return colour.XYZ_to_Lab(xyz, space.whitepoint)

    return float(np.mean(colour.delta_E(lab(photo_rows), lab(render_rows), method="CIE 2000")))


def reproduction(photo_rows: np.ndarray, render_rows: np.ndarray) -> Reproduction:
    """PSNR and ΔE2000 of a render against the photo (observed-pixel rows)."""
    s = photo_scale(photo_rows)
    return Reproduction(rgb_psnr(photo_rows, render_rows, s), delta_e2000(photo_rows, render_rows, s))
