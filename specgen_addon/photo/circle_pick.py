"""A ball's circle, or a white patch, from points a user picks on the photo (Blender's Image Editor).

The panel's *Pick in Image Editor* gathers clicks on the ball's silhouette in the photo, or on two
opposite corners of a neutral patch; this module turns them into the circle the command line's
``--circle X,Y,R`` takes (or the patch ``--white-patch X,Y,W,H`` takes): pixels of the file,
x right from the left edge, y down from the top edge (:func:`pixel_from_view`), the circle fitted
to three or more points by least squares on the algebraic distance (Kåsa 1976: the circle
``x² + y² + D x + E y + F = 0``, linear in D, E, F; exact through three points).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from specgen_addon.common.errors import ImageInputError

#: Fewest points that fix a circle.
MIN_POINTS = 3
#: Fewest points that fix a patch: two opposite corners.
MIN_PATCH_POINTS = 2


def pixel_from_view(u: float, v: float, width: int, height: int) -> tuple[float, float]:
    """An Image Editor view position (``u`` right, ``v`` up, 0–1 across the image) in the image's
    pixels as ``--circle`` counts them (x right from the left edge, y down from the top edge)."""
    return float(u) * width, (1.0 - float(v)) * height


def view_from_pixel(x: float, y: float, width: int, height: int) -> tuple[float, float]:
    """:func:`pixel_from_view` undone: pixels → the Image Editor's view position."""
    return float(x) / width, 1.0 - float(y) / height


def circle_through(points: Sequence[tuple[float, float]]) -> tuple[float, float, float]:
    """The circle (cx, cy, r in pixels) through ``points`` (x, y) on a ball's outline: exact for
    three, least squares (Kåsa 1976) for more. Fewer than three points, or points on one line,
    are refused in one sentence."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    if len(pts) < MIN_POINTS or not np.all(np.isfinite(pts)):
        raise ImageInputError(f"a circle needs at least {MIN_POINTS} points on the ball's outline, "
                              f"got {len(pts)}")
    centre = pts.mean(axis=0)
    scale = float(np.abs(pts - centre).max()) or 1.0
    p = (pts - centre) / scale                         # conditioned: about unit size
    a = np.column_stack([p[:, 0], p[:, 1], np.ones(len(p))])
    b = -(p ** 2).sum(axis=1)
    sol, _res, rank, sv = np.linalg.lstsq(a, b, rcond=None)
    if rank < 3 or sv[-1] < 1e-9 * sv[0]:
        raise ImageInputError("the points picked lie on one line: pick them around the ball's outline")
    d, e, f = sol
    cx, cy = -d / 2.0, -e / 2.0
    r2 = cx * cx + cy * cy - f
    if not r2 > 0:
        raise ImageInputError("the points picked fix no circle: pick them around the ball's outline")
    return (float(centre[0] + cx * scale), float(centre[1] + cy * scale), float(np.sqrt(r2) * scale))


def patch_through(points: Sequence[tuple[float, float]]) -> tuple[int, int, int, int]:
    """The white patch (x, y, w, h in whole pixels, as ``--white-patch`` takes it) spanning
    ``points`` (two opposite corners, or more); a patch under a pixel across is refused."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    if len(pts) < MIN_PATCH_POINTS or not np.all(np.isfinite(pts)):
        raise ImageInputError(f"a patch needs two opposite corners, got {len(pts)} point(s)")
    x0, y0 = np.floor(pts.min(axis=0)).astype(int)
    x1, y1 = np.ceil(pts.max(axis=0)).astype(int)
    if x1 - x0 < 2 or y1 - y0 < 2:
        raise ImageInputError("the corners picked span under two pixels: pick two opposite corners "
                              "of a neutral patch")
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)
