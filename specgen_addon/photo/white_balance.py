"""White balance from a neutral patch of the photo: a grey card, a white wall, a patch the user picks.

A von Kries (diagonal) correction: each linear channel is scaled so that the patch's mean colour
becomes the colour a neutral surface has under the light the run assumes (``target``: neutral for
D65 light, warmer under a 3200 K lamp), its luminance kept. The patch is given in the file's
pixels, top-left corner and size; saturated pixels in it are left out, and a patch that is
outside the photo, all saturated or black is refused in one sentence. Numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from specgen_addon.common.errors import ImageInputError

#: Linear-sRGB luminance weights (Rec. 709 / sRGB primaries, D65).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def parse_patch(text: str) -> tuple[float, float, float, float]:
    """``"X,Y,W,H"`` (pixels; x right, y down from the top-left corner) → (x, y, w, h)."""
    try:
        values = tuple(float(v) for v in str(text).replace(" ", "").split(","))
    except ValueError:
        values = ()
    if len(values) != 4 or not all(math.isfinite(v) for v in values) or values[2] < 1 or values[3] < 1:
        raise ImageInputError(f"--white-patch takes X,Y,W,H in pixels (top-left corner, width and height "
                              f"at least 1), got {text!r}")
    return values  # type: ignore[return-value]


def patch_gains(rgb: np.ndarray, saturated: np.ndarray | None, patch: tuple[float, float, float, float],
                target: tuple[float, float, float] | None = None, scale: float = 1.0) -> np.ndarray:
    """Per-channel gains (3,) that make the patch of ``rgb`` (H, W, 3+, linear) the colour of
    ``target`` (linear RGB, default neutral) at the patch's own luminance. ``scale`` is the read
    image's width over the file's (the patch is in the file's pixels)."""
    x, y, w, h = (v * scale for v in patch)
    height, width = rgb.shape[:2]
    x0, y0 = math.floor(x), math.floor(y)
    x1, y1 = max(x0 + 1, math.ceil(x + w)), max(y0 + 1, math.ceil(y + h))
    if x0 < 0 or y0 < 0 or x1 > width or y1 > height:
        raise ImageInputError(f"the white patch {patch} does not lie in the "
                              f"{round(width / scale)}×{round(height / scale)} photo")
    px = np.asarray(rgb[y0:y1, x0:x1, :3], np.float64).reshape(-1, 3)
    if saturated is not None:
        px = px[~np.asarray(saturated[y0:y1, x0:x1]).reshape(-1)]
    if px.shape[0] == 0:
        raise ImageInputError("the white patch is all saturated: pick a patch exposed below clipping")
    mean = px.mean(axis=0)
    if not np.all(mean > 0):
        raise ImageInputError(f"the white patch is black in a channel (mean {np.round(mean, 5).tolist()}): "
                              "pick a lit neutral patch")
    goal = np.ones(3) if target is None else np.asarray(target, np.float64)
    if goal.shape != (3,) or not np.all(goal > 0):
        raise ImageInputError(f"the white balance target must be a positive RGB colour, got {target}")
    goal = goal * (mean @ LUMINANCE) / (goal @ LUMINANCE)
    return goal / mean


def describe(gains: np.ndarray) -> str:
    """The gains for a run's report."""
    return "white balance from the patch: gains R {:.3f} G {:.3f} B {:.3f}".format(*gains)
