"""The sphere finder to a fraction of a pixel (specgen_addon.photo.sphere_edge, input_image's crop).

The truths are analytic: discs drawn by area sampling (8×8 points per pixel, as an antialiased
render or a camera's pixel integrates) or point sampling (a pixel counts when its centre is
inside, as the canonical renders), with shading that darkens or brightens towards the limb.
"""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.sphere_edge import refine_circle

SUPERSAMPLE = 8


def _shade(x: np.ndarray, y: np.ndarray, limb: float) -> np.ndarray:
    """A sphere-like shading on the unit disc: a linear gradient times a limb term
    (limb < 0 darkens the outline, > 0 brightens it)."""
    mu = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, 1.0))
    return (0.5 + 0.3 * x - 0.1 * y) * (1.0 + limb * (1.0 - mu))


def _disc(shape: tuple[int, int], cx: float, cy: float, r: float, limb: float = 0.0,
          area_sampled: bool = True, background: float = 0.0) -> np.ndarray:
    """(H, W, 3) image of a shaded disc, pixel centres at +0.5."""
    h, w = shape
    n = SUPERSAMPLE if area_sampled else 1
    offsets = (np.arange(n) + 0.5) / n
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    acc = np.zeros((h, w))
    for oy in offsets:
        for ox in offsets:
            x, y = (xx + ox - cx) / r, -(yy + oy - cy) / r
            inside = x * x + y * y < 1.0
            acc += np.where(inside, _shade(x, y, limb), background)
    img = acc / (n * n)
    return np.repeat(img[..., None], 3, -1) * np.array([1.0, 0.8, 0.6])


def _rough_circle(img: np.ndarray) -> tuple[float, float, float]:
    """The mask's circle (to about half a pixel), as input_image finds it first."""
    mask, _ = input_image._foreground(img)
    return input_image._circle_of_mask(mask, fit_outline=True)


@pytest.mark.parametrize("limb", [-0.8, 0.0, 0.8])
@pytest.mark.parametrize("cx,cy,r", [(80.5, 80.5, 64.0), (71.3, 77.85, 57.6), (90.0, 85.25, 70.4)])
def test_an_antialiased_sphere_is_found_to_a_tenth_of_a_pixel(cx, cy, r, limb):
    img = _disc((170, 170), cx, cy, r, limb)
    rough = _rough_circle(img)
    found = refine_circle(img.max(-1), *rough)
    assert found is not None
    assert np.abs(np.subtract(found, (cx, cy, r))).max() < 0.1, (found, rough)
    # the mask alone counts every partly covered outline pixel: about half a pixel too large
    assert rough[2] - r > 0.25


@pytest.mark.parametrize("cx,cy,r", [(64.0, 64.0, 64.0), (71.3, 77.85, 57.6)])
def test_a_point_sampled_sphere_is_found_to_a_tenth_of_a_pixel(cx, cy, r):
    img = _disc((150, 150), cx, cy, r, limb=-0.5, area_sampled=False)
    found = refine_circle(img.max(-1), *_rough_circle(img))
    assert found is not None and np.abs(np.subtract(found, (cx, cy, r))).max() < 0.1


def test_an_outline_too_dark_to_measure_is_left_to_the_mask():
    """A limb far darker than the sphere (here radiance ∝ μ⁶) gives no coverage to measure: the
    refinement declines, and the loader falls back to the mask's circle rather than guess."""
    h = w = 150
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    x, y = (xx - 75.0) / 60.0, (yy - 75.0) / 60.0
    mu = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, 1.0))
    img = np.repeat((mu ** 6)[..., None], 3, -1)
    assert refine_circle(img.max(-1), 75.0, 75.0, 60.0) is None
    assert input_image.prepare_sphere_array(img, 64).shape == (64, 64, 3)


def test_the_loader_crops_an_antialiased_sphere_to_its_true_size():
    """Linear shading survives bilinear resampling exactly, so what is left is the framing error:
    found from the mask alone (half a pixel too large), the gradient would be off by ~3·10⁻³."""
    size = 128
    img = _disc((300, 260), 131.37, 144.6, 101.3)
    out = input_image.prepare_sphere_array(img, size)
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5 - size / 2) / (size / 2)
    x, y = xx, -yy
    truth = np.repeat(_shade(x, y, 0.0)[..., None], 3, -1) * np.array([1.0, 0.8, 0.6])
    interior = x * x + y * y < 0.9 ** 2
    assert np.abs(out - truth)[interior].max() < 1e-3


def test_the_loader_still_copies_an_exactly_framed_point_sampled_sphere():
    img = _disc((128, 128), 64.0, 64.0, 64.0, limb=-0.5, area_sampled=False).astype(np.float32)
    np.testing.assert_array_equal(input_image.prepare_sphere_array(img), img)


def test_the_loader_finds_an_antialiased_sphere_on_a_grey_background():
    size = 64
    img = _disc((120, 140), 70.4, 58.7, 41.2, background=0.35)
    out = input_image.prepare_sphere_array(img, size)
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5 - size / 2) / (size / 2)
    truth = np.repeat(_shade(xx, -yy, 0.0)[..., None], 3, -1) * np.array([1.0, 0.8, 0.6])
    interior = xx * xx + yy * yy < 0.85 ** 2
    assert np.abs(out - truth)[interior].max() < 2e-3
