"""The thin-film family's fit to the photo: its design reproduces the renderer, it recovers a known
film's angle-dependent colour from the film's own photo (numpy only), and bad input is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from specgen_addon.corpus.families.thin_film import ThinFilm, airy_reflectance
from specgen_addon.corpus.material import Conductor, Dielectric
from specgen_addon.common.errors import SpecGenError
from specgen_addon.generate.thin_film import (AiryThicknessSeries, _ReducedDesign, fit_pixels, fit_thin_film,
                                         lobe_geometry, substrates, theta_d_response)
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.generate.refine import render_under
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.brdf.table import grid_angles

SIZE = 32
WL = np.linspace(380.0, 780.0, 21)


def test_theta_d_response_reproduces_the_renderer_image_of_a_tabulated_film():
    """K·R (the fit's linear model) equals the reference renderer's photo of the tabulated film."""
    film = ThinFilm("f", "test", alpha=0.08, film_eta=1.8, thickness_nm=320.0, substrate=Conductor("Al"))
    light = InputLighting()
    scene = light.scene(SIZE)
    op = PhotoOperator(scene, WL, light.image_exposure)
    pixels = fit_pixels(op)
    k = theta_d_response(op, lobe_geometry(film.alpha), pixels)            # (P, 3, J, Λ)
    r = film.film_reflectance(np.cos(grid_angles()[1]), op.render_wavelengths_nm)   # (J, Λ)
    model = np.einsum("pcjw,jw->pc", k, r)
    photo = op.observe(render_under(film.tabulate(WL), scene, light.image_exposure))[pixels]
    assert np.abs(model - photo).max() / photo.max() < 2e-3


def test_every_metal_and_the_dielectrics_are_candidate_substrates():
    subs = substrates(WL)
    assert sum(isinstance(s, Conductor) for s, _ in subs) >= 10
    assert sum(isinstance(s, Dielectric) for s, _ in subs) == 3
    # a zero-thickness film is its bare substrate: the Airy model's own limit, per candidate
    for _, n2 in subs:
        bare = airy_reflectance(np.array([[1.0]]), WL, 1.5, 0.0, n2)[0]
        assert np.allclose(bare, np.abs((1 - n2) / (1 + n2)) ** 2, atol=1e-9)


def test_malformed_photos_are_refused_before_any_work():
    with pytest.raises(SpecGenError, match="square"):
        fit_thin_film(np.zeros((8, 9, 3)))
    with pytest.raises(SpecGenError, match="NaN"):
        fit_thin_film(np.full((8, 8, 3), np.nan))
    with pytest.raises(SpecGenError, match="clipped"):
        fit_thin_film(np.ones((SIZE, SIZE, 3)))


def test_unknown_generator_model_is_refused():
    from specgen_addon.generate.pipeline import generate

    with pytest.raises(SpecGenError, match="unknown model"):
        generate(np.zeros((SIZE, SIZE, 3)), model="mlp")


def _hue(brdf, theta_d: np.ndarray) -> np.ndarray:
    import colour

    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.spectral.spectra import reflectance_to_linear_srgb

    wi, wo = io_from_half_diff(np.zeros_like(theta_d), theta_d, np.zeros_like(theta_d))
    rgb = reflectance_to_linear_srgb(np.asarray(brdf.eval(wi, wo, WL)), WL)
    lab = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False))
    return np.degrees(np.arctan2(lab[:, 2], lab[:, 1]))


@pytest.mark.slow
def test_a_film_is_recovered_from_its_own_photo_with_only_numpy(tmp_path, numpy_only):
    """An oxide film on copper, photographed under the canonical lighting: the fit (run with
    torch, scipy and colour-science blocked: the panel's path) reproduces the photo and the
    film's hue over θd, which an RGB or angle-independent model cannot."""
    from specgen_addon.photo import sphere_image as input_image

    truth = ThinFilm("t", "test", alpha=0.05, film_eta=2.1, thickness_nm=410.0, substrate=Conductor("Cu"))
    photo_path = tmp_path / "photo.npy"
    np.save(photo_path, input_image.render_input(truth, 48))
    out = numpy_only(f"""
        import json
        import numpy as np
        from specgen_addon.generate.thin_film import fit_thin_film
        fit = fit_thin_film(np.load({str(photo_path)!r}), clip_level=None)
        m = fit.material
        print(json.dumps({{"psnr": fit.reproduction.psnr_db, "alpha": m.alpha, "eta": m.film_eta,
                          "d": m.thickness_nm, "substrate": m.kind}}))
    """, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["psnr"] > 40.0, got
    sub = Conductor(got["substrate"].split(":")[1]) if got["substrate"].startswith("thin_film/metal") else Dielectric(1.5, 0.004)
    fitted = ThinFilm("fit", "test", alpha=got["alpha"], film_eta=got["eta"], thickness_nm=got["d"], substrate=sub)
    theta_d = np.radians(np.linspace(0.0, 75.0, 16))
    h_true, h_fit = _hue(truth, theta_d), _hue(fitted, theta_d)
    assert np.ptp(np.unwrap(np.radians(h_true))) > np.radians(20.0)      # the truth's hue does move
    assert np.mean(np.abs((h_fit - h_true + 180.0) % 360.0 - 180.0)) < 5.0


@pytest.mark.slow
def test_infer_with_the_thin_film_model_writes_a_table_that_reproduces_the_photo(tmp_path):
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.cli.app import main
    from specgen_addon.brdf.table import BRDFTable

    truth = ThinFilm("t", "test", alpha=0.12, film_eta=2.2, thickness_nm=300.0,
                     substrate=Dielectric(1.5, 0.004))
    image = tmp_path / "film.exr"     # at the loader's canonical size: a smaller photo is upsampled
    input_image.save_input(input_image.render_input(truth, input_image.CANONICAL_SIZE), image)
    out = tmp_path / "film.npz"
    assert main(["infer", str(image), "-o", str(out), "--model", "thin-film", "--bands", "9", "--quiet"]) == 0
    table = BRDFTable.load(out)
    assert table.values.shape[-1] == 9 and table.metadata["source"] == "specgen thin-film fit"
    assert table.metadata["fit_psnr_db"] > 38.0


@pytest.mark.slow
def test_a_photo_no_film_explains_is_warned_about_by_name():
    """Noise on the sphere: the closest film reproduces it badly, and the fit says so."""
    from specgen_addon.photo import sphere_image as input_image

    truth = ThinFilm("t", "test", alpha=0.1, film_eta=1.8, thickness_nm=300.0, substrate=Conductor("Al"))
    photo = input_image.render_input(truth, SIZE)
    photo = photo * np.random.default_rng(0).uniform(0.0, 2.0, size=photo.shape)
    fit = fit_thin_film(photo, clip_level=None)
    assert fit.reproduction.psnr_db < 30.0
    assert len(fit.warnings) == 1 and "does not explain this photo" in fit.warnings[0]


@pytest.mark.parametrize("film_eta", [1.2, 1.93, 2.6])
def test_the_thickness_series_equals_the_airy_summation_on_every_substrate(film_eta):
    """Stage 2's real-arithmetic Airy reflectance over many thicknesses against the corpus's complex
    Airy summation (itself checked against Fresnel at d = 0 and a quarter-wave zero)."""
    cos = np.cos(grid_angles()[1])[:, None]
    ds = np.arange(0.0, film_eta * 1500.0 + 1e-9, 4.0) / film_eta
    for _, n2 in substrates(WL):
        series = AiryThicknessSeries(cos, WL, film_eta, n2)(ds)
        assert series.shape == (ds.size, cos.shape[0], WL.size)
        assert np.allclose(series, airy_reflectance(cos, WL, film_eta, ds[:, None, None], n2), rtol=0, atol=1e-12)


def test_the_thickness_series_refuses_a_film_index_it_cannot_handle():
    with pytest.raises(SpecGenError, match="film index"):
        AiryThicknessSeries(np.ones((3, 1)), WL, 0.9, np.full(WL.size, 1.5))


@pytest.mark.parametrize("with_body", [False, True])
def test_the_reduced_design_ranks_candidates_as_least_squares_does(with_body):
    """Residuals in the reduced basis equal ‖b − K R − B ρ‖² (ρ free with a body) up to one constant
    (the part of b outside the design's span), when the design's rank fits the reduction."""
    rng = np.random.default_rng(3)
    k = rng.normal(size=(240, 60)) @ rng.normal(size=(60, 90))        # rank 60
    body = rng.normal(size=(240, 3))
    b = rng.normal(size=240)
    cands = rng.normal(size=(5, 9, 10))
    reduced = _ReducedDesign(k, body, b).residuals(cands, with_body)
    direct = []
    for r in cands:
        rest = b - k @ r.ravel()
        if with_body:
            rest = rest - body @ np.linalg.lstsq(body, rest, rcond=None)[0]
        direct.append(rest @ rest)
    offset = np.asarray(direct) - reduced
    assert np.all(offset >= -1e-8)
    assert np.allclose(offset, offset[0], rtol=0, atol=1e-8 * np.max(direct))


def test_a_blurred_photo_is_fitted_with_its_blur_and_not_as_a_rougher_lobe():
    """A sharp film's photo blurred by a Gaussian of 1 px (a resampled crop spreads a highlight
    so): fitted without a blur model, the lobe comes out far rougher than the truth; with the
    refinement's blur candidates the fit chooses σ = 1 px and finds the true roughness."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX, gaussian_blur_stack

    truth = ThinFilm("t", "test", alpha=0.03, film_eta=1.9, thickness_nm=380.0, substrate=Conductor("Al"))
    photo = gaussian_blur_stack(input_image.render_input(truth, 64), 1.0)
    sharp = fit_thin_film(photo, clip_level=None)
    blurred = fit_thin_film(photo, clip_level=None, blur_px=BLUR_CANDIDATES_PX)
    assert sharp.blur_px == 0.0 and sharp.material.alpha > 1.3 * truth.alpha
    assert blurred.blur_px == 1.0
    assert abs(np.log(blurred.material.alpha / truth.alpha)) < np.log(1.12)
    assert blurred.reproduction.psnr_db > sharp.reproduction.psnr_db + 3.0
    # the wording the CLI line and the panel summary share
    assert sharp.blur_note() == "" and blurred.blur_note() == "photo blur σ 1 px modelled"
    from specgen_addon.cli.model import film_fit_summary
    assert "photo blur σ 1 px modelled" in film_fit_summary(blurred, "the canonical studio")
    assert "blur" not in film_fit_summary(sharp, "the canonical studio")


@pytest.mark.parametrize("bad", [(), (-0.5,), (np.nan,), (0.0, 9.0)])
def test_a_bad_blur_width_is_refused(bad):
    with pytest.raises(SpecGenError, match="blur_px"):
        fit_thin_film(np.full((SIZE, SIZE, 3), 0.2), clip_level=None, blur_px=bad)
