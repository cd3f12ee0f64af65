"""White balance from a neutral patch the user picks (a grey card in the photo): the cast is taken
out, the patch's luminance kept, the light's own colour respected, and a chrome ball photographed
alike gets the same gains."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import ImageInputError
from specgen_addon.common.image_io import write_exr
from specgen_addon.photo.light_probe import read_probe
from specgen_addon.photo.read import read_photo
from specgen_addon.photo.sphere_image import PhotoSource
from specgen_addon.photo.white_balance import LUMINANCE, parse_patch, patch_gains

CAST = np.array([1.3, 1.0, 0.6])
PATCH = (4, 6, 20, 12)        # x, y, w, h: a grey card in the top-left corner
CIRCLE = (128.0, 128.0, 64.0)


@pytest.fixture
def photos(tmp_path, repo_dir):
    """The example sphere on black with a grey card, as taken (a colour cast) and neutral (EXR)."""
    ball = read_photo(repo_dir / "examples" / "sphere.png").rgb[..., :3]
    img = np.zeros((256, 256, 3), np.float32)
    img[64:192, 64:192] = ball
    x, y, w, h = PATCH
    img[y:y + h, x:x + w] = 0.18
    paths = {}
    for name, arr in (("neutral", img), ("cast", img * CAST.astype(np.float32))):
        paths[name] = write_exr(tmp_path / f"{name}.exr", {c: arr[..., i] for i, c in enumerate("RGB")})
    return paths


def test_a_grey_patch_takes_the_cast_out_of_the_photo(photos):
    neutral = PhotoSource(photos["neutral"], circle=CIRCLE).crop()
    balanced = PhotoSource(photos["cast"], circle=CIRCLE, white_patch=PATCH).crop()
    as_shot = PhotoSource(photos["cast"], circle=CIRCLE).crop()
    lum_gain = 1.0 / float(CAST @ LUMINANCE)                 # the patch's luminance is kept
    np.testing.assert_allclose(balanced.image, neutral.image / lum_gain, rtol=1e-4, atol=1e-6)
    assert not np.allclose(as_shot.image, balanced.image, rtol=1e-2)
    np.testing.assert_allclose(balanced.white_gains, 1.0 / CAST / lum_gain, rtol=1e-5)
    assert "white balance from the patch" in balanced.describe()


def test_the_patch_is_balanced_to_the_lights_colour():
    rgb = np.full((10, 10, 3), 0.5)
    warm = np.array([1.0, 0.52, 0.19])
    gains = patch_gains(rgb, None, (0, 0, 10, 10), tuple(warm))
    out = rgb[0, 0] * gains
    np.testing.assert_allclose(out / out.max(), warm, rtol=1e-9)
    assert out @ LUMINANCE == pytest.approx(0.5)


def test_saturated_pixels_of_the_patch_are_left_out():
    rgb = np.full((10, 10, 3), 0.4) * CAST
    rgb[:5] = 1.0
    sat = np.zeros((10, 10), bool)
    sat[:5] = True
    gains = patch_gains(rgb, sat, (0, 0, 10, 10))
    np.testing.assert_allclose(rgb[9, 9] * gains / (rgb[9, 9] * gains).max(), 1.0, rtol=1e-9)


@pytest.mark.parametrize("patch,sat,message", [
    ((8, 8, 5, 5), False, "does not lie in the"), ((0, 0, 4, 4), True, "all saturated"),
    ((0, 0, 4, 4), False, "black in a channel")])
def test_a_patch_that_cannot_balance_is_one_sentence(patch, sat, message):
    rgb = np.zeros((10, 10, 3))
    rgb[..., 0] = 0.5
    with pytest.raises(ImageInputError, match=message):
        patch_gains(rgb, np.full((10, 10), sat), patch)


@pytest.mark.parametrize("text", ["1,2,3", "a,b,c,d", "0,0,0,5", "1,2,3,inf"])
def test_a_malformed_patch_is_one_sentence(text):
    with pytest.raises(ImageInputError, match="--white-patch takes X,Y,W,H"):
        parse_patch(text)


def test_a_chrome_ball_photographed_alike_gets_the_same_gains(photos):
    plain = read_probe(photos["cast"], circle=CIRCLE)
    gains = (0.5, 1.0, 2.0)
    balanced = read_probe(photos["cast"], circle=CIRCLE, gains=gains)
    lit = plain.env_rgb.max(-1) > 1e-3
    np.testing.assert_allclose(balanced.env_rgb[lit] / plain.env_rgb[lit],
                               np.broadcast_to(gains, balanced.env_rgb[lit].shape), rtol=1e-4)


@pytest.mark.slow
def test_generate_judges_clipping_before_the_white_balance(repo_dir):
    """An 8-bit photo balanced by a patch whose gains exceed 1: Generate leaves out the pixels the
    camera saturated, not those the gains lifted past 1 (they are data)."""
    from specgen_addon.generate.pipeline import generate

    photo = repo_dir / "examples" / "sphere.png"
    source = PhotoSource(photo, white_patch=parse_patch("100,60,8,8"))
    crop = source.crop()
    assert crop.white_gains.max() > 1.5 and crop.saturated.any()
    lifted = np.any(crop.image >= 0.995, axis=-1) & ~crop.saturated
    assert lifted.sum() > 0.5 * crop.saturated.sum()           # a clip at 1 would take these too
    fit = generate(source).refinement
    disc = np.pi / 4 * crop.image.shape[0] ** 2
    saturated_share, lifted_share = crop.saturated.sum() / disc, lifted.sum() / disc
    assert fit.clipped_fraction < saturated_share + 0.5 * lifted_share, (fit.clipped_fraction, saturated_share)
    assert not any("clipped at full scale" in w for w in fit.warnings)
