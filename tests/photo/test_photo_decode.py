"""Camera files read right: bit depth kept, the encoding a choice, saturated pixels found
(specgen_addon.photo.read), tested against known pixel values."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.photo import read as photo_read
from specgen_addon.common.errors import ImageInputError


def _write_oiio(path, pixels: np.ndarray, fmt: str) -> None:
    oiio = pytest.importorskip("OpenImageIO")
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def test_a_large_16_bit_png_keeps_its_bit_depth(tmp_path):
    """A 2600×2200 16-bit RGB ramp of 605 levels (Pillow alone reads it as 8-bit: 9 levels left)."""
    h, w = 2200, 2600
    levels = (np.arange(h) // 2 * 605 // (h // 2)).astype(np.uint16) * 100 + 1000   # pairs of equal rows
    img = np.repeat(np.repeat(levels[:, None, None], w, 1), 3, 2).astype(np.uint16)
    _write_oiio(tmp_path / "ramp.png", img, "uint16")
    photo = photo_read.read_photo(tmp_path / "ramp.png", encoding="linear")
    assert photo.bits == 16 and photo.rgb.shape[:2] == (1100, 1300)     # averaged 2× in linear light
    col = photo.rgb[:, 10, 0]
    assert len(np.unique(np.round(col * 65535))) == 605
    np.testing.assert_allclose(col, levels[::2] / 65535.0, rtol=1e-6)


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_16_bit_files_decode_as_srgb_by_default_and_as_stored_with_linear(tmp_path, suffix):
    img = np.zeros((40, 50, 3), np.uint16)
    img[..., 0], img[..., 1], img[..., 2] = 30000, 65535, 12
    _write_oiio(tmp_path / f"p{suffix}", img, "uint16")
    lin = photo_read.read_photo(tmp_path / f"p{suffix}", encoding="linear")
    np.testing.assert_allclose(lin.rgb[5, 5], np.array([30000, 65535, 12]) / 65535.0, rtol=1e-6)
    srgb = photo_read.read_photo(tmp_path / f"p{suffix}")
    x = 30000 / 65535.0
    assert srgb.rgb[5, 5, 0] == pytest.approx(((x + 0.055) / 1.055) ** 2.4, rel=1e-5)
    assert srgb.saturated.all() and lin.encoding == "linear" and srgb.encoding == "sRGB-decoded"


def test_8_bit_saturation_is_found_and_reported(tmp_path):
    from PIL import Image

    img = np.full((30, 40, 3), 100, np.uint8)
    img[:3, :5, 1] = 255
    Image.fromarray(img).save(tmp_path / "p.png")
    photo = photo_read.read_photo(tmp_path / "p.png", encoding="linear")
    assert photo.saturated_count == 15 and photo.bits == 8
    assert photo.rgb[10, 10, 0] == pytest.approx(100 / 255)


def test_an_exr_is_unclipped_unless_a_white_level_is_given(tmp_path):
    from specgen_addon.common.image_io import write_exr

    rgb = np.full((20, 24, 3), 0.25, np.float32)
    rgb[2:4, 2:4] = 8.0
    write_exr(tmp_path / "p.exr", {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    assert photo_read.read_photo(tmp_path / "p.exr").saturated_count == 0
    clipped = photo_read.read_photo(tmp_path / "p.exr", white_level=8.0)
    assert clipped.saturated_count == 4 and clipped.rgb[10, 10, 0] == 0.25
    with pytest.raises(ImageInputError, match="white level must be a positive number"):
        photo_read.read_photo(tmp_path / "p.exr", white_level=-1.0)


@pytest.mark.parametrize("kind", ["float", "half"])
def test_a_floating_point_tiff_is_read_as_linear_light_like_an_exr(tmp_path, kind):
    oiio = pytest.importorskip("OpenImageIO")
    from specgen_addon.photo.sphere_image import PhotoSource

    rgb = np.full((20, 24, 3), 0.25, np.float32)
    rgb[2:4, 2:4] = (8.0, 2.0, 0.5)                           # above 1: not clipped
    path = tmp_path / "p.tif"
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(24, 20, 3, oiio.FLOAT if kind == "float" else oiio.HALF))
    assert out.write_image(rgb)
    out.close()
    photo = photo_read.read_photo(path)
    assert photo.encoding == "linear (float)" and photo.saturated_count == 0
    np.testing.assert_allclose(photo.rgb[..., :3], rgb, rtol=1e-3)
    assert photo_read.stores_floats(path) and PhotoSource(path).linear   # no clip level in the fits


def test_saturated_pixels_reach_the_crop_that_refinement_excludes(tmp_path):
    from PIL import Image

    from specgen_addon.photo import sphere_image as input_image

    img = np.zeros((96, 96, 3), np.uint8)
    yy, xx = np.mgrid[:96, :96]
    img[(xx + 0.5 - 48) ** 2 + (yy + 0.5 - 48) ** 2 < 40 ** 2] = 120
    img[40:46, 40:46] = 255
    Image.fromarray(img).save(tmp_path / "p.png")
    crop = input_image.PhotoSource(tmp_path / "p.png", circle=(48.0, 48.0, 40.0)).crop()
    assert crop.saturated is not None and 0 < crop.saturated.mean() < 0.05
    assert crop.saturated[56, 56] and not crop.saturated[80, 80]  # the clipped block, (43, 43) in the photo
    assert "saturated" in crop.describe()


def _dng(path, raw: np.ndarray, white: int) -> None:
    pidng = pytest.importorskip("pidng.core", reason="pidng writes the test DNG")
    from pidng.defs import (
        CalibrationIlluminant,
        CFAPattern,
        DNGVersion,
        Orientation,
        PhotometricInterpretation,
    )

    Tag = pidng.Tag
    h, w = raw.shape
    t = pidng.DNGTags()
    for tag, value in ((Tag.ImageWidth, w), (Tag.ImageLength, h), (Tag.TileWidth, w), (Tag.TileLength, h),
                       (Tag.Orientation, Orientation.Horizontal),
                       (Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array),
                       (Tag.SamplesPerPixel, 1), (Tag.BitsPerSample, 16), (Tag.CFARepeatPatternDim, [2, 2]),
                       (Tag.CFAPattern, CFAPattern.RGGB), (Tag.BlackLevel, 0), (Tag.WhiteLevel, white),
                       (Tag.ColorMatrix1, [[1, 1], [0, 1], [0, 1], [0, 1], [1, 1], [0, 1], [0, 1], [0, 1], [1, 1]]),
                       (Tag.CalibrationIlluminant1, CalibrationIlluminant.D65),
                       (Tag.AsShotNeutral, [[1, 1], [1, 1], [1, 1]]), (Tag.BaselineExposure, [[0, 100]]),
                       (Tag.DNGVersion, DNGVersion.V1_4), (Tag.DNGBackwardVersion, DNGVersion.V1_2),
                       (Tag.Make, "Test"), (Tag.Model, "Flat")):
        t.set(tag, value)
    conv = pidng.RAW2DNG()
    conv.options(t, path="", compress=False)
    conv.convert(raw, filename=str(path.with_suffix("")))


def test_a_dng_is_developed_linearly_with_its_clipped_photosites_marked(tmp_path):
    pytest.importorskip("rawpy")
    raw = np.full((48, 64), 1000, np.uint16)
    raw[:, 32:] = 2000
    raw[:8, :8] = 4095                 # clipped at the white level
    _dng(tmp_path / "flat.dng", raw, 4095)
    photo = photo_read.read_photo(tmp_path / "flat.dng")
    # identity colour matrix, neutral white balance: each pixel is its photosite over the white level
    np.testing.assert_allclose(photo.rgb[20, 10], 1000 / 4095, rtol=2e-3)
    np.testing.assert_allclose(photo.rgb[20, 50], 2000 / 4095, rtol=2e-3)
    assert photo.saturated[:8, :8].all() and not photo.saturated[20:, 20:].any()
    assert photo.bits == 16 and "RAW" in photo.encoding


def test_an_unknown_encoding_and_a_missing_file_are_refused(tmp_path):
    with pytest.raises(ImageInputError, match="unknown encoding"):
        photo_read.read_photo(tmp_path / "x.png", encoding="gamma")
    with pytest.raises(ImageInputError, match="no such image file"):
        photo_read.read_photo(tmp_path / "x.png")


def test_a_circle_given_in_the_files_pixels_follows_a_downsampled_read(tmp_path):
    """A 4200-px-wide photo is read at a third of its size (the longer side ≤ 2048): so is the
    user's circle, given in the file's pixels."""
    from PIL import Image

    from specgen_addon.photo import sphere_image as input_image

    img = np.zeros((300, 4200, 3), np.uint8)
    img[100:200, 2000:2100] = 150
    Image.fromarray(img).save(tmp_path / "wide.png")
    crop = input_image.PhotoSource(tmp_path / "wide.png", circle=(2050.0, 150.0, 50.0)).crop()
    np.testing.assert_allclose(crop.circle, (2050.0 / 3, 50.0, 50.0 / 3))
    np.testing.assert_allclose(crop.file_circle, (2050.0, 150.0, 50.0))   # reported as given
    assert "centre (2050.00, 150.00) px, radius 50.00 px" in crop.describe()
