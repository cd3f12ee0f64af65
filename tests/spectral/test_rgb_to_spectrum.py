"""RGB → spectrum: one dispatcher, one module per method (specgen_addon.spectral.rgb_to_spectrum)."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.colour_tables import mallett2019_basis, tables
from specgen_addon.spectral.mallett2019 import mallett2019_reflectance
from specgen_addon.spectral.otsu2018 import otsu2018_reflectance, xyz_of_reflectance
from specgen_addon.spectral.rgb_to_spectrum import RGB_TO_SPECTRUM_METHODS, rgb_to_spectrum, xyz_to_spectrum

WL = np.arange(400.0, 701.0, 10.0)
RGB_TO_XYZ = np.asarray(tables()["srgb_rgb_to_xyz"], np.float64)


def test_the_dispatcher_gives_each_method_module_its_own_result():
    xyz = np.array([0.2, 0.18, 0.08])
    assert np.array_equal(xyz_to_spectrum(xyz, WL, method="Otsu 2018"), otsu2018_reflectance(xyz, WL))
    rgb = np.array([[0.6, 0.3, 0.1], [0.1, 0.2, 0.7]])
    assert np.array_equal(rgb_to_spectrum(rgb, WL, method="Mallett 2019"), mallett2019_reflectance(rgb, WL))
    assert np.array_equal(rgb_to_spectrum(np.eye(3), WL, method="Mallett 2019"), mallett2019_basis(WL).T)


@pytest.mark.parametrize("method", sorted(RGB_TO_SPECTRUM_METHODS))
def test_every_method_keeps_the_colour_of_an_sRGB_input(method):
    rgb = np.array([[0.5, 0.3, 0.2], [0.2, 0.4, 0.3]])
    spectra = rgb_to_spectrum(rgb, WL, method=method)
    assert spectra.shape == (2, WL.size)
    xyz = np.stack([xyz_of_reflectance(s, WL) for s in spectra])
    np.testing.assert_allclose(xyz, rgb @ RGB_TO_XYZ.T, atol=0.01)   # 10 nm grid: a little off the exact colour
    np.testing.assert_allclose(xyz_to_spectrum(rgb @ RGB_TO_XYZ.T, WL, method=method), spectra, atol=1e-9)


def test_an_unknown_method_is_refused_with_the_known_ones():
    with pytest.raises(SpecGenError, match="unknown RGB to spectrum method 'Jakob 2019'; known: Otsu 2018, Mallett 2019"):
        rgb_to_spectrum(np.ones(3), WL, method="Jakob 2019")
