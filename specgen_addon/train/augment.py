"""Input augmentations of the training images that the lighting mix does not cover.

A user's sphere is found and cropped by :mod:`specgen_addon.input_image`, which centres it to a
fraction of a pixel, never exactly; the corpus renders are centred exactly. The thirteenth session
measured what that costs a network trained on exact centring: a diagonal shift of one canonical
pixel (half a network pixel) loses 9 dB (docs/model.md). :func:`jitter_position` shows the network
the sphere a fraction of a pixel off centre, as a real crop leaves it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import shift as nd_shift


def shift_image(img: np.ndarray, dy_px: float, dx_px: float) -> np.ndarray:
    """``(C, S, S)`` image moved by (dy, dx) pixels: bilinear, edge pixels repeated outside."""
    out = nd_shift(np.asarray(img, dtype=np.float32), (0.0, dy_px, dx_px), order=1, mode="nearest")
    return np.ascontiguousarray(out, dtype=np.float32)


def jitter_position(img: np.ndarray, rng: np.random.Generator, max_shift_px: float) -> np.ndarray:
    """The image moved by a shift drawn uniformly in [−max, max]² network pixels."""
    dy, dx = rng.uniform(-max_shift_px, max_shift_px, size=2)
    return shift_image(img, float(dy), float(dx))
