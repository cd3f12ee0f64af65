"""Input augmentations of the training images that the lighting mix does not cover.

A user's sphere is found and cropped by :mod:`specgen_addon.input_image`, which snaps the crop to
whole pixels; the corpus renders are framed exactly. Off the pixel grid the crop comes out up to
half a pixel off centre and half a pixel (of a 64-pixel radius) too wide, and the thirteenth
session measured what that costs a network trained on exact framing: 6–8 dB (docs/model.md,
``evaluate --input-shift``). :func:`jitter_framing` shows the network the sphere moved and scaled
by such amounts, as a real crop leaves it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import affine_transform


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
