"""Spectral EXR (Fichet et al. 2021): our writer read back by colour-science + OpenImageIO."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import OutputExistsError
from specgen_addon.render.spectral_exr import (SpectralEXRError, channel_name, parse_channel_name,
                                        read_spectral_exr, write_preview_png, write_spectral_exr)

colour = pytest.importorskip("colour")
pytest.importorskip("OpenImageIO", reason="colour's Fichet 2021 reader needs OpenImageIO")


def _image(wavelengths: np.ndarray, h: int = 6, w: int = 5) -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.uniform(0.0, 3.0, size=(h, w, wavelengths.size)).astype(np.float32)


def test_channel_names_use_comma_decimal_separator():
    assert channel_name(550) == "S0.550,000000nm"
    assert channel_name(412.5) == "S0.412,500000nm"
    assert parse_channel_name("S0.412,500000nm") == 412.5
    assert parse_channel_name("R") is None


def test_colour_reader_sees_our_channels_attributes_and_values(tmp_path):
    wavelengths = np.array([380.0, 412.5, 500.0, 555.0, 640.0, 780.0])
    values = _image(wavelengths)
    path = write_spectral_exr(tmp_path / "stack.exr", values, wavelengths,
                              rgb=np.zeros(values.shape[:2] + (3,)), attributes={"specgenMesh": "sphere"})

    components, spec = colour.read_spectral_image_Fichet2021(path, additional_data=True)
    assert spec.is_emissive and not spec.is_polarised and not spec.is_bispectral
    assert set(components) == {"S0"}
    read_wl, read_values = components["S0"]
    np.testing.assert_allclose(read_wl, wavelengths)
    np.testing.assert_array_equal(read_values, values)  # float32 written, float32 read: bit-exact
    attributes = {a.name: a.value for a in spec.attributes}
    assert attributes["spectralLayoutVersion"] == "1.0"
    assert attributes["emissiveUnits"] == "W.m^-2.sr^-1"
    assert attributes["specgenMesh"] == "sphere"


def test_preview_is_cmf_integral_of_the_spectrum(tmp_path):
    from specgen_addon.spectral.spectra import cmfs, spectral_to_linear_srgb

    wavelengths = np.linspace(380.0, 780.0, 21)
    values = _image(wavelengths, 3, 4)
    path = write_spectral_exr(tmp_path / "p.exr", values, wavelengths)
    image = read_spectral_exr(path)
    np.testing.assert_allclose(image.rgb, spectral_to_linear_srgb(values, wavelengths), rtol=1e-5, atol=1e-6)
    # Independent check of the luminance: Y = Σ L ȳ / Σ ȳ (emissive convention), sRGB Y row.
    ybar = cmfs(wavelengths)[:, 1]
    y_expected = values @ ybar / ybar.sum()
    y_preview = image.rgb @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(y_preview, y_expected, rtol=2e-3)


def test_existing_output_is_not_overwritten_unless_asked(tmp_path):
    wavelengths = np.array([500.0, 600.0])
    target = tmp_path / "a.exr"
    write_spectral_exr(target, _image(wavelengths), wavelengths, rgb=np.zeros((6, 5, 3)))
    before = target.read_bytes()
    with pytest.raises(OutputExistsError):
        write_spectral_exr(target, 2 * _image(wavelengths), wavelengths, rgb=np.zeros((6, 5, 3)))
    assert target.read_bytes() == before
    write_spectral_exr(target, 2 * _image(wavelengths), wavelengths, rgb=np.zeros((6, 5, 3)), overwrite=True)
    np.testing.assert_allclose(read_spectral_exr(target).values, 2 * _image(wavelengths))


def test_failed_write_leaves_no_file(tmp_path):
    with pytest.raises(SpectralEXRError):
        write_spectral_exr(tmp_path / "bad.exr", np.zeros((4, 4, 3)), np.array([500.0, 600.0]))
    with pytest.raises(SpectralEXRError):
        write_spectral_exr(tmp_path / "bad.exr", np.zeros((4, 4, 2)), np.array([600.0, 500.0]),
                           rgb=np.zeros((4, 4, 3)))
    assert list(tmp_path.iterdir()) == []


def test_reader_rejects_plain_rgb_exr(tmp_path):
    import OpenEXR

    path = tmp_path / "rgb.exr"
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION},
                      {c: np.zeros((2, 2), np.float32) for c in "RGB"}) as exr:
        exr.write(str(path))
    with pytest.raises(SpectralEXRError, match="spectralLayoutVersion"):
        read_spectral_exr(path)


def test_preview_png_is_srgb_encoded(tmp_path):
    from PIL import Image

    rgb = np.zeros((2, 2, 3))
    rgb[0, 0] = 0.18
    rgb[1, 1] = 1.0
    path = write_preview_png(tmp_path / "p.png", rgb)
    pixels = np.asarray(Image.open(path))
    assert pixels.shape == (2, 2, 3)
    assert pixels[0, 0, 0] == 118  # sRGB OETF(0.18) = 0.4613 -> 118
    assert pixels[1, 1, 2] == 255 and pixels[0, 1, 0] == 0
