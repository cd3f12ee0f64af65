"""Native closure fit (specgen_addon.bake.closure_fit.closures): model, recovery, reported error. No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.bake.closure_fit import ClosureFit, fit_closures, ggx_lobe, rgb_standin
from specgen_addon.bake.closure_fit.closures import (StackClosure, fresnel_dielectric, group_closures, stack_layout,
                                       standin_closures)
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([420.0, 500.0, 580.0, 660.0])
RHO = np.array([0.1, 0.5, 0.3, 0.2])
SPEC = np.array([0.8, 0.5, 0.3, 0.1])


def _dirs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


def test_ggx_lobe_matches_the_textbook_height_correlated_smith_form():
    # Second formulation: G2 = 1 / (1 + Λ(θi) + Λ(θo)), Λ = (√(1 + α² tan²θ) − 1) / 2 (Heitz 2014).
    wi, wo = _dirs(2000)
    r = 0.4
    a2 = r ** 4
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    d = a2 / (np.pi * (h[:, 2] ** 2 * (a2 - 1) + 1) ** 2)
    lam = lambda c: (np.sqrt(1 + a2 * (1 - c * c) / (c * c)) - 1) / 2  # noqa: E731
    ref = d / (1 + lam(wi[:, 2]) + lam(wo[:, 2])) / (4 * wi[:, 2] * wo[:, 2])
    np.testing.assert_allclose(ggx_lobe(wi, wo, r), ref, rtol=1e-9)
    below = wi.copy()
    below[:, 2] *= -1
    assert np.all(ggx_lobe(below, wo, r) == 0)


def test_ggx_lobe_albedo_at_normal_incidence_is_bounded_by_the_visible_microfacets():
    # At normal incidence wo = reflect(z, h) lies above the horizon only for θh < 45°; GGX puts
    # P(tan²θh < 1) = 1/(1 + α²) of its projected normals there, so ∫ f cos θo dωo ≤ 1/(1 + α²),
    # and the Smith masking G₂ ≤ 1 takes a little more.
    n = 400_000
    rng = np.random.default_rng(1)
    u1, u2 = rng.random(n), rng.random(n)
    wo = np.stack([np.sqrt(u1) * np.cos(2 * np.pi * u2), np.sqrt(u1) * np.sin(2 * np.pi * u2),
                   np.sqrt(1 - u1)], -1)                  # cosine-weighted: pdf = cos/π
    wi = np.tile([0.0, 0.0, 1.0], (n, 1))
    albedos = []
    for r in (0.2, 0.6, 0.8):
        bound = 1.0 / (1.0 + r ** 4)
        albedos.append(np.mean(ggx_lobe(wi, wo, r) * np.pi))
        assert 0.75 * bound < albedos[-1] <= bound + 0.005, (r, albedos[-1], bound)
    assert albedos[0] > 0.97 and albedos[0] > albedos[1] > albedos[2]


def _model_table(roughness=(0.3,), weights=(SPEC,), rho=RHO) -> BRDFTable:
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        out = above * rho[None] / np.pi
        for r, w in zip(roughness, weights):
            out = out + ggx_lobe(wi, wo, r)[:, None] * w[None]
        return out
    return BRDFTable.tabulate(fn, WL)


@pytest.fixture(scope="module")
def model_table() -> BRDFTable:
    return _model_table()


def test_fit_recovers_a_diffuse_plus_ggx_material(model_table):
    fit = fit_closures(model_table)
    np.testing.assert_allclose(fit.diffuse, RHO, atol=3e-3)
    # one true lobe: the fit may split it into two nearly equal roughnesses; their sum is the tint
    np.testing.assert_allclose(fit.roughness, 0.3, atol=0.01)
    np.testing.assert_allclose(fit.specular.sum(axis=0), SPEC, rtol=0.01)
    assert fit.max_error < 1e-3
    assert not np.any(fit.diffuse_fresnel > 1e-3) and not np.any(fit.specular_fresnel > 1e-3)
    assert not fit.per_band_lobes.any()                       # shared roughness: one closure per term
    assert all(c.channel is None for c in stack_layout(fit))
    wi, wo = _dirs(500, seed=2)
    ref = RHO[None] / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * SPEC[None]   # the analytic model
    np.testing.assert_allclose(fit.eval(wi, wo), ref, rtol=0.02, atol=1e-3 * ref.max())


def test_fit_recovers_a_fresnel_weighted_plastic():
    # Lambert · (1 − F(θo)) + GGX · F(θo), F the dielectric Fresnel of Cycles' Fresnel node (η 1.5)
    def plastic(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        f = fresnel_dielectric(wo[:, 2], 1.5)[:, None]
        return above * RHO[None] / np.pi * (1 - f) + ggx_lobe(wi, wo, 0.2)[:, None] * f * 3 * SPEC[None]
    fit = fit_closures(BRDFTable.tabulate(plastic, WL))
    assert fit.max_error < 1e-3
    assert {"Diffuse Fresnel", "Lobe 1 Fresnel"} <= {t[0] for t in fit.terms()}
    np.testing.assert_allclose(fit.diffuse_fresnel, RHO, rtol=0.01)
    wi, wo = _dirs(500, seed=5)
    np.testing.assert_allclose(fit.eval(wi, wo), plastic(*__import__("specgen_addon.brdf.rusinkiewicz",
                               fromlist=["half_diff_from_io"]).half_diff_from_io(wi, wo)),
                               rtol=0.03, atol=1e-3)


def test_fresnel_matches_the_textbook_dielectric_values():
    assert fresnel_dielectric(np.array([1.0]), 1.5)[0] == pytest.approx(0.04)      # ((η−1)/(η+1))²
    assert fresnel_dielectric(np.array([0.0]), 1.5)[0] == pytest.approx(1.0)
    assert fresnel_dielectric(np.array([0.5]), 1 / 1.5)[0] == pytest.approx(1.0)    # total reflection


def test_fit_reports_a_large_error_for_a_material_outside_the_model():
    def retro(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        back = np.clip(np.sum(wi * wo, -1), 0, 1) ** 8  # retro-reflection: no GGX lobe does this
        return (back * ((wi[:, 2] > 0) & (wo[:, 2] > 0)))[:, None] * np.ones(WL.size)
    fit = fit_closures(BRDFTable.tabulate(retro, WL))
    assert fit.max_error > 0.2


def test_fit_roundtrips_through_json_and_interpolates_bands(model_table):
    fit = fit_closures(model_table, max_lobes=1)
    assert fit.roughness.shape == (1, WL.size) and fit.specular.shape == (1, WL.size)
    back = ClosureFit.from_json(fit.to_json())
    for a in ("wavelengths_nm", "diffuse", "roughness", "specular", "rel_error", "diffuse_fresnel",
              "specular_fresnel", "ior"):
        np.testing.assert_array_equal(getattr(back, a), getattr(fit, a))
    mid = fit.at(np.array([460.0]))
    np.testing.assert_allclose(mid.diffuse, (fit.diffuse[0] + fit.diffuse[1]) / 2)
    with pytest.raises(SpecGenError):
        ClosureFit.from_json("{not json")
    with pytest.raises(SpecGenError):
        fit_closures(model_table.to_rgb())


def test_rgb_standin_of_a_flat_spectrum_is_grey():
    wl = np.linspace(380, 780, 21)
    fit = ClosureFit(wl, np.full(21, 0.5), np.array([0.3]), np.full((1, 21), 0.04), np.zeros(21))
    colours = rgb_standin(fit)
    assert set(colours) == {"Diffuse", "Lobe 1"}                # zero closures are left out
    np.testing.assert_allclose(colours["Diffuse"], 0.5, atol=2e-3)
    np.testing.assert_allclose(colours["Lobe 1"], 0.04, atol=2e-4)


# ------------------------------------------------------------------------- per-band roughness
WL6 = np.array([420.0, 470.0, 520.0, 570.0, 620.0, 670.0])
R6 = np.geomspace(0.15, 0.45, WL6.size)     # the lobe widens with λ: r(λ) ∝ exp(λ)
RHO6 = np.linspace(0.1, 0.5, WL6.size)
SPEC6 = np.linspace(0.8, 0.3, WL6.size)


def _per_band_lobe(wi, wo):
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return above * RHO6 / np.pi + np.stack([ggx_lobe(wi, wo, r) for r in R6], -1) * SPEC6


@pytest.fixture(scope="module")
def per_band_table() -> BRDFTable:
    return BRDFTable.tabulate(lambda th, td, pd: _per_band_lobe(*io_from_half_diff(th, td, pd)), WL6)


def test_fit_recovers_a_lobe_whose_roughness_varies_with_wavelength(per_band_table):
    shared = fit_closures(per_band_table, max_lobes=1, per_band=False)
    fit = fit_closures(per_band_table, max_lobes=1)
    assert shared.max_error > 0.05                              # one roughness cannot do it
    assert fit.max_error < 0.01 and fit.per_band_lobes.tolist() == [True]
    np.testing.assert_allclose(fit.roughness[0], R6, rtol=0.005)
    np.testing.assert_allclose(fit.specular[0] + fit.specular_fresnel[0] * 0.04, SPEC6, rtol=0.05)
    wi, wo = _dirs(800, seed=7)
    ref = _per_band_lobe(wi, wo)
    np.testing.assert_allclose(fit.eval(wi, wo), ref, rtol=0.03, atol=2e-3 * ref.max())
    back = ClosureFit.from_json(fit.to_json())                  # per-band roughness survives JSON
    np.testing.assert_array_equal(back.roughness, fit.roughness)
    np.testing.assert_allclose(fit.at(np.array([445.0])).roughness[0], (fit.roughness[0, 0] + fit.roughness[0, 1]) / 2)


def test_two_lobe_fit_of_a_per_band_lobe_reproduces_the_table(per_band_table):
    fit = fit_closures(per_band_table)                          # the bake's default: up to 2 lobes
    assert fit.max_error < 0.01
    wi, wo = _dirs(800, seed=8)
    ref = _per_band_lobe(wi, wo)
    np.testing.assert_allclose(fit.eval(wi, wo), ref, rtol=0.05, atol=3e-3 * ref.max())


def test_json_of_one_roughness_per_lobe_still_reads():
    fit = ClosureFit.from_json('{"wavelengths_nm": [450, 550, 650], "diffuse": [0.1, 0.2, 0.3], '
                               '"roughness": [0.3], "specular": [[0.5, 0.5, 0.5]], "rel_error": [0, 0, 0]}')
    np.testing.assert_array_equal(fit.roughness, [[0.3, 0.3, 0.3]])


def _split_fit() -> ClosureFit:
    wl = np.linspace(400, 700, 7)
    rough = np.array([[0.2, 0.2, 0.2, 0.3, 0.4, 0.5, 0.6]])
    return ClosureFit(wl, np.full(7, 0.3), rough, np.full((1, 7), 0.5), np.zeros(7),
                      specular_fresnel=np.full((1, 7), 0.2))


def test_a_per_band_lobe_is_three_closures_and_a_constant_group_uses_one():
    fit = _split_fit()
    layout = stack_layout(fit)
    assert [c.name for c in layout] == ["Diffuse", "Lobe 1 (R)", "Lobe 1 (G)", "Lobe 1 (B)",
                                        "Lobe 1 Fresnel (R)", "Lobe 1 Fresnel (G)", "Lobe 1 Fresnel (B)"]
    assert layout[1] == StackClosure("Lobe 1 (R)", "Lobe 1", 0, True, False)
    same = group_closures(fit, np.array([0, 1, 2]), layout)     # r = 0.2 in all three bands
    np.testing.assert_allclose(same["Lobe 1 (R)"][0], 0.5)
    assert same["Lobe 1 (R)"][1] == pytest.approx(0.2)
    assert not same["Lobe 1 (G)"][0].any() and not same["Lobe 1 (B)"][0].any()   # skipped by Cycles
    np.testing.assert_allclose(same["Diffuse"][0], 0.3)
    assert same["Diffuse"][1] is None
    varied = group_closures(fit, np.array([3, 4, 5]), layout)   # 0.3, 0.4, 0.5: one band per channel
    for j, ch in enumerate("RGB"):
        colour, r = varied[f"Lobe 1 Fresnel ({ch})"]
        np.testing.assert_allclose(colour, np.where(np.arange(3) == j, 0.2, 0.0))
        assert r == pytest.approx([0.3, 0.4, 0.5][j])
    standin = standin_closures(fit, layout)                     # RGB: long waves are rougher
    assert standin["Lobe 1 (R)"][1] > standin["Lobe 1 (G)"][1] > standin["Lobe 1 (B)"][1]
    np.testing.assert_allclose(standin["Lobe 1 (R)"][0], [rgb_standin(fit)["Lobe 1"][0], 0, 0])
