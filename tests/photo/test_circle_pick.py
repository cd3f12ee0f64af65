"""A ball's circle from points picked on its outline: exact through three, least squares through
more, the Image Editor's view position in the photo's pixels as --circle counts them."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import ImageInputError
from specgen_addon.photo.circle_pick import circle_through, pixel_from_view, view_from_pixel

TRUE = (412.3, 287.9, 151.6)     # cx, cy, r in pixels


def _on_circle(angles_deg, circle=TRUE):
    cx, cy, r = circle
    t = np.radians(angles_deg)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def test_three_points_give_the_circle_through_them():
    np.testing.assert_allclose(circle_through(_on_circle([10, 130, 250])), TRUE, atol=1e-9)


def test_three_points_close_together_still_give_the_circle():
    np.testing.assert_allclose(circle_through(_on_circle([80, 95, 110])), TRUE, rtol=1e-7)


def test_more_points_with_a_hand_tremor_give_the_circle_to_a_fraction_of_a_pixel():
    rng = np.random.default_rng(5)
    pts = _on_circle(np.linspace(0, 360, 12, endpoint=False)) + rng.normal(0, 0.7, (12, 2))
    np.testing.assert_allclose(circle_through(pts), TRUE, atol=0.5)


@pytest.mark.parametrize("points,needle", [
    ([(0, 0), (10, 10)], "at least 3 points"),
    ([(0, 0), (10, 10), (20, 20), (30, 30)], "on one line"),
    ([(0, 0), (10, 10), (float("nan"), 3)], "at least 3 points"),
])
def test_too_few_or_collinear_points_are_refused_in_one_sentence(points, needle):
    with pytest.raises(ImageInputError, match=needle):
        circle_through(points)


def test_the_view_position_is_the_photos_pixels_counted_from_the_top_left():
    # the Image Editor's view: u right, v up, 0–1 across the image; --circle: x right, y down
    assert pixel_from_view(0.0, 1.0, 640, 480) == (0.0, 0.0)            # top-left corner
    assert pixel_from_view(1.0, 0.0, 640, 480) == (640.0, 480.0)        # bottom-right corner
    assert pixel_from_view(0.25, 0.75, 640, 480) == (160.0, 120.0)
    np.testing.assert_allclose(view_from_pixel(*pixel_from_view(0.3, 0.6, 640, 480), 640, 480), (0.3, 0.6))


def test_two_corners_give_the_white_patch_in_whole_pixels():
    from specgen_addon.photo.circle_pick import patch_through

    assert patch_through([(120.4, 30.6), (100.2, 50.1)]) == (100, 30, 21, 21)   # any two opposite corners
    assert patch_through([(10, 10), (20, 15), (12, 30)]) == (10, 10, 10, 20)      # or more: their span
    with pytest.raises(ImageInputError, match="two opposite corners"):
        patch_through([(10, 10)])
    with pytest.raises(ImageInputError, match="under two pixels"):
        patch_through([(10.2, 10.2), (10.7, 40.0)])
