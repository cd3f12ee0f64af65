"""Photo-consistent refinement: analytic recovery, never worse than the network, numpy-only path."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.photo.photo_lighting import InputLighting, LightingError, parse_lighting
from specgen_addon.generate.refine import (CorrectionBasis, RefineOptions, apply_correction, diffuse_floor_of,
                                  refine_brdf, render_under)
from specgen_addon.generate.refine.basis import hat_matrix
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.generate.refine.solve import nonneg_ridge
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable
from specgen_standins import RampMaterial

SIZE = 48
WL = np.linspace(380.0, 780.0, 9)


def _tinted(table: BRDFTable, tint: np.ndarray) -> BRDFTable:
    return BRDFTable(table.values * tint.astype(np.float32), table.wavelengths)


def test_hats_are_a_partition_of_unity_and_interpolate_knots():
    knots = np.array([0.0, 2.0, 7.0, 89.0])
    x = np.linspace(-3, 95, 200)
    h = hat_matrix(x, knots)
    assert np.allclose(h.sum(axis=1), 1.0)
    assert np.allclose(hat_matrix(knots, knots), np.eye(4))
    assert np.all(h >= 0)


def test_nonneg_ridge_matches_unconstrained_solution_when_interior_and_binds_negatives():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 5))
    x_true = np.array([1.0, 2.0, 0.5, 3.0, 1.5])
    g, r = a.T @ a, a.T @ (a @ x_true)
    assert np.allclose(nonneg_ridge(g, r), x_true)
    # a target with a negative coordinate: the solution is feasible and satisfies KKT
    x_neg = np.array([1.0, -2.0, 0.5, 3.0, -1.0])
    r = a.T @ (a @ x_neg)
    sol = nonneg_ridge(g, r)
    grad = g @ sol - r
    assert np.all(sol >= 0)
    assert np.all(np.abs(grad[sol > 1e-9]) < 1e-8)       # stationary on the free set
    assert np.all(grad[sol <= 1e-9] >= -1e-8)             # pointing outward on the bound set


def test_photo_operator_reproduces_the_renderer_for_the_identity_correction(ramp_table):
    """The design at θ = identity equals the reference renderer's photo of the table."""
    light = InputLighting()
    scene = light.scene(SIZE)
    op = PhotoOperator(scene, WL, light.image_exposure)
    basis = CorrectionBasis()
    floor = diffuse_floor_of(ramp_table)
    s_hats = basis.spectral_hats(WL)
    lobe = op.lobe_design(ramp_table.values, floor, basis).reshape(op.n_pixels, 3, -1).sum(axis=2)
    body = op.lambert_design(floor, s_hats).sum(axis=2)
    model = lobe + body
    photo = op.observe(render_under(ramp_table, scene, light.image_exposure))
    rel = np.abs(model - photo).max() / photo.max()
    assert rel < 2e-3


def test_known_spectral_tint_is_recovered_from_its_own_render(ramp_table):
    """A table × a tint inside the spectral basis is recovered to ≤ 1 % from its own photo (with the
    network's body spectrum kept: the correction alone). The photo shares the operator's samples, so
    the fit may go below the sampling error (``fit_floor=None``): this checks the solver's exactness."""
    basis = CorrectionBasis()
    knots_value = np.array([0.6, 1.05, 1.4])
    tint = basis.spectral_hats(WL) @ knots_value
    truth = _tinted(ramp_table, tint)
    light = InputLighting()
    photo = render_under(truth, light.scene(SIZE), light.image_exposure)
    res = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, body_prior="network",
                                                              fit_floor=None))
    err = np.linalg.norm(res.table.values - truth.values) / np.linalg.norm(truth.values)
    assert err <= 0.01, f"relative table error {err:.4f}"
    assert res.after.psnr_db > 45.0
    assert res.improved


def test_brightness_and_separate_specular_tint_are_fitted(ramp_table):
    """Lobe tinted red and body darkened: both corrections at once reproduce the photo."""
    floor = diffuse_floor_of(ramp_table)
    basis = CorrectionBasis()
    x = np.ones(basis.shape)
    x[..., :] = [0.3, 0.8, 1.6]                       # a warm highlight
    truth = apply_correction(ramp_table, floor, x, np.array([0.5, 0.5, 0.5]), np.zeros(3), basis)
    light = InputLighting()
    photo = render_under(truth, light.scene(SIZE), light.image_exposure)
    res = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    assert res.before.psnr_db < 30.0
    assert res.after.psnr_db > 45.0
    assert res.after.delta_e2000 < 0.5


@pytest.mark.parametrize("kind", ["noise", "other_material", "black"])
def test_refinement_never_makes_self_reproduction_worse(ramp_table, kind):
    light = InputLighting()
    rng = np.random.default_rng(1)
    if kind == "noise":
        photo = rng.random((SIZE, SIZE, 3)) * 0.8
    elif kind == "other_material":
        other = BRDFTable(np.roll(ramp_table.values, 30, axis=0) * 2.0, WL)
        photo = render_under(other, light.scene(SIZE), light.image_exposure)
    else:
        photo = np.zeros((SIZE, SIZE, 3))
    res = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    assert res.after.psnr_db >= res.before.psnr_db - 1e-9
    if kind in ("noise", "black"):
        assert any("does not explain" in w or "black" in w for w in res.warnings)


def test_unexplained_photo_warns_with_the_residual(ramp_table):
    """A photo taken under another map than the one claimed gets a warning quoting the residual."""
    truth = ramp_table
    photo = render_under(truth, parse_lighting("night").scene(SIZE), 0.5) * 3.0
    res = refine_brdf(ramp_table, photo, InputLighting(), RefineOptions(clip_level=None))
    if res.after.psnr_db < 30.0:
        assert any(f"{res.after.psnr_db:.1f} dB" in w for w in res.warnings)
    else:  # the refinement explained it after all: no warning is due
        assert not any("does not explain" in w for w in res.warnings)


def test_clipped_photo_is_warned_about(ramp_table):
    light = InputLighting()
    photo = np.clip(render_under(ramp_table, light.scene(SIZE), light.image_exposure) * 20.0, 0, 1)
    res = refine_brdf(ramp_table, photo, light)
    assert res.clipped_fraction > 0.25
    assert any("clipped" in w for w in res.warnings)


def test_refinement_cancel_raises_cancelled(ramp_table):
    light = InputLighting()
    photo = render_under(ramp_table, light.scene(SIZE), light.image_exposure)
    with pytest.raises(Cancelled):
        refine_brdf(ramp_table, photo, light, cancel=lambda: True)


def test_refinement_rejects_rgb_tables_and_bad_photos(ramp_table):
    with pytest.raises(SpecGenError, match="spectral"):
        refine_brdf(ramp_table.to_rgb(), np.zeros((SIZE, SIZE, 3)))
    with pytest.raises(SpecGenError, match="square"):
        refine_brdf(ramp_table, np.zeros((SIZE, SIZE + 1, 3)))
    bad = np.zeros((SIZE, SIZE, 3))
    bad[3, 3] = np.nan
    with pytest.raises(SpecGenError, match="NaN"):
        refine_brdf(ramp_table, bad)


def test_input_lighting_validates_names_files_and_values(tmp_path):
    assert parse_lighting(None).is_canonical
    assert parse_lighting("canonical").key_light
    assert not parse_lighting("forest", 30).key_light
    with pytest.raises(LightingError, match="no bundled map"):
        parse_lighting("nowhere")
    with pytest.raises(LightingError, match="no such HDRI"):
        parse_lighting(str(tmp_path / "missing.hdr"))
    with pytest.raises(LightingError, match="neither"):
        parse_lighting("../world/studio")
    with pytest.raises(LightingError, match="exposure"):
        parse_lighting("forest", 0.0, float("nan"))


def test_user_hdr_file_lights_like_the_same_map_as_exr(tmp_path):
    """A Radiance .hdr written by OpenImageIO (a reader no one here wrote) gives the same lighting."""
    oiio = pytest.importorskip("OpenImageIO")
    from specgen_addon.render.environment_maps import env_path
    from specgen_addon.render.environment import read_exr_rgb

    rgb = read_exr_rgb(env_path("forest"))[::4, ::4].copy()
    path = tmp_path / "forest_small.hdr"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.FLOAT))
    out.write_image(rgb)
    out.close()
    user = parse_lighting(str(path))
    bundled = parse_lighting("forest")
    a, b = user.white_sphere_rgb(), bundled.white_sphere_rgb()
    assert np.allclose(a, b, rtol=0.03), (a, b)


def test_network_gain_brings_a_map_to_the_canonical_white_level():
    g = parse_lighting("sunset").network_gain()
    white = parse_lighting("sunset").white_sphere_rgb()
    assert np.allclose(white * g, InputLighting().white_sphere_rgb())
    assert np.allclose(InputLighting().network_gain(), 1.0)


def test_refinement_runs_with_only_numpy_importable(tmp_path, ramp_table, numpy_only):
    """The panel's path: numpy only (torch, scipy, scikit-image, Pillow, colour-science and OpenEXR blocked)."""
    path = tmp_path / "t.npz"
    ramp_table.save(path)
    out = numpy_only(f"""
        import numpy as np
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.photo.photo_lighting import InputLighting
        from specgen_addon.generate.refine import refine_brdf, render_under, RefineOptions
        t = BRDFTable.load({str(path)!r})
        light = InputLighting()
        photo = render_under(BRDFTable(t.values * 1.3, t.wavelengths), light.scene({SIZE}), 0.5)
        res = refine_brdf(t, photo, light, RefineOptions(clip_level=None))
        assert res.after.psnr_db > 45, res.summary()
        assert 'torch' not in sys.modules and 'scipy' not in sys.modules
        print('ok', res.summary())
    """)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("ok")


def test_a_coarse_table_is_scored_on_the_fine_render_grid(ramp_table):
    """A 5-band table: the photo model integrates light and camera on the 21-band grid, so the
    refinement reproduces a photo rendered at 21 bands as well as a fine table would."""
    from specgen_addon.generate.refine.operator import render_grid

    coarse_wl = np.linspace(380.0, 780.0, 5)
    coarse = BRDFTable(ramp_table.values[..., ::2], coarse_wl)
    assert np.allclose(render_grid(coarse_wl), np.linspace(380.0, 780.0, 21))
    light = InputLighting()
    truth = _tinted(ramp_table, np.linspace(0.7, 1.3, WL.size))
    photo = render_under(truth, light.scene(SIZE), light.image_exposure)
    res = refine_brdf(coarse, photo, light, RefineOptions(clip_level=None))
    assert res.after.psnr_db > 40.0, res.summary()


def test_default_spectral_correction_is_mallett_2019_as_colour_science_has_it():
    """The three spectral functions are colour-science's Mallett & Yuksel basis (blue, green, red),
    a partition of unity (so the identity correction is x = 1); 'hats' stays available."""
    colour = pytest.importorskip("colour")
    wl = np.arange(380.0, 781.0, 20.0)
    s = CorrectionBasis().spectral_hats(wl)
    reference = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019.copy().align(
        colour.SpectralShape(380, 780, 5))
    expected = np.stack([np.interp(wl, reference.wavelengths, reference.values[:, c]) for c in (2, 1, 0)], 1)
    np.testing.assert_allclose(s, expected, atol=1e-6)
    np.testing.assert_allclose(s.sum(axis=1), 1.0, atol=1e-4)
    hats = CorrectionBasis(spectral="hats").spectral_hats(wl)
    np.testing.assert_allclose(hats.sum(axis=1), 1.0)
    assert np.count_nonzero(hats[:, 0]) < wl.size            # hats are local, Mallett's are not
    with pytest.raises(SpecGenError, match="spectral correction basis"):
        CorrectionBasis(spectral="otsu")


def _with_body(table: BRDFTable, body: np.ndarray) -> BRDFTable:
    """``table`` with its diffuse floor replaced by ``body`` (sr⁻¹ per band)."""
    floor = diffuse_floor_of(table)
    return BRDFTable((table.values - floor + body).astype(np.float32), table.wavelengths)


@pytest.fixture(scope="module")
def ramp_table_21() -> BRDFTable:
    mat = RampMaterial(a=0.4, b=0.0, alpha=0.2, f0=0.05)      # a grey body under a white lobe
    wl = np.linspace(380.0, 780.0, 21)

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return mat.eval(wi, wo, wl)

    return BRDFTable.tabulate(fn, wl)


def _ochre_body_photo(table: BRDFTable):
    """An ochre Otsu-basis reflectance (Λ,), the canonical lighting, and the photo of ``table``
    with that body."""
    from specgen_addon.spectral.otsu2018 import otsu2018_reflectance

    rho = otsu2018_reflectance(np.array([0.25, 0.20, 0.08]), table.wavelengths)
    light = InputLighting()
    return rho, light, render_under(_with_body(table, rho / np.pi), light.scene(SIZE), light.image_exposure)


def test_a_natural_body_spectrum_is_recovered_from_a_grey_prior(ramp_table_21):
    """The network predicts a grey body; the photo shows an Otsu-basis reflectance. The default
    body prior recovers that spectrum (its shape, not only its colour); the network body prior
    keeps a tinted grey that has the colour but not the shape."""
    rho, light, photo = _ochre_body_photo(ramp_table_21)
    errs = {}
    for prior in ("otsu2018", "network"):
        res = refine_brdf(ramp_table_21, photo, light, RefineOptions(clip_level=None, body_prior=prior))
        got = diffuse_floor_of(res.table) * np.pi
        errs[prior] = float(np.sqrt(np.mean((got - rho) ** 2)) / rho.mean())
        assert res.after.psnr_db > 40.0, res.summary()
        assert res.coefficients["body_prior"] == prior
    assert errs["otsu2018"] < 0.03, errs
    assert errs["network"] > 2 * errs["otsu2018"], errs


def test_a_metal_keeps_the_network_body_spectrum():
    """A table whose lobe has its floor's colour (a conductor) is not given a diffuse body."""
    from specgen_addon.generate.refine.body import has_separate_body

    wl = np.linspace(380.0, 780.0, 21)
    colour_ = np.linspace(0.4, 0.95, wl.size)                           # copper-like, rising to red
    values = np.zeros((90, 90, 180, wl.size), np.float32)
    values[:] = 0.05 * colour_
    values[:20] += (5.0 * colour_).astype(np.float32)                    # the lobe, same colour
    floor = 0.05 * colour_
    assert not has_separate_body(values, floor, wl)
    values[:20] = 0.05 * colour_ + 5.0                                   # white lobe: a dielectric
    assert has_separate_body(values, floor, wl)
    assert has_separate_body(values * 0 + floor.astype(np.float32), floor, wl)   # no lobe at all


def test_a_blended_body_lies_between_the_natural_and_the_network_body(ramp_table_21):
    """The blend prior mixes the Otsu 2018 body with the network's colour-fitted one: its body
    error lies between theirs, and the photo's colour is still met."""
    rho, light, photo = _ochre_body_photo(ramp_table_21)
    errs = {}
    for prior, share in (("otsu2018", 0.5), ("blend", 0.5), ("network", 0.5), ("blend", 0.0)):
        res = refine_brdf(ramp_table_21, photo, light,
                          RefineOptions(clip_level=None, body_prior=prior, body_blend=share))
        got = diffuse_floor_of(res.table) * np.pi
        errs[prior, share] = float(np.sqrt(np.mean((got - rho) ** 2)) / rho.mean())
        assert res.after.psnr_db > 40.0, res.summary()
    assert errs["otsu2018", 0.5] < errs["blend", 0.5] < errs["network", 0.5], errs
    assert errs["blend", 0.0] == pytest.approx(errs["otsu2018", 0.5], rel=1e-6), errs


def test_the_body_tails_the_eye_barely_sees_are_left_to_the_network():
    """Visibility is 1 at each colour-matching function's peak and falls toward 0 in the far violet
    and far red; the tails prior mixes the network's body in only there."""
    from specgen_addon.generate.refine.body import blind_share, visibility

    assert visibility(np.array([442.0, 556.0, 599.0])) == pytest.approx(1.0, abs=0.01)
    wl = np.linspace(380.0, 780.0, 21)
    share = blind_share(wl, 0.3)
    assert np.all(share[(wl >= 420) & (wl <= 640)] == 0.0)
    assert np.all(share[wl >= 700] > 0.95) and share[0] > 0.95
    assert np.all(blind_share(wl, 0.1) <= share)
    with pytest.raises(SpecGenError, match="visibility threshold"):
        blind_share(wl, 0.0)


def test_the_tails_prior_keeps_the_natural_body_where_the_eye_sees(ramp_table_21):
    from specgen_addon.generate.refine.body import blind_share

    wl = ramp_table_21.wavelengths
    rho, light, photo = _ochre_body_photo(ramp_table_21)
    bodies = {}
    for prior in ("otsu2018", "tails", "network"):
        res = refine_brdf(ramp_table_21, photo, light, RefineOptions(clip_level=None, body_prior=prior))
        bodies[prior] = np.asarray(res.coefficients["body"])
        assert res.after.psnr_db > 40.0, res.summary()
    seen, blind = blind_share(wl, 0.3) == 0.0, blind_share(wl, 0.3) > 0.99
    # the body before its tint: Otsu 2018's where the eye sees, the network's (colour-fitted) where blind
    ratio = bodies["tails"][seen] / bodies["otsu2018"][seen]
    assert np.allclose(ratio, ratio[0], rtol=0.05), ratio
    assert not np.allclose(bodies["tails"][blind], bodies["otsu2018"][blind], rtol=0.05)


def test_unknown_body_prior_is_refused():
    with pytest.raises(SpecGenError, match="unknown body prior"):
        RefineOptions(body_prior="smits")
    with pytest.raises(SpecGenError, match="body_blend"):
        RefineOptions(body_prior="blend", body_blend=1.5)
    with pytest.raises(SpecGenError, match="body_visibility"):
        RefineOptions(body_prior="tails", body_visibility=0.0)


def test_an_added_angular_term_gives_a_near_lambertian_prior_the_photos_grazing_sheen(ramp_table_21):
    """The network predicts a near-Lambertian table; the photo is brighter towards grazing θd (a
    sheen). A multiplicative lobe correction has almost no lobe to scale; the added term fits it."""
    from specgen_addon.generate.refine.basis import CorrectionBasis

    basis = CorrectionBasis()
    floor = diffuse_floor_of(ramp_table_21)
    sheen = np.zeros(basis.shape)
    sheen[:, -2:, :] = 0.08                                          # added at θd ≥ 77°, all θh
    truth = apply_correction(ramp_table_21, floor, np.ones(basis.shape), np.ones(3), np.zeros(3), basis,
                             added=sheen)
    light = InputLighting()
    photo = render_under(truth, light.scene(SIZE), light.image_exposure)
    psnr = {}
    for additive in (False, True):   # with the smoothness of one strength per block (before s34)
        res = refine_brdf(ramp_table_21, photo, light, RefineOptions(clip_level=None, additive=additive,
                                                                     body_prior="network", smooth_weight="block"))
        psnr[additive] = res.after.psnr_db
    assert psnr[True] > 45.0, psnr
    assert psnr[True] > psnr[False] + 3.0, psnr
    default = refine_brdf(ramp_table_21, photo, light, RefineOptions(clip_level=None, body_prior="network"))
    assert default.after.psnr_db > 45.0


def test_a_blurred_photo_is_fitted_with_its_blur_modelled(ramp_table):
    """The photo of a tinted table, blurred as a lens or an off-grid crop blurs it: with the blur
    chosen by the fit (the default) the tint is recovered far better than by a fit that takes the
    photo as sharp, and an unblurred photo still chooses no blur."""
    from specgen_addon.generate.refine.blur import blur_image

    basis = CorrectionBasis()
    tint = basis.spectral_hats(WL) @ np.array([0.6, 1.05, 1.4])
    truth = _tinted(ramp_table, tint)
    light = InputLighting()
    sharp = render_under(truth, light.scene(SIZE), light.image_exposure)
    blurred = blur_image(sharp, 0.7)
    opts = RefineOptions(clip_level=None, body_prior="network")

    def error(res) -> float:
        return float(np.linalg.norm(res.table.values - truth.values) / np.linalg.norm(truth.values))

    modelled = refine_brdf(ramp_table, blurred, light, opts)
    as_sharp = refine_brdf(ramp_table, blurred, light, RefineOptions(clip_level=None, body_prior="network",
                                                                      blur_px=0.0))
    assert modelled.blur_px == pytest.approx(0.7)
    assert error(modelled) < 0.03, error(modelled)
    assert error(modelled) < 0.5 * error(as_sharp), (error(modelled), error(as_sharp))
    assert refine_brdf(ramp_table, sharp, light, opts).blur_px == 0.0


def test_a_bad_blur_width_is_refused():
    with pytest.raises(SpecGenError, match="blur_px"):
        RefineOptions(blur_px=-1.0)


def _kkt_residual(g, r, sol):
    grad = g @ sol - r
    free = sol > 0
    return max(np.abs(grad[free]).max(initial=0.0), (-grad[~free]).max(initial=0.0), (-sol).max(initial=0.0))


@pytest.mark.parametrize("seed", range(6))
def test_nonneg_ridge_agrees_with_scipy_nnls_when_many_coordinates_bind(seed):
    """A second implementation: for G = LLᵀ the problem is NNLS of ‖Lᵀθ − L⁻¹r‖, which
    scipy.optimize.nnls (Lawson–Hanson) solves. Targets with negative coordinates and a correlated
    design, so that many coordinates bind and some are released again."""
    scipy_optimize = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(seed)
    n = 40 + 30 * seed
    a = rng.normal(size=(3 * n, n)) + 0.3 * rng.normal(size=(3 * n, 1))   # correlated columns
    g = a.T @ a + 1e-3 * np.eye(n)
    r = a.T @ (a @ rng.normal(size=n))
    sol = nonneg_ridge(g, r)
    lower = np.linalg.cholesky(g)
    ref, _ = scipy_optimize.nnls(lower.T, np.linalg.solve(lower, r), maxiter=50 * n)
    assert 0.1 * n < np.count_nonzero(sol == 0) < 0.95 * n
    assert _kkt_residual(g, r, sol) < 1e-7 * (1 + np.abs(r).max())
    assert np.allclose(sol, ref, rtol=1e-7, atol=1e-9)


def _photo_by_samples(op: PhotoOperator, values: np.ndarray) -> np.ndarray:
    """(P, 3): Σ over each pixel's samples of f(ω_s) R_s projected to RGB — the operator's
    definition written out sample by sample (a trilinear lookup of ``values`` per sample)."""
    flat = values.reshape(-1, values.shape[-1]).astype(np.float64)
    photo = np.zeros((op.n_pixels, 3))
    for g in op.groups:
        ih, jd, kp = (g.ih.astype(np.int64), g.jd.astype(np.int64), g.kp.astype(np.int64))
        f = 0.0
        for di, wi in ((0, 1 - g.th), (1, g.th)):
            for dj, wj in ((0, 1 - g.td), (1, g.td)):
                for dk, wk in ((0, 1 - g.tp), (1, g.tp)):
                    cell = ((ih + di) * 90 + jd + dj) * 180 + (kp + dk) % 180
                    f = f + (wi * wj * wk)[:, None] * flat[cell]
        radiance = g.weights.astype(np.float64) @ g.radiance_basis
        np.add.at(photo, g.pixel, ((f @ op.interp) * radiance) @ op.to_rgb.T)
    return op.exposure * photo


def test_the_added_terms_design_is_the_photo_of_each_hat_as_a_brdf():
    """Each column of the added term's design is the photo of the BRDF h_a(θh) g_b(θd) s_l(λ),
    computed sample by sample; the columns sum to the photo of a constant 1 sr⁻¹."""
    light = InputLighting()
    op = PhotoOperator(light.scene(SIZE), WL, light.image_exposure)
    basis = CorrectionBasis()
    design = op.added_design(basis)                                  # (P, 3, Na, Nb, L)
    h, g, s = basis.theta_h_hats(), basis.theta_d_hats(), basis.spectral_hats(WL)
    for a, b, l in ((1, 0, 0), (5, 2, 1), (len(basis.theta_h_knots) - 1, 5, 2)):
        values = np.broadcast_to(h[:, a, None, None, None] * g[None, :, b, None, None]
                                 * s[None, None, None, :, l], (90, 90, 180, WL.size))
        photo = _photo_by_samples(op, values)
        assert photo.max() > 0
        assert np.allclose(design[:, :, a, b, l], photo, rtol=1e-4, atol=1e-5 * photo.max()), (a, b, l)
    photo = _photo_by_samples(op, np.ones((90, 90, 180, WL.size)))
    assert np.allclose(design.sum(axis=(2, 3, 4)), photo, rtol=1e-4, atol=1e-5 * photo.max())


def test_the_lobe_design_is_the_photo_of_the_table_times_each_hat(ramp_table):
    """A lobe design column is the photo of (f − c) h_a g_b s_l, computed sample by sample."""
    light = InputLighting()
    op = PhotoOperator(light.scene(SIZE), WL, light.image_exposure)
    basis = CorrectionBasis()
    floor = diffuse_floor_of(ramp_table)
    design = op.lobe_design(ramp_table.values, floor, basis)
    h, g, s = basis.theta_h_hats(), basis.theta_d_hats(), basis.spectral_hats(WL)
    lobe = ramp_table.values.astype(np.float64) - floor
    for a, b, l in ((0, 0, 1), (6, 1, 0), (10, 4, 2)):
        values = lobe * (h[:, a, None, None, None] * g[None, :, b, None, None] * s[None, None, None, :, l])
        photo = _photo_by_samples(op, values)
        assert np.abs(photo).max() > 0
        assert np.allclose(design[:, :, a, b, l], photo, rtol=1e-4, atol=1e-5 * np.abs(photo).max()), (a, b, l)


@pytest.mark.parametrize("knots", [(0, 2.5, 89), (0, 30, 95), (-1, 40), (0, 40, 30), ()])
def test_correction_knots_off_the_grid_are_refused(knots):
    with pytest.raises(SpecGenError, match="knots"):
        CorrectionBasis(theta_h_knots=knots)
    with pytest.raises(SpecGenError, match="knots"):
        CorrectionBasis(theta_d_knots=knots)


@pytest.mark.parametrize("shape", [(48, 48, 5), (70, 33, 2), (5, 9, 3)])
@pytest.mark.parametrize("sigma", [0.35, 1.0, 2.6])
def test_the_banded_blur_equals_scipys_gaussian_filter(shape, sigma):
    """The refinement's numpy blur against scipy.ndimage (a second implementation): zeros beyond
    the edge, the same truncated kernel, stacks smaller than a band and than the kernel."""
    ndimage = pytest.importorskip("scipy.ndimage")
    from specgen_addon.generate.refine.blur import gaussian_blur_stack

    img = np.random.default_rng(len(shape) + int(10 * sigma)).random(shape)
    ours = gaussian_blur_stack(img, sigma)
    theirs = ndimage.gaussian_filter(img, sigma=(sigma, sigma, 0), mode="constant")
    assert np.allclose(ours, theirs, rtol=0, atol=1e-13)
    assert np.array_equal(gaussian_blur_stack(img, 0.0), img)


# ------------------------------------------------------------------ the renderer's sampling error


def _independent_photo(table: BRDFTable, seed: int = 7) -> np.ndarray:
    """``table``'s photo under the canonical lighting, rendered with environment samples the
    refinement's operator does not use (as every real photo is)."""
    from dataclasses import replace

    light = InputLighting()
    scene = light.scene(SIZE)
    other = scene.with_sampling(replace(scene.sampling, seed=seed))
    return render_under(table, other, light.image_exposure)


def test_discrepancy_scale_finds_the_pull_that_leaves_the_target_residual():
    from specgen_addon.generate.refine.discrepancy import discrepancy_scale

    def residual(s: float) -> float:        # grows from 0 (plain fit) to 1 (the prior itself)
        return s / (1.0 + s)

    assert discrepancy_scale(residual, 0.5) == pytest.approx(1.0, rel=0.06)
    assert discrepancy_scale(residual, 0.9) == pytest.approx(9.0, rel=0.06)
    assert discrepancy_scale(residual, 0.0) == 0.0                  # the plain fit already leaves it
    assert discrepancy_scale(residual, 2.0) == float("inf")         # only the prior itself does


def test_sampling_variance_is_half_the_difference_of_two_independent_renders():
    from specgen_addon.generate.refine.discrepancy import difference_variance, sampling_variance

    rng = np.random.default_rng(3)
    truth = rng.uniform(0.2, 0.8, size=(20000, 3))
    a = truth + rng.normal(0.0, 0.02, truth.shape)
    b = truth + rng.normal(0.0, 0.02, truth.shape)
    assert sampling_variance(a, b) == pytest.approx(0.02 ** 2, rel=0.03)
    assert difference_variance(a - b) == sampling_variance(a, b)
    assert difference_variance(np.zeros((0, 3))) == 0.0


def test_with_a_fit_floor_the_fit_stops_at_the_renderers_sampling_error(ramp_table):
    """With ``fit_floor`` the lobe's correction is held back once the residual reaches the operator's
    own sampling error (measured from a second render with independent samples), while the body's
    tint and the added Lambertian (brightness, colour) stay free; without it, a photo that shares
    the operator's samples is fitted far more closely."""
    basis = CorrectionBasis()
    truth = _tinted(ramp_table, basis.spectral_hats(WL) @ np.array([0.6, 1.05, 1.4]))
    light = InputLighting()
    photo = render_under(truth, light.scene(SIZE), light.image_exposure)
    floored = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, fit_floor=1.0))
    plain = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    assert plain.sampling_floor_db is None and floored.sampling_floor_db is not None
    assert floored.prior_scale > 0.0
    assert plain.after.psnr_db > floored.after.psnr_db + 10.0         # the lobe held back ...
    assert floored.after.psnr_db > floored.before.psnr_db + 10.0      # ... brightness and colour still fitted


def test_a_sharp_photo_that_shares_no_samples_is_not_fitted_as_a_blurred_one(ramp_table):
    """Blurring the operator's renders averages its sampling noise away; that must not make a sharp
    photo look blurred: with ``fit_floor`` (which measures that noise) the choice subtracts each
    candidate's own noise variance and takes a smaller blur than without."""
    basis = CorrectionBasis()
    tint = basis.spectral_hats(WL) @ np.array([0.8, 1.0, 1.2])
    truth = _tinted(ramp_table, tint)
    photo = _independent_photo(truth)
    res = refine_brdf(ramp_table, photo, InputLighting(), RefineOptions(clip_level=None, fit_floor=1.0))
    plain = refine_brdf(ramp_table, photo, InputLighting(), RefineOptions(clip_level=None))
    assert res.blur_px < plain.blur_px


def test_refine_options_refuse_a_bad_fit_floor_or_smoothness_weighting():
    with pytest.raises(SpecGenError, match="fit_floor"):
        RefineOptions(fit_floor=-1.0)
    with pytest.raises(SpecGenError, match="smooth_weight"):
        RefineOptions(smooth_weight="sideways")


def test_the_relaxed_fit_is_kept_only_for_the_required_gain(ramp_table):
    """Below ``relax_below_db`` the smoothness is relaxed; the relaxed fit replaces the smooth one only
    if it reproduces the photo at least ``relax_min_gain_db`` better, else the smooth fit stays."""
    light = InputLighting()
    other = BRDFTable(np.roll(ramp_table.values, 30, axis=0) * 2.0, WL)
    photo = render_under(other, light.scene(SIZE), light.image_exposure)
    smooth = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, relax_below_db=0.0))
    assert smooth.relaxed_gain_db is None and not smooth.relaxed
    free = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    assert free.relaxed_gain_db is not None and free.relaxed_gain_db > 0 and free.relaxed
    assert free.after.psnr_db == pytest.approx(smooth.after.psnr_db + free.relaxed_gain_db, abs=1e-9)
    strict = refine_brdf(ramp_table, photo, light,
                         RefineOptions(clip_level=None, relax_min_gain_db=free.relaxed_gain_db + 0.5))
    assert not strict.relaxed and strict.relaxed_gain_db == pytest.approx(free.relaxed_gain_db)
    assert strict.after.psnr_db == pytest.approx(smooth.after.psnr_db)
    with pytest.raises(SpecGenError, match="relax_min_gain_db"):
        RefineOptions(relax_min_gain_db=-1.0)


def test_the_relaxed_fit_is_tried_only_where_it_predicts_held_out_pixels_better(ramp_table):
    """With ``relax_holdout`` (the default) the relaxed fit is tried only if it predicts held-out
    pixels better than the smooth one: a material unlike the network's (a structure the photo shows
    everywhere) is relaxed as without the check; the network's own material under pixel noise (2 %,
    independent per pixel) is not, although relaxing would fit that noise more closely."""
    light = InputLighting()
    scene = light.scene(SIZE)
    other = BRDFTable(np.roll(ramp_table.values, 30, axis=0) * 2.0, WL)
    photo = render_under(other, scene, light.image_exposure)
    checked = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    plain = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, relax_holdout=False))
    assert plain.relaxed_holdout_db is None and plain.relaxed
    assert checked.relaxed_holdout_db > 0 and checked.relaxed
    assert checked.after.psnr_db == pytest.approx(plain.after.psnr_db)

    clean = render_under(ramp_table, scene, light.image_exposure)
    noisy = clean * (1.0 + 0.02 * np.random.default_rng(3).standard_normal(clean.shape))
    always = dict(clip_level=None, relax_below_db=99.0)                 # try relaxing whatever the fit
    checked = refine_brdf(ramp_table, noisy, light, RefineOptions(**always))
    plain = refine_brdf(ramp_table, noisy, light, RefineOptions(**always, relax_holdout=False))
    assert plain.relaxed and plain.relaxed_gain_db > 0                 # in-sample, relaxing "helps"
    assert checked.relaxed_holdout_db <= 0 and not checked.relaxed and checked.relaxed_gain_db is None


def test_relaxing_theta_h_only_keeps_the_correction_smooth_along_theta_d(ramp_table):
    light = InputLighting()
    other = BRDFTable(np.roll(ramp_table.values, 30, axis=0) * 2.0, WL)
    photo = render_under(other, light.scene(SIZE), light.image_exposure)

    def theta_d_roughness(res) -> float:
        x = np.asarray(res.coefficients["lobe"])
        return float(np.sum(np.diff(x, axis=1) ** 2))

    both = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None))
    h_only = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, relax_axes="theta_h"))
    assert both.relaxed and h_only.relaxed_gain_db is not None
    assert theta_d_roughness(h_only) < theta_d_roughness(both)


def test_the_held_out_score_ranks_the_photographed_table_above_another_prior(ramp_table):
    """``score_holdout`` scores a starting table as a prior: each half of the sphere's pixel blocks,
    fitted alone, predicts the other. Refined from the very table the photo shows, the held-out
    pixels are predicted far better than refined from another table (a lobe 30 θh rows away and
    twice as bright), although the refinement fits both to the photo. Off by default."""
    light = InputLighting()
    clean = render_under(ramp_table, light.scene(SIZE), light.image_exposure)
    photo = clean * (1.0 + 0.01 * np.random.default_rng(5).standard_normal(clean.shape))
    other = BRDFTable(np.roll(ramp_table.values, 30, axis=0) * 2.0, WL)
    right = refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None, score_holdout=True))
    wrong = refine_brdf(other, photo, light, RefineOptions(clip_level=None, score_holdout=True))
    assert right.holdout_db > wrong.holdout_db + 10.0
    assert right.holdout_db > 45.0
    assert refine_brdf(ramp_table, photo, light, RefineOptions(clip_level=None)).holdout_db is None
