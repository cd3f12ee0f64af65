"""The shipped colour tables are colour-science's, and spectra.py computes what colour-science does."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.spectral import colour_tables
from specgen_addon.spectral import spectra
from specgen_addon.render.environment import srgb_luminance_weights, uplift_basis

colour = pytest.importorskip("colour")


def test_shipped_colour_tables_equal_a_fresh_build_from_colour_science():
    fresh = colour_tables.build_tables()
    shipped = colour_tables.tables()
    assert sorted(fresh) == sorted(shipped)
    for key, value in fresh.items():
        np.testing.assert_array_equal(shipped[key], value, err_msg=key)
    assert colour_tables.TABLES_PATH.stat().st_size < 100_000


def test_spectra_from_tables_match_colour_science():
    w = np.linspace(372.5, 812.0, 37)
    cmfs = colour.MSDS_CMFS[spectra.CMFS_NAME]
    ref = np.stack([np.interp(w, cmfs.wavelengths, cmfs.values[:, c], left=0, right=0) for c in range(3)], -1)
    np.testing.assert_array_equal(spectra.cmfs(w), ref)
    for name in ("D65", "A", "FL2"):
        sd = colour.SDS_ILLUMINANTS[name]
        got = spectra.illuminant_spd(name, w)
        np.testing.assert_allclose(got / got.max(), np.interp(w, sd.wavelengths, sd.values) /
                                   np.interp(w, sd.wavelengths, sd.values).max(), rtol=1e-12)
    white = spectra.spectral_to_xyz(spectra.illuminant_spd("A", w), w)
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    ref_cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(
        white / white[1], colour.xy_to_XYZ(srgb.whitepoint), transform="Bradford")
    np.testing.assert_allclose(spectra.white_balance_matrix(w, "A"), ref_cat, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(spectra.xyz_to_linear_srgb(np.eye(3)), srgb.matrix_XYZ_to_RGB.T, rtol=1e-12)
    np.testing.assert_allclose(srgb_luminance_weights(), srgb.matrix_RGB_to_XYZ[1], rtol=1e-12)
    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    ref_u = np.stack([np.interp(w, basis.wavelengths, basis.values[:, c]) for c in range(3)])
    np.testing.assert_allclose(uplift_basis(w), ref_u * spectra.illuminant_spd("D65", w)[None], rtol=1e-12)
    with pytest.raises(spectra.SpecGenError, match="unknown illuminant"):
        spectra.illuminant_spd("D99", w)


def test_srgb_transfer_functions_match_colour_science():
    x = np.concatenate([np.linspace(-0.2, 1.5, 2001), [0.0031308, 0.04045]])
    np.testing.assert_allclose(spectra.srgb_encode(x), colour.cctf_encoding(x, function="sRGB"),
                               rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(spectra.srgb_decode(x), colour.cctf_decoding(x, function="sRGB"),
                               rtol=1e-13, atol=1e-15)
