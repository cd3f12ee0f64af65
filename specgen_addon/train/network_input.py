"""Training renders as the network sees them: prepared exactly as inference prepares a user's
image (:func:`specgen_addon.photo.sphere_image.prepare_sphere_array`, then resampled)."""

from __future__ import annotations

import numpy as np

from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.resample import resample_square
from specgen_addon.spectral.spectra import srgb_decode, srgb_encode


def png_like(image: np.ndarray) -> np.ndarray:
    """What an 8-bit sRGB PNG of a linear render holds once read back: clipped to [0, 1], quantised."""
    q = np.round(srgb_encode(np.clip(image, 0.0, 1.0)) * 255.0) / 255.0
    return srgb_decode(q).astype(np.float32)


def network_inputs(images: list[np.ndarray], image_size: int, png_augment: bool = False) -> np.ndarray:
    """Renders -> network inputs ``(K, 3, S, S)`` exactly as inference prepares a user image.

    With ``png_augment`` each render also appears as its 8-bit PNG version (highlights clipped),
    so the network copes with PNG/JPEG inputs as well as linear EXR (2K images).
    """
    if png_augment:
        images = list(images) + [png_like(im) for im in images]
    return np.stack([resample_square(input_image.prepare_sphere_array(im), image_size) for im in images])
