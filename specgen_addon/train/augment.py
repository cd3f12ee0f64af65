"""Input augmentations of the training images that the lighting mix does not cover.

The corpus renders are framed exactly: the sphere's outline on the pixel grid, its outline pixels
point-sampled. A user's sphere lies off the grid, and :mod:`specgen_addon.photo.sphere_image` finds it to
a fraction of a pixel and resamples it; the resampling blurs the image a little and the outline
pixels mix with the background. Measurements show what that costs a network trained on exact
framing (docs/model-card.md, lab/notebook/resampled-network.md, ``evaluate --input-shift``).

* :func:`jitter_framing` moves and scales the sphere by up to the old whole-pixel crop's error.
* :func:`displaced_input` moves an image by a fraction of a pixel inside a black border (an
  off-grid sphere, as in a photograph).
* :func:`offgrid_photo_crop` hands the network what the pipeline makes of a photo whose sphere
  lies off the grid: the canonical image moved by a random fraction of a pixel (bilinear, black
  around it), then cropped by the pipeline's own resampler with the sphere finder's measured error.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import affine_transform
from scipy.ndimage import shift as nd_shift
from specgen_addon.photo.sphere_image import _resample_circle


def reframe(img: np.ndarray, dy_px: float, dx_px: float, scale: float = 1.0) -> np.ndarray:
    """``(C, S, S)`` image scaled by ``scale`` about its centre, then moved by (dy, dx) pixels:
    bilinear, black outside (the background of a cropped input)."""
    img = np.asarray(img, dtype=np.float32)
    s = img.shape[-1]
    c = (s - 1) / 2.0
    # output pixel o samples the input at c + (o − c − shift) / scale
    matrix = np.diag([1.0, 1.0 / scale, 1.0 / scale])
    offset = np.array([0.0, c - (c + dy_px) / scale, c - (c + dx_px) / scale])
    out = affine_transform(img, matrix, offset=offset, order=1, mode="constant", cval=0.0)
    return np.ascontiguousarray(out, dtype=np.float32)


def jitter_framing(img: np.ndarray, rng: np.random.Generator, max_shift_px: float,
                   max_scale: float = 0.0) -> np.ndarray:
    """The image moved by a shift uniform in [−max, max]² network pixels and, when ``max_scale``
    > 0, scaled by a factor uniform in [1 − max_scale, 1 + max_scale]."""
    dy, dx = rng.uniform(-max_shift_px, max_shift_px, size=2)
    scale = 1.0 + rng.uniform(-max_scale, max_scale) if max_scale > 0 else 1.0
    return reframe(img, float(dy), float(dx), float(scale))


def displaced_input(image: np.ndarray, shift_px: float | tuple[float, float],
                    border_px: int = 16) -> np.ndarray:
    """``image`` (H×W×C) inside a black border of ``border_px``, moved by ``shift_px`` pixels right
    and down, or by (down, right) pixels given a pair (bilinear): a sphere that sits off the pixel
    grid, as in a photograph."""
    dy, dx = (shift_px, shift_px) if np.isscalar(shift_px) else shift_px
    b = border_px
    padded = np.pad(np.asarray(image, dtype=np.float64), ((b, b), (b, b), (0, 0)))
    return nd_shift(padded, (dy, dx, 0.0), order=1, mode="constant", cval=0.0).astype(np.float32)


def offgrid_photo_crop(img: np.ndarray, rng: np.random.Generator, finder_error_px: float) -> np.ndarray:
    """``(C, S, S)`` canonical input as the pipeline passes on a photo of it moved by a fraction of
    a pixel (uniform in [0, 1)² pixels, bilinear): found with a Gaussian error of ``finder_error_px``
    (standard deviation, each of centre x, y and radius) and resampled by
    :func:`specgen_addon.photo.sphere_image._resample_circle`."""
    img = np.asarray(img, dtype=np.float32)
    s = img.shape[-1]
    border = 4
    dy, dx = rng.uniform(0.0, 1.0, size=2)
    ex, ey, er = rng.normal(0.0, finder_error_px, size=3) if finder_error_px > 0 else (0.0, 0.0, 0.0)
    photo = displaced_input(img.transpose(1, 2, 0), (dy, dx), border_px=border)
    centre = s / 2.0 + border
    out = _resample_circle(photo, centre + dx + ex, centre + dy + ey, s / 2.0 + er, s)
    return np.ascontiguousarray(out.transpose(2, 0, 1), dtype=np.float32)
