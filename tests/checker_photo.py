"""A synthetic photo with an X-Rite ColorChecker Classic in it: the 24 swatches drawn from
colour-science's reference values (4 rows of 6, black gaps, on a grey background), turned a few
degrees, next to the example sphere, the whole under a colour cast.

Import it by name (``from checker_photo import checker_photo``): tests/ is on the test path.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.common.image_io import write_exr
from specgen_addon.photo.colour_checker import reference_swatches
from specgen_addon.photo.read import read_photo

#: The photo's size (pixels, width × height) and the ball's circle in it (cx, cy, r).
WIDTH, HEIGHT = 640, 400
CIRCLE = (128.0, 200.0, 64.0)
#: The chart's centre (pixels), swatch pitch and black gap between swatches (pixels).
CHART_CENTRE, PITCH, GAP = (430.0, 200.0), 48.0, 8.0
#: A test that finds a chart skips where the command line's detector is not installed.
needs_detector = pytest.mark.skipif(importlib.util.find_spec("colour_checker_detection") is None,
                                    reason="colour-checker-detection (OpenCV) is not installed: the "
                                           "command line's colour checker cannot be found")


def draw_checker(img: np.ndarray, angle_deg: float = 4.0, centre: tuple[float, float] = CHART_CENTRE,
                 pitch: float = PITCH, gap: float = GAP) -> np.ndarray:
    """``img`` (H, W, 3, linear) with the chart drawn in about ``centre`` (pixels), turned
    ``angle_deg`` clockwise, its swatches ``pitch`` apart with black gaps ``gap`` wide."""
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    a = np.radians(angle_deg)
    dx, dy = xs - centre[0], ys - centre[1]
    u, v = dx * np.cos(a) + dy * np.sin(a), -dx * np.sin(a) + dy * np.cos(a)
    out = img.copy()
    out[(np.abs(u) < 3 * pitch + gap) & (np.abs(v) < 2 * pitch + gap)] = 0.02     # the chart's black frame
    col, row = np.floor(u / pitch + 3), np.floor(v / pitch + 2)
    fu, fv = u / pitch + 3 - col, v / pitch + 2 - row
    m = gap / 2 / pitch
    inside = (col >= 0) & (col < 6) & (row >= 0) & (row < 4) & (fu > m) & (fu < 1 - m) & (fv > m) & (fv < 1 - m)
    out[inside] = np.clip(reference_swatches(), 0.0, None)[(row * 6 + col)[inside].astype(int)]   # cyan is out of sRGB
    return out


def checker_photo(path: Path, cast=(1.0, 1.0, 1.0), repo: Path | None = None, chart: bool = True,
                  angle_deg: float = 4.0) -> Path:
    """Write the photo (a linear EXR): the example sphere at :data:`CIRCLE`, the chart beside it
    (``chart=False``: left out), on a mid-grey background, all multiplied by ``cast`` (R, G, B)."""
    repo = repo or Path(__file__).resolve().parents[1]
    img = np.full((HEIGHT, WIDTH, 3), 0.25)
    ball = read_photo(repo / "examples" / "sphere.png").rgb[..., :3]
    cx, cy, r = CIRCLE
    img[int(cy - r):int(cy + r), int(cx - r):int(cx + r)] = ball
    if chart:
        img = draw_checker(img, angle_deg)
    img = (img * np.asarray(cast, np.float64)).astype(np.float32)
    return write_exr(path, {c: img[..., i] for i, c in enumerate("RGB")})
