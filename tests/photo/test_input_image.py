"""Canonical input renders and the user-image loader (real files written by independent writers)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.photo import sphere_image as input_image
from specgen_addon.spectral import spectra
from specgen_addon.common.errors import ImageInputError, OutputExistsError
from specgen_addon.render.analytic import GGXReflector, Lambertian

SIZE = input_image.CANONICAL_SIZE
needs_bpy = pytest.mark.skipif(importlib.util.find_spec("bpy") is None,
                               reason="the canonical lighting is an HDRI of the bpy wheel")


def _shade(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Linear RGB of the synthetic sphere at unit-disc coordinates (x right, y up)."""
    s = 0.6 + 0.25 * x + 0.15 * y
    return np.stack([0.8 * s, 0.35 * s, 0.2 * s], -1)


def _photo(width=200, height=160, cx=112.0, cy=70.0, r=45.0, background=0.3, seed=0):
    """A linear 'photo': the sphere on a grey, slightly noisy background; also its alpha mask."""
    yy, xx = np.mgrid[0:height, 0:width] + 0.5
    x, y = (xx - cx) / r, -(yy - cy) / r
    inside = x * x + y * y < 1
    img = np.full((height, width, 3), background) + 0.005 * np.random.default_rng(seed).standard_normal(
        (height, width, 3))
    img[inside] = _shade(x[inside], y[inside])
    return np.clip(img, 0, 1), inside


def _canonical_truth() -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(SIZE) + 0.5) / SIZE * 2 - 1
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 1
    return _shade(x, y) * inside[..., None], inside


def _assert_matches_truth(img: np.ndarray, tol: float = 0.02) -> None:
    truth, inside = _canonical_truth()
    assert img.shape == (SIZE, SIZE, 3) and img.dtype == np.float32
    core = inside.copy()
    core[1:-1, 1:-1] &= inside[:-2, 1:-1] & inside[2:, 1:-1] & inside[1:-1, :-2] & inside[1:-1, 2:]
    # away from the rim (one pixel) the resampled sphere equals the analytic shading
    assert np.abs(img[core] - truth[core]).mean() < tol
    assert np.all(img[~inside] == 0)


def _write_png(path: Path, linear: np.ndarray, bits: int, alpha: np.ndarray | None = None) -> None:
    import OpenImageIO as oiio

    enc = spectra.srgb_encode(np.clip(linear, 0, 1))
    if alpha is not None:
        enc = np.concatenate([enc, alpha[..., None].astype(float)], -1)
    fmt, scale, dtype = (oiio.UINT8, 255, np.uint8) if bits == 8 else (oiio.UINT16, 65535, np.uint16)
    data = np.round(enc * scale).astype(dtype)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(data.shape[1], data.shape[0], data.shape[2], fmt))
    out.write_image(data)
    out.close()


def _write_exr(path: Path, linear: np.ndarray) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(linear[..., i], np.float32) for i, c in enumerate("RGBA"[:linear.shape[-1]])}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))


@pytest.mark.parametrize("bits", [8, 16])
def test_loader_finds_and_crops_an_offset_sphere_in_a_png(tmp_path, bits):
    linear, _ = _photo()
    path = tmp_path / f"sphere{bits}.png"
    _write_png(path, linear, bits)
    _assert_matches_truth(input_image.load_sphere_image(path), tol=0.02 if bits == 8 else 0.01)


def test_loader_reads_16_bit_precision(tmp_path):
    linear = np.zeros((64, 64, 3))
    yy, xx = np.mgrid[0:64, 0:64] + 0.5
    linear[(xx - 32) ** 2 + (yy - 32) ** 2 < 30 ** 2] = 0.001234  # below one 8-bit sRGB step
    _write_png(tmp_path / "dim.png", linear, 16)
    img = input_image.load_sphere_image(tmp_path / "dim.png")
    assert abs(float(img[64, 64, 0]) - 0.001234) < 2e-5


def test_loader_finds_a_scaled_sphere_in_an_exr(tmp_path):
    linear, _ = _photo(width=400, height=300, cx=180.0, cy=160.0, r=110.0)
    _write_exr(tmp_path / "sphere.exr", linear)
    _assert_matches_truth(input_image.load_sphere_image(tmp_path / "sphere.exr"), tol=0.01)


def test_loader_uses_the_alpha_channel(tmp_path):
    # Background as bright as the sphere: only alpha can tell them apart.
    linear, inside = _photo(background=0.5)
    linear[~inside] = _shade(np.zeros(1), np.zeros(1))[0]
    _write_png(tmp_path / "rgba.png", linear, 8, alpha=inside)
    _assert_matches_truth(input_image.load_sphere_image(tmp_path / "rgba.png"))


def test_loader_reads_jpeg(tmp_path):
    from PIL import Image

    linear, _ = _photo()
    enc = np.round(spectra.srgb_encode(linear) * 255).astype(np.uint8)
    Image.fromarray(enc).save(tmp_path / "sphere.jpg", quality=95)
    _assert_matches_truth(input_image.load_sphere_image(tmp_path / "sphere.jpg"), tol=0.03)


def test_loader_rejects_a_blank_image(tmp_path):
    _write_png(tmp_path / "blank.png", np.zeros((64, 64, 3)), 8)
    with pytest.raises(ImageInputError, match="blank"):
        input_image.load_sphere_image(tmp_path / "blank.png")


def test_loader_rejects_nan_and_inf(tmp_path):
    linear, _ = _photo()
    linear = linear.astype(np.float32)
    linear[10, 10, 1] = np.nan
    _write_exr(tmp_path / "nan.exr", linear)
    with pytest.raises(ImageInputError, match="NaN or Inf"):
        input_image.load_sphere_image(tmp_path / "nan.exr")
    linear[10, 10, 1] = np.inf
    with pytest.raises(ImageInputError, match="NaN or Inf"):
        input_image.prepare_sphere_array(linear)


def test_prepare_rejects_a_two_channel_array():
    # files in gray+alpha are converted to RGBA on reading (tests/house/test_bad_input.py); a raw
    # two-channel array handed to the API is still refused
    la = np.zeros((64, 64, 2))
    la[16:48, 16:48] = 0.8
    with pytest.raises(ImageInputError, match="2 channel"):
        input_image.prepare_sphere_array(la)


def test_loader_rejects_a_square_that_is_not_a_sphere():
    img = np.zeros((96, 96, 3))
    img[20:76, 20:76] = 0.7
    with pytest.raises(ImageInputError, match="not a circle"):
        input_image.prepare_sphere_array(img)


@needs_bpy
def test_canonical_input_is_deterministic_and_already_framed():
    brdf = GGXReflector(alpha=0.2, f0=0.04, kd=0.6, kd_rgb=(0.6, 0.6, 0.6))
    a = input_image.render_input(brdf)
    b = input_image.render_input(brdf)
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)  # equal up to BLAS summation order
    assert a.shape == (SIZE, SIZE, 3) and a.dtype == np.float32 and np.isfinite(a).all()
    _, inside = _canonical_truth()
    assert np.all(a[~inside] == 0) and np.all(a[inside].sum(-1) > 0)
    # the loader leaves a canonical render untouched (same framing and pixel grid)
    np.testing.assert_array_equal(input_image.prepare_sphere_array(a), a)


@needs_bpy
def test_canonical_input_exposure_keeps_a_white_lambertian_in_range():
    img = input_image.render_input(Lambertian(1.0))
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    assert 0.5 < lum.max() < 2.0


@needs_bpy
def test_training_variants_change_the_lighting_not_the_framing():
    brdf = Lambertian(0.5)
    base = input_image.render_training_input(brdf, 0)
    np.testing.assert_allclose(base, input_image.render_input(brdf), rtol=1e-6, atol=1e-7)
    other = input_image.render_training_input(brdf, 1)
    assert (other > 0).sum() == (base > 0).sum()
    assert np.abs(other - base).mean() > 0.01


@needs_bpy
def test_saved_exr_and_png_round_trip_through_the_loader(tmp_path):
    img = input_image.render_input(Lambertian(0.4))
    written = input_image.save_input(img, tmp_path / "in.exr")
    assert [p.name for p in written] == ["in.exr", "in.png"]
    np.testing.assert_array_equal(input_image.load_sphere_image(tmp_path / "in.exr"), img)
    png = input_image.load_sphere_image(tmp_path / "in.png")
    assert np.abs(png - np.clip(img, 0, 1)).max() < 0.01  # 8-bit sRGB quantisation
    with pytest.raises(OutputExistsError):
        input_image.save_input(img, tmp_path / "in.png")


@needs_bpy
def test_render_input_cli_writes_both_files(tmp_path):
    from specgen_addon.cli.app import main

    assert main(["render-input", "mat0002", "-o", str(tmp_path / "s.png"), "--quiet"]) == 0
    assert (tmp_path / "s.png").is_file() and (tmp_path / "s.exr").is_file()
    assert main(["render-input", "mat0002", "-o", str(tmp_path / "s.exr"), "--quiet"]) == 2
    assert main(["render-input", "no_such_material", "-o", str(tmp_path / "t.png"), "--quiet"]) == 2


@needs_bpy
def test_independent_photo_shares_the_lighting_but_not_the_samples():
    """The stand-in for a real photograph (no inverse crime): the canonical scene, exposure and
    framing, other environment samples. A Lambertian sphere's mean matches the canonical render's
    (both estimate the same irradiance); a sharp highlight's pixels differ by sampling noise."""
    size = 48
    matte = Lambertian(albedo=0.6)
    canonical = input_image.render_input(matte, size)
    independent = input_image.render_independent_input(matte, size)
    assert independent.shape == canonical.shape == (size, size, 3)
    np.testing.assert_allclose(independent.mean((0, 1)), canonical.mean((0, 1)), rtol=0.01)

    shiny = GGXReflector(alpha=0.05, f0=0.9, kd=0.1)
    diff = np.abs(input_image.render_independent_input(shiny, size) - input_image.render_input(shiny, size))
    assert diff.max() > 0.05 * input_image.render_input(shiny, size).max()
    sampling = input_image.independent_sampling()
    assert sampling.seed != input_image.input_sampling().seed
    assert sampling.total >= input_image.input_sampling().total
