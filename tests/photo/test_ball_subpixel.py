"""The ball in a photo found to a fraction of a pixel without a mask
(specgen_addon.photo.sphere_detect.find_ball).

Truths: an analytic ball (a Lambertian sphere lit by one distant light plus a little ambient,
each pixel the mean of 8×8 samples, on a dark ground with a stand touching it from below), whose
centre and radius are known to any precision; and the shared real photos, whose silhouette is
measured without a model (the half-rise circle of the brightest-of-twelve image, scipy as oracle).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from specgen_addon.photo.sphere_detect import find_ball
from specgen_addon.photo.sphere_image import mask_circle

SUPERSAMPLE = 8
PHOTOS = Path(__file__).resolve().parents[3] / "shared" / "data" / "photos" / "psm_gray_chrome"


def _lit_ball(shape: tuple[int, int], cx: float, cy: float, r: float, light: tuple[float, float, float],
              ambient: float = 0.02) -> np.ndarray:
    """(H, W, 3) photo of a Lambertian ball (albedo 0.8) lit from ``light`` (x right, y up, z to the
    camera), area-sampled, on a dark ground brightening downwards, a grey stand below it."""
    h, w = shape
    lx, ly, lz = np.asarray(light, np.float64) / np.linalg.norm(light)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    acc = np.zeros((h, w))
    for oy in (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE:
        for ox in (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE:
            x, y = (xx + ox - cx) / r, -(yy + oy - cy) / r
            rr = x * x + y * y
            z = np.sqrt(np.clip(1.0 - rr, 0.0, None))
            ball = 0.8 * np.clip(lx * x + ly * y + lz * z, 0.0, None) + ambient
            stand = (np.abs(x) < 0.25) & (y < -0.9)
            ground = np.where(stand, 0.06, 0.01 * (1.0 + 0.5 * (yy + oy) / h))
            acc += np.where(rr < 1.0, ball, ground)
    return np.repeat((acc / SUPERSAMPLE ** 2)[..., None], 3, -1)


@pytest.mark.parametrize("cx,cy,r,light", [
    (160.37, 121.81, 88.6, (0.7, 0.3, 0.65)),     # from the right: the left side's terminator inside
    (151.2, 130.55, 93.3, (-0.5, 0.6, 0.62)),     # from the upper left: the stand on the unlit side
    (170.0, 118.25, 80.45, (0.1, 0.15, 0.98)),    # nearly from the front: the rim lit on one side only
    (155.5, 125.5, 90.0, (0.0, 0.0, 1.0)),        # from the front: no rim lit, the limb everywhere
])
def test_a_lit_ball_with_an_analytic_edge_is_found_to_a_tenth_of_a_pixel(cx, cy, r, light):
    found = find_ball(_lit_ball((250, 320), cx, cy, r, light))
    assert np.hypot(found.cx - cx, found.cy - cy) < 0.1 and abs(found.r - r) < 0.1, (found, (cx, cy, r))


def _half_rise_circle(lum: np.ndarray, cx: float, cy: float, r: float) -> tuple[float, float, float]:
    """The silhouette without a model: along rays from (cx, cy), where the brightness is halfway
    between the rim's (3 px inside) and the ground's (3–6 px outside); the stand (rays 30°–150°,
    y down) and rays of little contrast left out; a least-squares circle through those points."""
    from scipy.ndimage import map_coordinates

    phi = np.radians(np.arange(0.5, 360.0, 1.0))
    phi = phi[(phi < np.radians(30)) | (phi > np.radians(150))]
    rho = np.arange(r - 6.0, r + 6.0 + 1e-9, 0.05)
    x, y = cx + np.cos(phi)[:, None] * rho, cy + np.sin(phi)[:, None] * rho
    prof = map_coordinates(lum, [y - 0.5, x - 0.5], order=1, mode="nearest")
    rim, ground = prof[:, np.searchsorted(rho, r - 3.0)], np.median(prof[:, rho > r + 3.0], axis=1)
    pts = []
    for k in np.nonzero(rim - ground > 0.1 * np.max(rim - ground))[0]:
        half = 0.5 * (rim[k] + ground[k])
        j = np.nonzero((prof[k] < half) & (rho > r - 3.0))[0][0]
        e = np.interp(half, [prof[k, j], prof[k, j - 1]], [rho[j], rho[j - 1]])
        pts.append((cx + e * np.cos(phi[k]), cy + e * np.sin(phi[k])))
    pts = np.array(pts)
    (a, b, c), *_ = np.linalg.lstsq(np.c_[pts, np.ones(len(pts))], (pts ** 2).sum(1), rcond=None)
    return a / 2, b / 2, float(np.sqrt(c + a * a / 4 + b * b / 4))


@pytest.fixture(scope="module")
def grey():
    """The 12 grey-ball photos (linear values, as read with ``--linear``) and the mask's circle."""
    if not (PHOTOS / "gray").is_dir():
        pytest.skip(f"needs the shared photos at {PHOTOS}")
    from specgen_addon.photo.read import read_photo
    from specgen_addon.photo.sphere_image import read_mask

    photos = [read_photo(PHOTOS / "gray" / f"gray.{i}.tga", encoding="linear").rgb[..., :3] for i in range(12)]
    return photos, mask_circle(read_mask(PHOTOS / "gray" / "gray.mask.tga", photos[0].shape[:2]))


@pytest.fixture(scope="module")
def grey_found(grey):
    return [find_ball(p) for p in grey[0]]


@pytest.mark.slow
def test_the_grey_ball_is_found_within_half_a_pixel_of_its_outline_in_every_photo(grey, grey_found):
    photos, mask = grey
    lum = np.max(photos, axis=0) @ np.array([0.2126, 0.7152, 0.0722])   # every side lit in one of them
    sx, sy, sr = _half_rise_circle(lum, *mask)
    for i, found in enumerate(grey_found):
        assert np.hypot(found.cx - sx, found.cy - sy) < 0.5 and abs(found.r - sr) < 0.5, (i, found)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the dataset's mask is drawn about 0.7 px left of the ball's "
                   "outline in the photos (docs/photo-guide.md, 'Finding the ball')")
def test_the_grey_ball_is_found_within_half_a_pixel_of_the_mask_circle_in_every_photo(grey, grey_found):
    _, (mx, my, mr) = grey
    for i, found in enumerate(grey_found):
        assert np.hypot(found.cx - mx, found.cy - my) < 0.5 and abs(found.r - mr) < 0.5, (i, found)
