"""Per-band conversion maths of the full-scene render (specgen_addon.bake.scene_uplift). No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.spectral import spectra
from specgen_addon.bake import scene_uplift as uplift
from specgen_addon.common.errors import SpecGenError

WL = spectra.wavelength_grid(380.0, 780.0, 21)


def test_reflectance_basis_is_mallett_yuksel_2019_and_keeps_white_flat():
    colour = pytest.importorskip("colour")
    m = uplift.reflectance_basis(WL)
    np.testing.assert_allclose(m.sum(axis=0), 1.0, atol=1e-3)       # white → reflectance 1
    rng = np.random.default_rng(0)
    for rgb in rng.random((5, 3)):
        sd = colour.recovery.RGB_to_sd_Mallett2019(rgb)              # colour-science's own
        ref = np.interp(WL, sd.wavelengths, sd.values)
        np.testing.assert_allclose(rgb @ m, ref, atol=1e-6)


@pytest.mark.parametrize("bands, atol", [(81, 2e-3), (21, 1e-2)])  # 5 nm; 20 nm (coarser sums)
def test_emission_basis_projects_back_to_the_same_rgb(bands, atol):
    wl = spectra.wavelength_grid(380.0, 780.0, bands)
    u = uplift.emission_basis(wl)
    rng = np.random.default_rng(1)
    rgb = rng.random((20, 3))
    back = spectra.spectral_to_linear_srgb(rgb @ u, wl)               # CIE 1931 CMFs, D65 white
    np.testing.assert_allclose(back, rgb, atol=atol)


@pytest.mark.parametrize("kelvin", [2000.0, 3500.0, 6500.0, 12000.0])
def test_blackbody_spectrum_has_unit_luminance_and_colour_sciences_chromaticity(kelvin):
    colour = pytest.importorskip("colour")
    wl = np.arange(380.0, 781.0, 5.0)
    b = uplift.blackbody_spectrum(kelvin, wl)
    xyz = spectra.spectral_to_xyz(b, wl)
    assert xyz[1] == pytest.approx(1.0, rel=1e-9)
    sd = colour.sd_blackbody(kelvin, colour.SpectralShape(380, 780, 5))
    ref = colour.sd_to_XYZ(sd, method="Integration")
    np.testing.assert_allclose(xyz / xyz.sum(), ref / ref.sum(), atol=2e-4)


def test_band_groups_pack_three_bands_per_render_and_unpack():
    g = uplift.band_groups(7)
    assert g.tolist() == [[0, 1, 2], [3, 4, 5], [6, 6, 6]]
    images = np.arange(3 * 2 * 2 * 3, dtype=float).reshape(3, 2, 2, 3)
    stack = uplift.unpack_groups(images, 7)
    assert stack.shape == (2, 2, 7)
    np.testing.assert_array_equal(stack[1, 0, 4], images[1, 1, 0, 1])
    with pytest.raises(SpecGenError):
        uplift.unpack_groups(images, 4)
    with pytest.raises(SpecGenError):
        uplift.blackbody_spectrum(0.0, WL)


def test_group_matrix_turns_an_rgb_colour_into_its_three_band_values():
    m = uplift.reflectance_basis(WL)
    group = uplift.band_groups(WL.size)[2]
    rgb = np.array([0.2, 0.7, 0.1])
    np.testing.assert_allclose(uplift.group_matrix(m, group) @ rgb, (rgb @ m)[group])
