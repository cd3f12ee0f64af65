import colour
import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.spectra import (DEFAULT_WAVELENGTHS_NM, cmfs, illuminant_spd,
                                   reflectance_to_linear_srgb, spectral_to_xyz, srgb_decode,
                                   srgb_encode, wavelength_grid)


def test_default_grid_covers_cie_visible_range():
    assert DEFAULT_WAVELENGTHS_NM[0] == 380 and DEFAULT_WAVELENGTHS_NM[-1] == 780
    assert len(DEFAULT_WAVELENGTHS_NM) == 21


def test_grid_accepts_up_to_360_1000_and_rejects_beyond():
    assert wavelength_grid(360, 1000, 65)[-1] == 1000
    with pytest.raises(SpecGenError):
        wavelength_grid(300, 800, 10)
    with pytest.raises(SpecGenError):
        wavelength_grid(400, 700, 0)


def test_cmfs_match_colour_science_at_sample_points():
    cm = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    assert np.allclose(cmfs(np.array([555.0]))[0], cm[555], atol=1e-12)


def test_illuminant_has_unit_luminance_on_grid():
    w = wavelength_grid(380, 780, 81)
    assert spectral_to_xyz(illuminant_spd("D65", w), w)[1] == pytest.approx(1.0)


@pytest.mark.parametrize("count", [5, 21, 81, 401])
def test_flat_reflectance_under_d65_is_neutral(count):
    w = wavelength_grid(380, 780, count)
    rgb = reflectance_to_linear_srgb(np.full(count, 0.4), w)
    assert np.allclose(rgb, 0.4, rtol=1e-3)


def test_fine_grid_matches_colour_science_sd_to_xyz():
    # Independent reference: colour.sd_to_XYZ of the ColorChecker "red" patch under D65.
    sd = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]["red"]
    w = np.arange(380.0, 781.0, 5.0)
    refl = np.interp(w, sd.wavelengths, sd.values)
    ours = spectral_to_xyz(refl * illuminant_spd("D65", w), w)
    ref = colour.sd_to_XYZ(sd.copy().align(colour.SpectralShape(380, 780, 5)),
                           illuminant=colour.SDS_ILLUMINANTS["D65"]) / 100
    assert np.allclose(ours, ref, atol=3e-3)


def test_srgb_transfer_round_trip():
    x = np.linspace(0, 1, 50)
    assert np.allclose(srgb_decode(srgb_encode(x)), x, atol=1e-10)
    assert srgb_encode(np.array([0.0031308]))[0] == pytest.approx(0.0031308 * 12.92, rel=1e-6)
