"""The photo's blur, modelled on the rendered side of the refinement's fit.

A photo's sphere is blurred: a camera's pixels integrate light over their area, lenses spread it,
and the pipeline's crop resamples a sphere that lies off the pixel grid bilinearly
(:mod:`specgen_addon.input_image`). The refinement's operator renders point-sampled pixels. Fitted
to a blurred photo, the correction broadens sharp highlights and dims grazing ones to match the
blur, and the table moves away from the material (docs/refinement.md, "Blur").

So the refinement fits ``photo ≈ G_σ ∗ render(θ)``: each design column (a photo of one basis
function) is blurred by a Gaussian ``G_σ``, and σ (pixels of the canonical crop) is the candidate
whose solve reproduces the photo best (the blur's maximum-likelihood value on a small grid). An
exactly framed render reproduces best at σ = 0, which leaves the fit as it was.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: Blur widths (Gaussian σ, canonical-crop pixels) the refinement chooses among. Two bilinear
#: resamplings half a pixel off the grid blur by σ ≈ 0.71.
BLUR_CANDIDATES_PX = (0.0, 0.35, 0.5, 0.7, 1.0, 1.4)
#: Rows whose blurred neighbourhood reaches outside the observed sphere by more than this fraction
#: of its weight are left out of the fit (their true neighbours, the rim, are not observed).
INSIDE_WEIGHT = 0.98


def _gaussian_filter():
    try:
        from scipy.ndimage import gaussian_filter
    except ImportError:
        from ..ndimage_np import gaussian_filter
    return gaussian_filter


def blur_image(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H, W, C) image blurred by a Gaussian of ``sigma_px`` pixels (a copy; unchanged at 0)."""
    img = np.asarray(img, dtype=np.float64)
    if sigma_px <= 0:
        return img
    return _gaussian_filter()(img, sigma=(sigma_px, sigma_px, 0), mode="constant")


def blur_rows(shape: tuple[int, int], pixel_ids: np.ndarray, sigma_px: float
              ) -> Callable[[np.ndarray], np.ndarray]:
    """Rows (P, ...) of the observed pixels ``pixel_ids`` of an (H, W) image → the same rows of
    their image blurred by a Gaussian of ``sigma_px`` (unobserved pixels count as 0)."""
    if sigma_px <= 0:
        return lambda rows: rows
    h, w = shape
    gaussian_filter = _gaussian_filter()

    def blur(rows: np.ndarray) -> np.ndarray:
        flat = rows.reshape(rows.shape[0], -1)
        img = np.zeros((h * w, flat.shape[1]))
        img[pixel_ids] = flat
        img = gaussian_filter(img.reshape(h, w, -1), sigma=(sigma_px, sigma_px, 0), mode="constant")
        return img.reshape(h * w, -1)[pixel_ids].reshape(rows.shape)

    return blur


def rows_inside(shape: tuple[int, int], pixel_ids: np.ndarray, sigma_px: float,
                excluded: np.ndarray) -> np.ndarray:
    """Mask (P,) of the rows that a blur of ``sigma_px`` keeps inside the observed pixels and away
    from the ``excluded`` ones (clipped: their true value is unknown, and blurring spreads it)."""
    blur = blur_rows(shape, pixel_ids, sigma_px)
    ones = blur(np.ones((pixel_ids.size, 1)))[:, 0]
    spread = blur(excluded.astype(np.float64)[:, None])[:, 0]
    return (ones >= INSIDE_WEIGHT) & (spread < 1e-3) & ~excluded
