"""Metrics: PSNR/SSIM per band with the documented normalisation, checked against the formulas."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.render import metrics
from specgen_addon.common.errors import SpecGenError


def test_identical_images_give_infinite_psnr_and_unit_ssim():
    gt = np.random.default_rng(0).random((24, 24, 4))
    res = metrics.spectral_metrics(gt, gt.copy())
    assert np.all(np.isinf(res.psnr)) and res.psnr_mean == np.inf
    np.testing.assert_allclose(res.ssim, 1.0)


def test_psnr_of_known_noise_matches_the_formula_per_band():
    rng = np.random.default_rng(1)
    gt = np.full((40, 40, 3), 2.0)           # constant: its 99.9th percentile (the scale) is 2
    sigma = np.array([0.02, 0.05, 0.1])
    noise = rng.standard_normal(gt.shape) * sigma
    res = metrics.spectral_metrics(gt, gt + noise)
    expected = -10 * np.log10(np.mean((noise / 2.0) ** 2, axis=(0, 1)))  # data_range 1 after /2
    np.testing.assert_allclose(res.psnr, expected, rtol=1e-9)
    assert res.psnr_mean == pytest.approx(expected.mean())
    assert res.scale == pytest.approx(2.0)


def test_errors_outside_the_mask_do_not_count():
    rng = np.random.default_rng(2)
    gt = rng.random((32, 32, 2)) + 0.5
    mask = np.zeros((32, 32), bool)
    mask[8:24, 8:24] = True
    pred = gt.copy()
    pred[~mask] += 5.0
    res = metrics.spectral_metrics(gt, pred, mask)
    assert np.all(np.isinf(res.psnr))
    assert np.all(metrics.spectral_metrics(gt, pred).psnr < 10)


def test_metrics_are_invariant_to_a_common_exposure():
    rng = np.random.default_rng(3)
    gt = rng.random((32, 32, 3))
    pred = gt + 0.03 * rng.standard_normal(gt.shape)
    a = metrics.spectral_metrics(gt, pred)
    b = metrics.spectral_metrics(7.0 * gt, 7.0 * pred)
    np.testing.assert_allclose(a.psnr, b.psnr)
    np.testing.assert_allclose(a.ssim, b.ssim)


def test_scale_ignores_a_single_hot_pixel():
    gt = np.full((64, 64, 1), 1.0)
    gt[5, 5, 0] = 1000.0  # a firefly must not decide the normalisation
    assert metrics.normalisation_scale(gt) == pytest.approx(1.0)


def test_ssim_falls_as_structure_is_destroyed():
    rng = np.random.default_rng(4)
    y, x = np.mgrid[0:48, 0:48] / 48.0
    gt = np.stack([np.sin(6 * x) * np.cos(4 * y) + 1.5] * 2, -1)
    values = [metrics.spectral_metrics(gt, gt + s * rng.standard_normal(gt.shape)).ssim_mean
              for s in (0.01, 0.1, 0.5)]
    assert 1 > values[0] > values[1] > values[2]


def test_bad_inputs_raise():
    gt = np.ones((8, 8, 2))
    with pytest.raises(SpecGenError, match="differ in shape"):
        metrics.spectral_metrics(gt, np.ones((8, 8, 3)))
    with pytest.raises(SpecGenError, match="NaN or Inf"):
        metrics.spectral_metrics(gt, np.full((8, 8, 2), np.nan))
    with pytest.raises(SpecGenError, match="black"):
        metrics.spectral_metrics(np.zeros((8, 8, 2)), gt)


def test_brightness_fit_removes_an_exposure_error_and_nothing_else():
    from specgen_addon.render.metrics import brightness_fitted_psnr, mean_psnr

    rng = np.random.default_rng(3)
    gt = rng.random((16, 16, 4)) + 0.1
    psnr_fit, k = brightness_fitted_psnr(gt, 2.0 * gt)
    assert k == pytest.approx(0.5) and psnr_fit > 100                      # a pure exposure error
    noisy = gt + rng.normal(0, 0.05, gt.shape)                               # no exposure error
    psnr_fit, k = brightness_fitted_psnr(gt, noisy)
    assert k == pytest.approx(1.0, abs=0.02)
    assert psnr_fit == pytest.approx(mean_psnr(gt, noisy), abs=0.2)
    assert mean_psnr(gt, noisy) == pytest.approx(metrics.spectral_metrics(gt, noisy).psnr_mean)


def test_colour_fit_removes_a_smooth_white_balance_error_and_not_a_shape_error():
    from specgen_addon.spectral.colour_tables import tables
    from specgen_addon.render.metrics import brightness_fitted_psnr, colour_fitted_psnr, mean_psnr

    rng = np.random.default_rng(4)
    w = np.linspace(400.0, 780.0, 20)
    gt = rng.random((16, 16, 20)) + 0.1
    t = tables()
    red = np.interp(w, t["mallett2019_wavelengths_nm"], t["mallett2019_values"][:, 0])
    tint = 0.5 + red          # the basis sums to 1 (white), so this gain lies inside its span
    psnr_fit, gain = colour_fitted_psnr(gt, gt / tint, w)  # a prediction with a smooth cyan cast
    # an exact fit leaves every band's MSE near 0, so the 1/MSE-weighted normal equations are nearly
    # singular and the last digits of the gain depend on the BLAS build (1e-5 on this 2-core EPYC)
    assert psnr_fit > 100 and np.allclose(gain, tint, rtol=1e-4, atol=0)
    # one brightness factor cannot remove a cast; the colour fit can
    assert brightness_fitted_psnr(gt, gt / tint)[0] < 40
    # a shape error (noise) is not a colour: the fit leaves it, gain ≈ 1
    noisy = gt + rng.normal(0, 0.05, gt.shape)
    psnr_fit, gain = colour_fitted_psnr(gt, noisy, w)
    assert np.allclose(gain, 1.0, atol=0.02)
    assert psnr_fit == pytest.approx(mean_psnr(gt, noisy), abs=0.2)
    with pytest.raises(SpecGenError, match="wavelengths"):
        colour_fitted_psnr(gt, noisy, w[:5])


def test_fitted_oracles_never_score_below_the_prediction_they_correct():
    """Both oracles maximise the mean band PSNR itself, and the colour fit starts from the brightness
    fit, so network ≤ brightness fitted ≤ colour fitted. A least-squares gain over all bands weighs a
    bright band above a dark one and can score *below* the unfitted prediction (it does on some of
    these draws); the fitted gain cannot."""
    from specgen_addon.render.metrics import brightness_fitted_psnr, colour_fitted_psnr, mean_psnr

    rng = np.random.default_rng(11)
    w = np.linspace(400.0, 700.0, 6)
    least_squares_lost = 0
    for _ in range(12):
        level = 10.0 ** rng.uniform(-2.5, 0.0, 6)                 # bands of very different level
        gt = (rng.random((12, 12, 6)) + 0.2) * level
        error = rng.normal(0.0, 0.02, 6) * level.max() * rng.random(6)
        pred = gt * rng.uniform(0.8, 1.2, 6) + error + rng.normal(0.0, 1e-4, gt.shape)
        plain = mean_psnr(gt, pred)
        k_ls = float(np.sum(gt * pred) / np.sum(pred * pred))
        least_squares_lost += mean_psnr(gt, k_ls * pred) < plain - 0.1
        bright = brightness_fitted_psnr(gt, pred)[0]
        assert plain - 1e-9 <= bright <= colour_fitted_psnr(gt, pred, w)[0] + 1e-9
    assert least_squares_lost > 0          # the draws include the case the old fit got wrong
