"""The photo-only baselines: NNLS, the analytic BRDF fit to a sphere photo, and exact albedo uplifting."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.spectral import spectra
from specgen_addon.evaluation import baselines, photo_fit


def test_nnls_solves_a_hand_case_with_an_active_bound():
    # min (x1 − 2)² + (x2 + 1)² + (x1 + x2 − 1)²: unconstrained (2, −1); with x ≥ 0, x2 = 0 and
    # x1 = argmin (x1 − 2)² + (x1 − 1)² = 1.5 (KKT: ∂/∂x2 = 2 + 1 > 0 there).
    a = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    b = np.array([2.0, -1.0, 1.0])
    np.testing.assert_allclose(photo_fit.nnls(a, b), [1.5, 0.0], atol=1e-9)
    np.testing.assert_allclose(photo_fit.nnls(a, np.array([1.0, 2.0, 3.0])), [1.0, 2.0], atol=1e-9)


def test_nnls_matches_scipy_on_random_problems():
    from scipy.optimize import nnls as scipy_nnls

    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.normal(size=(40, 8))
        b = rng.normal(size=40)
        mine = photo_fit.nnls(a, b)
        ref, _ = scipy_nnls(a, b)
        assert np.all(mine >= 0)
        np.testing.assert_allclose(np.linalg.norm(a @ mine - b), np.linalg.norm(a @ ref - b), rtol=1e-9)
        np.testing.assert_allclose(mine, ref, atol=1e-7)


@pytest.fixture(scope="module")
def input_scene():
    """The canonical input lighting (studio map + D65 key light) on a 64² sphere (fast)."""
    from specgen_addon.photo import sphere_image as input_image

    return input_image._scene(input_image.CANONICAL_ENV, 0.0, 64), input_image.EXPOSURE


def test_fit_recovers_an_analytic_ggx_material_under_the_input_lighting(input_scene):
    """An independent GGX implementation (render.analytic: separable Smith, Schlick) rendered under
    the input scene comes back: roughness within one grid step, colours within a few per cent."""
    from specgen_addon.render.analytic import GGXReflector

    scene, exposure = input_scene
    truth = GGXReflector(alpha=0.3, f0=0.04, kd_rgb=(0.6, 0.3, 0.1))
    photo = scene.render_rgb(truth).rgb * exposure
    fit = photo_fit.fit_photo(photo, scene, exposure, coat_alphas=(), refine_steps=4, rounds=1)
    b = fit.brdf
    step = photo_fit.ALPHA_GRID[1] / photo_fit.ALPHA_GRID[0]
    assert 1 / step <= b.alpha / truth.alpha <= step
    np.testing.assert_allclose(b.diffuse, truth.kd_rgb, rtol=0.03)
    np.testing.assert_allclose(b.f0, [truth.f0] * 3, rtol=0.15)
    assert fit.residual < 0.02


def test_fit_recovers_its_own_model_with_a_coat_exactly_on_the_grid(input_scene):
    """Rendering is linear in the BRDF: on grid roughnesses the colours are solved exactly."""
    scene, exposure = input_scene
    alpha, coat_alpha = photo_fit.ALPHA_GRID[13], photo_fit.COAT_ALPHA_GRID[3]
    truth = photo_fit.AnalyticRGB((0.2, 0.5, 0.3), (0.9, 0.6, 0.3), alpha, 0.8, 0.5, coat_alpha)
    photo = scene.render_rgb(truth).rgb * exposure
    fit = photo_fit.fit_photo(photo, scene, exposure, alphas=photo_fit.ALPHA_GRID[10:16],
                              coat_alphas=photo_fit.COAT_ALPHA_GRID[:6], refine_steps=0)
    assert (fit.brdf.alpha, fit.brdf.coat_alpha) == (alpha, coat_alpha)
    np.testing.assert_allclose(fit.brdf.diffuse + fit.brdf.f0, truth.diffuse + truth.f0, rtol=1e-6)
    np.testing.assert_allclose([fit.brdf.edge, fit.brdf.coat], [truth.edge, truth.coat], rtol=1e-6)
    assert fit.residual < 1e-8


def test_fit_refuses_a_black_photo_and_a_wrong_size(input_scene):
    from specgen_addon.common.errors import SpecGenError

    scene, exposure = input_scene
    with pytest.raises(SpecGenError, match="black"):
        photo_fit.fit_photo(np.zeros((64, 64, 3)), scene, exposure)
    with pytest.raises(SpecGenError, match="shape"):
        photo_fit.fit_photo(np.ones((32, 32, 3)), scene, exposure)


def test_spectral_fit_with_flat_spectra_equals_the_rgb_fit():
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(200, 3))
    wo = rng.normal(size=(200, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    rgb = photo_fit.AnalyticRGB((0.4,) * 3, (0.05,) * 3, 0.2, 1.0, 0.3, 0.05)
    wl = np.array([400.0, 550.0, 700.0])
    spec = photo_fit.AnalyticSpectral(wl, np.full(3, 0.4), np.full(3, 0.05), 0.2, 1.0, 0.3, 0.05)
    np.testing.assert_allclose(spec.eval(wi, wo, wl), np.repeat(rgb.eval_rgb(wi, wo)[:, :1], 3, axis=1),
                               rtol=1e-12)


@pytest.mark.parametrize("method, tol", [(baselines.MALLETT2019, 0.01), (baselines.OTSU2018, 0.02),
                                         (baselines.JAKOB2019, 0.02), (baselines.SMITS1999, 0.2)])
def test_albedo_uplifting_reproduces_the_colour(method, tol):
    """Each fitted colour is uplifted exactly (no face table): under D65 it gives its RGB back
    (Smits 1999 only roughly: its seven fitted spectra do not round-trip, see test_evaluation)."""
    rgb = np.array([[0.6, 0.3, 0.1], [0.05, 0.4, 0.2], [0.04, 0.04, 0.04], [0.9, 0.6, 0.3], [0.0, 0.0, 0.0]])
    wl = baselines.LUT_WAVELENGTHS_NM
    rho = baselines.uplift_albedo(rgb, method, wl)
    assert np.all(rho[-1] == 0.0) and np.all(rho >= -1e-9)
    back = spectra.reflectance_to_linear_srgb(rho[:-1], wl)
    rel = np.abs(back - rgb[:-1]).max(axis=1) / rgb[:-1].max(axis=1)
    assert rel.max() < tol, rel
