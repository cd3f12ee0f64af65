"""The photo's blur, modelled on the rendered side of the refinement's fit.

A photo's sphere is blurred: a camera's pixels integrate light over their area, lenses spread it,
and the pipeline's crop resamples a sphere that lies off the pixel grid bilinearly
(:mod:`specgen_addon.photo.sphere_image`). The refinement's operator renders point-sampled pixels. Fitted
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

from specgen_addon.photo.ndimage_np import gaussian_matrix

#: Blur widths (Gaussian σ, canonical-crop pixels) the refinement chooses among. Two bilinear
#: resamplings half a pixel off the grid blur by σ ≈ 0.71.
BLUR_CANDIDATES_PX = (0.0, 0.35, 0.5, 0.7, 1.0, 1.4)
#: Where :func:`search_blur`'s walk starts: σ = 0.5 px, between a sharp render and a resampled photo.
WALK_START = 2
#: Rows whose blurred neighbourhood reaches outside the observed sphere by more than this fraction
#: of its weight are left out of the fit (their true neighbours, the rim, are not observed).
INSIDE_WEIGHT = 0.98


#: Output rows per band of the blur's matrix products: a block sees only its rows ± the kernel's
#: radius, so the products skip the matrix's zeros (3–4× fewer operations than the full matrix).
_BAND_ROWS = 32


def _banded_product(matrix: np.ndarray, img: np.ndarray, axis: int, radius: int) -> np.ndarray:
    """``matrix`` applied along ``axis`` of a C-contiguous array, band by band: each block of
    output rows reads only its input rows ± ``radius`` (the matrix is zero beyond)."""
    shape = img.shape
    x = img.reshape(int(np.prod(shape[:axis], dtype=np.int64)), shape[axis], -1)   # (outer, n, inner)
    out = np.empty_like(x)
    n = shape[axis]
    for start in range(0, n, _BAND_ROWS):
        stop = min(start + _BAND_ROWS, n)
        lo, hi = max(start - radius, 0), min(stop + radius, n)
        np.matmul(matrix[start:stop, lo:hi], x[:, lo:hi], out=out[:, start:stop])
    return out.reshape(shape)


def gaussian_blur_stack(img: np.ndarray, sigma_px: float, truncate: float = 4.0,
                        dtype: type = np.float64) -> np.ndarray:
    """(H, W, C) stack of images blurred in H and W by a Gaussian of ``sigma_px`` pixels, zeros
    beyond the edge: ``scipy.ndimage.gaussian_filter(img, (σ, σ, 0), mode="constant")`` to
    rounding (the same truncated kernel), computed as banded matrix products, which numpy's BLAS
    runs on every core (numpy only, as in a stock Blender). ``dtype`` float32 halves the memory
    traffic and the products' time (the refinement's blur search: relative rounding 10⁻⁷,
    far below the photo's noise)."""
    img = np.ascontiguousarray(img, dtype=dtype)
    if sigma_px <= 0:
        return img.copy()
    radius = int(truncate * sigma_px + 0.5)
    for axis in (0, 1):
        matrix = gaussian_matrix(img.shape[axis], float(sigma_px), "constant", truncate).astype(dtype)
        img = _banded_product(matrix, img, axis, radius)
    return img


def blur_image(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H, W, C) image blurred by a Gaussian of ``sigma_px`` pixels (a copy; unchanged at 0)."""
    img = np.asarray(img, dtype=np.float64)
    if sigma_px <= 0:
        return img
    return gaussian_blur_stack(img, sigma_px)


def blur_rows(shape: tuple[int, int], pixel_ids: np.ndarray, sigma_px: float
              ) -> Callable[[np.ndarray], np.ndarray]:
    """Rows (P, ...) of the observed pixels ``pixel_ids`` of an (H, W) image → the same rows of
    their image blurred by a Gaussian of ``sigma_px`` (unobserved pixels count as 0)."""
    if sigma_px <= 0:
        return lambda rows: rows

    def blur(rows: np.ndarray) -> np.ndarray:
        return gather_rows(gaussian_blur_stack(embed_rows(shape, pixel_ids, rows), sigma_px),
                           pixel_ids).reshape(rows.shape)

    return blur


def embed_rows(shape: tuple[int, int], pixel_ids: np.ndarray, rows: np.ndarray,
               dtype: type = np.float64) -> np.ndarray:
    """Rows (P, ...) of the observed pixels → an (H, W, C) stack, zeros at the other pixels."""
    h, w = shape
    flat = rows.reshape(rows.shape[0], -1)
    img = np.zeros((h * w, flat.shape[1]), dtype=dtype)
    img[pixel_ids] = flat
    return img.reshape(h, w, -1)


def gather_rows(img: np.ndarray, pixel_ids: np.ndarray) -> np.ndarray:
    """An (H, W, C) stack's rows (len(pixel_ids), C) at the flat pixel indices ``pixel_ids``."""
    return img.reshape(-1, img.shape[-1])[pixel_ids]


def rows_inside(shape: tuple[int, int], pixel_ids: np.ndarray, sigma_px: float,
                excluded: np.ndarray) -> np.ndarray:
    """Mask (P,) of the rows that a blur of ``sigma_px`` keeps inside the observed pixels and away
    from the ``excluded`` ones (clipped: their true value is unknown, and blurring spreads it)."""
    blur = blur_rows(shape, pixel_ids, sigma_px)
    ones = blur(np.ones((pixel_ids.size, 1)))[:, 0]
    spread = blur(excluded.astype(np.float64)[:, None])[:, 0]
    return (ones >= INSIDE_WEIGHT) & (spread < 1e-3) & ~excluded


def search_blur(residual: Callable[[int], float], n: int, how: str = "walk", start: int = WALK_START) -> int:
    """Index of the blur candidate (0 … n − 1) with the smallest ``residual(k)``.

    ``"all"`` evaluates every candidate. ``"walk"`` evaluates ``start`` and steps towards the smaller
    neighbour (the larger σ first) until the residual stops falling: the residual of the blur's
    fit has one minimum over σ (the blur's likelihood), so the walk lands on it after 3–4
    evaluations of six; ties keep the smaller σ, as ``"all"`` does. Each candidate is evaluated at
    most once."""
    if how == "all":
        values = [residual(k) for k in range(n)]
        return int(np.argmin(values))
    if how != "walk":
        raise ValueError(f"unknown blur search {how!r}")
    seen: dict[int, float] = {}

    def cost(k: int) -> float:
        if k not in seen:
            seen[k] = residual(k)
        return seen[k]

    i = min(max(start, 0), n - 1)
    for step in (1, -1):
        if 0 <= i + step < n and cost(i + step) < cost(i):
            while 0 <= i + step < n and cost(i + step) < cost(i):
                i += step
            break
    return i
