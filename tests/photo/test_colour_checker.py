"""White balance from a ColorChecker Classic in the photo: the chart is found (turned, under a cast,
at any exposure, in a portrait photo), its greys take the cast out to within 0.1 %, balanced to the
light's colour with the luminance kept; clipped greys are left out; greys that do not follow the
chart warn; a photo without a chart, or a chart with a white patch too, is one sentence."""

from __future__ import annotations

import re
import sys
import warnings

import numpy as np
import pytest
from checker_photo import CHART_CENTRE, CIRCLE, checker_photo, draw_checker, needs_detector

from specgen_addon.common.errors import ImageInputError
from specgen_addon.photo.colour_checker import (
    GREYS,
    CheckerFound,
    checker_balance,
    find_checker,
    reference_swatches,
)
from specgen_addon.photo.image_checks import ImageNote
from specgen_addon.photo.sphere_image import PhotoSource
from specgen_addon.photo.white_balance import LUMINANCE

CAST = np.array([1.3, 1.0, 0.6])
#: How far the balanced greys' colour may be from the reference's (share of each channel).
TOLERANCE = 1e-3


def _found(swatches: np.ndarray, saturated=None) -> CheckerFound:
    return CheckerFound(np.asarray(swatches, np.float64), np.zeros(24) if saturated is None else saturated,
                        np.array([[0, 0], [60, 0], [60, 40], [0, 40]], np.float64))


def test_the_greys_are_balanced_to_the_lights_colour_with_their_luminance_kept():
    greys = reference_swatches()[GREYS]
    swatches = reference_swatches() * CAST * 0.7
    warm = np.array([1.0, 0.52, 0.19])
    balance = checker_balance(_found(swatches), tuple(warm))
    out = swatches[GREYS] * balance.gains
    np.testing.assert_allclose(out / out[:, 1:2], greys * warm / (greys * warm)[:, 1:2], rtol=1e-9)
    assert (out @ LUMINANCE).sum() == pytest.approx((swatches[GREYS] @ LUMINANCE).sum())
    assert balance.fit_rms < 1e-9 and balance.used == tuple(range(6))


def test_saturated_greys_are_left_out_and_said():
    swatches = reference_swatches() * CAST
    swatches[18] = 1.0                       # the white clipped to the file's maximum
    clipped = np.zeros(24)
    clipped[18] = 0.3
    balance = checker_balance(_found(swatches, clipped))
    np.testing.assert_allclose(balance.gains * CAST / (balance.gains * CAST)[1], 1.0, rtol=1e-9)
    assert balance.used == (1, 2, 3, 4, 5) and "swatch 19 saturated, left out" in balance.describe()


def test_a_chart_with_too_few_usable_greys_is_one_sentence():
    clipped = np.zeros(24)
    clipped[18:23] = 1.0
    with pytest.raises(ImageInputError, match="greys are saturated or black"):
        checker_balance(_found(reference_swatches(), clipped))


def test_greys_that_do_not_follow_the_chart_warn_and_ones_that_do_not():
    swatches = reference_swatches() * CAST
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImageNote)
        checker_balance(_found(swatches))                      # a good fit: no warning
    encoded = np.clip(swatches, 0, None) ** (1 / 2.2)           # a linear file taken as sRGB, or the reverse
    with pytest.warns(ImageNote, match="differ from the reference by .* check the photo's encoding"):
        checker_balance(_found(encoded))


@pytest.fixture(scope="module")
def photos(tmp_path_factory, repo_dir):
    root = tmp_path_factory.mktemp("checker")
    return {"neutral": checker_photo(root / "neutral.exr", repo=repo_dir),
            "cast": checker_photo(root / "cast.exr", cast=CAST, repo=repo_dir),
            "none": checker_photo(root / "none.exr", cast=CAST, repo=repo_dir, chart=False)}


@needs_detector
@pytest.mark.slow
def test_a_checker_in_the_photo_takes_the_cast_out(photos):
    neutral = PhotoSource(photos["neutral"], circle=CIRCLE).crop()
    balanced = PhotoSource(photos["cast"], circle=CIRCLE, colour_checker=True).crop()
    lit = neutral.image.max(-1) > 1e-3
    ratio = balanced.image[lit] / neutral.image[lit]
    np.testing.assert_allclose(ratio / np.median(ratio), 1.0, rtol=TOLERANCE)
    gains = balanced.white_gains * CAST
    np.testing.assert_allclose(gains / gains[1], 1.0, rtol=TOLERANCE)
    assert "white balance from the colour checker: gains R" in balanced.describe()
    note = balanced.white_note
    at = re.search(r"ColorChecker Classic at \((\d+), (\d+)\) px", note)
    assert at is not None and np.abs(np.array(at.groups(), float) - CHART_CENTRE).max() < 3.0, note
    assert "24 swatches sampled" in note
    assert "greys as shot (linear R/G/B, white to black) {:.3f}/{:.3f}/{:.3f},".format(
        *reference_swatches()[18] * CAST) in note
    assert "6 fitted to the reference greys to 0.0 % rms" in note


@needs_detector
@pytest.mark.slow
@pytest.mark.parametrize("portrait", [False, True])
def test_the_chart_is_found_and_oriented_under_a_strong_cast_at_any_exposure(portrait):
    cast = np.array([1.0, 0.45, 0.15]) * 8.0         # a tungsten lamp, over-exposed EXR
    img = draw_checker(np.full((400, 640, 3), 0.25), angle_deg=-8.0)
    img = np.clip(img, 0, None) * cast
    centre = np.array(CHART_CENTRE)
    if portrait:                                       # turned a quarter anticlockwise: 400 wide, 640 high
        img = np.rot90(img).copy()
        centre = np.array([centre[1], 640 - centre[0]])
    found = find_checker(img.astype(np.float32), None)
    expected = np.clip(reference_swatches()[GREYS], 0, None) * cast
    np.testing.assert_allclose(found.swatches[GREYS], expected, rtol=0.01)
    assert np.abs(found.corners.mean(axis=0) - centre).max() < 3.0


@needs_detector
@pytest.mark.slow
def test_a_photo_without_a_checker_is_one_sentence(photos):
    with pytest.raises(ImageInputError, match=r"none\.exr: no colour checker found in the photo") as info:
        PhotoSource(photos["none"], circle=CIRCLE, colour_checker=True).crop()
    assert "\n" not in str(info.value)


def test_a_checker_and_a_white_patch_together_are_refused(photos):
    with pytest.raises(ImageInputError, match="--white-patch and --colour-checker both set the white balance"):
        PhotoSource(photos["cast"], circle=CIRCLE, colour_checker=True, white_patch=(1, 1, 4, 4)).crop()


def test_without_the_detector_the_option_is_one_sentence(photos, monkeypatch):
    monkeypatch.setitem(sys.modules, "colour_checker_detection", None)    # a stock Blender: no OpenCV
    monkeypatch.setitem(sys.modules, "cv2", None)
    with pytest.raises(ImageInputError, match="needs the colour-checker-detection package .* a stock "
                                              "Blender does not$"):
        PhotoSource(photos["none"], circle=CIRCLE, colour_checker=True).crop()
