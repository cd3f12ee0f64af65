"""The ball found in real camera photos without a mask, and at any resolution.

Real photos: ../shared/data/photos/psm_gray_chrome (12 photos of a matte grey ball on a stand, dark
background, each lit from one side). The dataset's mask is a drawn disc; the photos' own silhouette
is measured on the brightest-of-twelve image, where every side of the ball is lit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.sphere_detect import find_ball

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
PHOTOS = SHARED / "data" / "photos" / "psm_gray_chrome"


def _tga(path):
    from PIL import Image

    return np.asarray(Image.open(path)).astype(np.float64) / 255.0


@pytest.fixture(scope="module")
def gray_photos():
    if not (PHOTOS / "gray").is_dir():
        pytest.skip(f"needs the shared photos at {PHOTOS}")
    return [_tga(PHOTOS / "gray" / f"gray.{i}.tga") for i in range(12)]


@pytest.mark.slow
def test_grey_ball_is_found_without_a_mask_in_every_photo(gray_photos):
    silhouette = find_ball(np.max(gray_photos, axis=0))   # every side lit in one of the twelve
    assert silhouette.arc > 0.8 and silhouette.rms_px < 0.3
    for i, photo in enumerate(gray_photos):
        found = find_ball(photo)
        off = np.hypot(found.cx - silhouette.cx, found.cy - silhouette.cy)
        assert off < 1.2 and abs(found.r - silhouette.r) < 1.2, (i, found, silhouette)


def test_a_given_circle_and_a_mask_are_used_as_they_are(tmp_path):
    from PIL import Image

    img = np.zeros((90, 120, 3), np.uint8)
    yy, xx = np.mgrid[:90, :120]
    img[(xx + 0.5 - 60) ** 2 + (yy + 0.5 - 45) ** 2 < 30 ** 2] = 200
    Image.fromarray(img).save(tmp_path / "p.png")
    mask = np.where((xx + 0.5 - 60) ** 2 + (yy + 0.5 - 45) ** 2 < 30 ** 2, 255, 0).astype(np.uint8)
    Image.fromarray(mask).save(tmp_path / "m.png")
    crop = input_image.PhotoSource(tmp_path / "p.png", circle=(61.0, 44.0, 29.0)).crop()
    assert crop.circle == (61.0, 44.0, 29.0) and crop.circle_source == "given"
    crop = input_image.PhotoSource(tmp_path / "p.png", mask=tmp_path / "m.png").crop()
    assert np.allclose(crop.circle, (60.0, 45.0, 30.0), atol=0.3) and "mask" in crop.circle_source
    assert "radius" in crop.describe()
    input_image.write_circle_preview(tmp_path / "c.png", input_image.PhotoSource(tmp_path / "p.png"),
                                     crop.circle)
    drawn = np.asarray(Image.open(tmp_path / "c.png"))
    assert tuple(drawn[45, 90]) == (255, 40, 40)   # on the circle, right of the centre


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "1,2,0", "1,2,-3"])
def test_a_bad_circle_is_refused_in_one_sentence(text):
    from specgen_addon.common.errors import ImageInputError

    with pytest.raises(ImageInputError, match="--circle takes X,Y,R"):
        input_image.parse_circle(text)


@pytest.mark.slow
@pytest.mark.parametrize("side", [4096, 8000])
@pytest.mark.parametrize("resample", ["nearest", "bilinear"])
def test_the_example_sphere_is_found_the_same_at_any_resolution(tmp_path, side, resample):
    """The example sphere upscaled (its circle in the upscaled frame known from the original's)."""
    from PIL import Image

    small = np.asarray(Image.open(REPO / "examples" / "sphere.png").convert("RGB")).astype(np.float64) / 255
    ref = input_image.crop_sphere(input_image.spectra.srgb_decode(small)).circle
    big = Image.open(REPO / "examples" / "sphere.png").convert("RGB").resize(
        (side, side), Image.NEAREST if resample == "nearest" else Image.BILINEAR)
    big.save(tmp_path / "big.png")
    crop = input_image.load_sphere_crop(tmp_path / "big.png")
    scale = crop_side = None
    from specgen_addon.common.limits import MAX_WORK_SIDE

    factor = int(np.ceil(side / MAX_WORK_SIDE))
    crop_side = side // factor
    scale = crop_side / 128.0
    expect = np.array(ref) * scale
    got = np.array(crop.circle)
    # within a hundredth of the radius (half a pixel of the 128 px original)
    assert np.all(np.abs(got - expect) < 0.01 * expect[2] + 0.5 * scale), (got, expect)
