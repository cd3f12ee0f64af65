"""Antialiased bilinear resampling of an image to the network's square input, in numpy.

The triangle-filter weights of ``torch.nn.functional.interpolate(mode="bilinear", antialias=True,
align_corners=False)`` (and PIL's BILINEAR) as a matrix, so the onnxruntime path, the encoder's
fixed down-sampling and the training data share one implementation and none needs torch.
"""

from __future__ import annotations

import numpy as np

from specgen_addon.common.errors import ImageInputError


def aa_bilinear_weights(n_in: int, n_out: int) -> np.ndarray:
    """Matrix ``(n_out, n_in)`` of antialiased bilinear (triangle-filter) resampling.

    The same weights as ``torch.nn.functional.interpolate(mode="bilinear", antialias=True,
    align_corners=False)`` (and PIL's BILINEAR): the triangle support widens by the scale factor
    when shrinking. Written in numpy so the onnxruntime path needs no torch.
    """
    scale = n_in / n_out
    support = scale if scale > 1.0 else 1.0
    inv = 1.0 / scale if scale > 1.0 else 1.0
    w = np.zeros((n_out, n_in), dtype=np.float64)
    for i in range(n_out):
        center = scale * (i + 0.5)
        lo = max(int(center - support + 0.5), 0)
        hi = min(int(center + support + 0.5), n_in)
        j = np.arange(lo, hi)
        k = np.clip(1.0 - np.abs((j - center + 0.5) * inv), 0.0, None)
        if k.sum() > 0:
            w[i, lo:hi] = k / k.sum()
    return w


def resample_square(arr: np.ndarray, size: int) -> np.ndarray:
    """Antialiased bilinear resample of an H×W×3 linear image to ``(3, size, size)`` float32."""
    arr = np.asarray(arr, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ImageInputError(f"expected an H×W×3 RGB image, got shape {arr.shape}")
    chw = np.ascontiguousarray(arr.transpose(2, 0, 1))
    if chw.shape[1:] == (size, size):
        return chw
    wy = aa_bilinear_weights(chw.shape[1], size).astype(np.float32)
    wx = aa_bilinear_weights(chw.shape[2], size).astype(np.float32)
    return np.ascontiguousarray((wy @ chw) @ wx.T, dtype=np.float32)   # separable: rows, then columns
