"""Generate's network evaluates bands at most 40 nm apart and interpolates the others in λ."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.model.runtime import inference as infer
from specgen_addon.spectral.spectra import wavelength_grid


def test_a_20_nm_grid_keeps_every_other_band_and_both_ends():
    wl = wavelength_grid(380.0, 780.0, 21)
    kept = infer.network_bands(wl, 40.0)
    assert np.array_equal(wl[kept], np.arange(380.0, 781.0, 40.0))


@pytest.mark.parametrize("n", [2, 5, 11, 16, 31, 41])
def test_kept_bands_are_never_more_than_the_gap_apart(n):
    wl = wavelength_grid(380.0, 780.0, n)
    kept = infer.network_bands(wl, 40.0)
    assert kept[0] == 0 and kept[-1] == n - 1
    spacing = wl[1] - wl[0]
    assert np.all(np.diff(wl[kept]) <= max(40.0, spacing) + 1e-9)
    if spacing <= 40.0:                         # the fewest: dropping any kept band opens a wider gap
        for i in range(1, kept.size - 1):
            assert wl[kept[i + 1]] - wl[kept[i - 1]] > 40.0


def test_a_grid_coarser_than_the_gap_and_no_gap_keep_every_band():
    wl = wavelength_grid(380.0, 780.0, 5)                        # 100 nm apart
    assert np.array_equal(infer.network_bands(wl, 40.0), np.arange(5))
    wl = wavelength_grid(380.0, 780.0, 21)
    assert np.array_equal(infer.network_bands(wl, None), np.arange(21))


def test_filled_bands_are_exact_for_spectra_linear_between_kept_bands():
    wl = wavelength_grid(380.0, 780.0, 21)
    kept = infer.network_bands(wl, 40.0)
    rng = np.random.default_rng(0)
    knots = rng.random((4, 3, kept.size)).astype(np.float32)   # any values at the kept bands
    truth = np.stack([np.interp(wl, wl[kept], k) for k in knots.reshape(-1, kept.size)]).reshape(4, 3, -1)
    filled = infer.fill_bands(knots, wl, kept)
    assert filled.shape == (4, 3, 21) and filled.dtype == np.float32
    np.testing.assert_array_equal(filled[..., kept], knots)
    np.testing.assert_allclose(filled, truth, rtol=1e-6, atol=1e-7)


def test_generate_brdf_with_a_gap_interpolates_the_network_between_its_own_bands(tmp_path, tiny_network):
    from specgen_addon.model import save_weights
    from specgen_addon.photo.sphere_image import render_input
    from specgen_standins import RampMaterial

    path = save_weights(tiny_network(), tmp_path / "tiny.pt")
    image = render_input(RampMaterial(), size=64)
    wl = np.array([400.0, 420.0, 440.0, 460.0, 480.0])
    full = infer.generate_brdf(image, weights=path, wavelengths_nm=wl)
    gapped = infer.generate_brdf(image, weights=path, wavelengths_nm=wl, band_gap_nm=40.0)
    kept = [0, 2, 4]
    np.testing.assert_allclose(gapped.values[..., kept], full.values[..., kept], rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(gapped.values[..., 1], 0.5 * (full.values[..., 0] + full.values[..., 2]),
                               rtol=1e-5, atol=1e-8)
    assert gapped.metadata["network_bands_nm"] == [400.0, 440.0, 480.0]
    assert "network_bands_nm" not in full.metadata
