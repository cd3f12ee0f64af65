"""Corpus families: physics (non-negative, reciprocal, albedo ≤ 1, analytic cases),
serialisation, the mixed corpus' splits and mix, and refusal of bad mixes."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.corpus import ClearCoat, Conductor, Dielectric, Material, Reflectance, metal_ior
from specgen_addon.corpus.families import (CarPaint, Lobes, Sheen, ThinFilm, TintedCoat, airy_reflectance,
                                           directional_albedo, halfvector_quadrature, hemisphere_quadrature,
                                           material_from_dict)
from specgen_addon.corpus.families.lobes import back_vector_cosines, gtr_d
from specgen_addon.corpus.families.sheen import charlie_d
from specgen_addon.corpus.fresnel import fresnel_conductor, fresnel_dielectric
from specgen_addon.corpus.generate import FAMILY_MIX, check_mix, generate_mixed_corpus, material_family
from specgen_addon.corpus.microfacet import ggx_d
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM, measured_groups
from specgen_addon.common.errors import SpecGenError

WL = np.array([400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0])
WHITE = Reflectance("flat white", (1.0,) * REFLECTANCE_GRID_NM.size)


def _measured(i: int) -> Reflectance:
    s = measured_groups("train")[i][0]
    return Reflectance(s.id, tuple(np.round(s.values, 6)))


def _examples() -> list:
    """One material per family and variant, with white or measured spectra (worst cases for energy)."""
    plastic = Material("b", "train", 0.3, Dielectric(1.5, 0.004), WHITE)
    return [
        ThinFilm("tf-d", "train", 0.15, 1.33, 350.0, Dielectric(1.5, 0.004), WHITE),
        ThinFilm("tf-m", "train", 0.1, 2.2, 300.0, Conductor("Al")),
        TintedCoat("tc-m", "train", Material("b", "train", 0.2, Conductor("Ag")), ClearCoat(0.05, 1.5),
                   _measured(5), 0.8),
        TintedCoat("tc-p", "train", plastic, ClearCoat(0.08, 1.5), _measured(7), 0.5),
        CarPaint("cp", "train", WHITE, Conductor("Al"), 0.3, 0.5, ClearCoat(0.08, 1.5)),
        Sheen("sh", "train", 0.4, WHITE, WHITE),
        Sheen("sh-r", "train", 1.0, WHITE, _measured(2)),
        Lobes("gtr", "train", 0.15, 1.3, Dielectric(1.5, 0.004), WHITE),
        Lobes("retro", "train", 0.2, 2.0, Dielectric(1.5, 0.004), WHITE, 0.8, 0.4),
    ]


def _random_pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[..., 2] = np.abs(v[..., 2]) + 1e-3
    return v[0] / np.linalg.norm(v[0], axis=-1, keepdims=True), v[1] / np.linalg.norm(v[1], axis=-1, keepdims=True)


@pytest.mark.parametrize("material", _examples(), ids=lambda m: m.name)
def test_family_brdf_is_non_negative_finite_and_reciprocal(material):
    wi, wo = _random_pairs(3000)
    f, g = material.eval(wi, wo, WL), material.eval(wo, wi, WL)
    assert np.all(np.isfinite(f)) and f.min() >= 0.0
    np.testing.assert_allclose(f, g, rtol=1e-9, atol=1e-12)
    below = wi.copy()
    below[:, 2] *= -1
    assert np.all(material.eval(below, wo, WL) == 0.0)


@pytest.mark.parametrize("material", _examples(), ids=lambda m: m.name)
def test_family_albedo_is_at_most_one_in_a_white_furnace(material):
    # the quadrature that resolves the material's sharpest lobe: GGX-warped half vectors for the
    # glossy coats (α ≤ 0.08), the cosine-spaced hemisphere otherwise (it agrees with a 160² one to
    # 1e-4 on these); 0.5 % is left for quadrature error at grazing incidence
    sharp = isinstance(material, (TintedCoat, CarPaint))
    quad = halfvector_quadrature(0.05) if sharp else hemisphere_quadrature(64, 64)
    e = directional_albedo(material._spectral, quad, WL)
    assert e.max() <= 1.0 + 5e-3, (material.name, e.max())
    assert e.min() >= 0.0


@pytest.mark.parametrize("material", _examples(), ids=lambda m: m.name)
def test_family_material_round_trips_through_its_dict(material):
    back = material_from_dict(material.to_dict())
    assert back == material
    wi, wo = _random_pairs(50)
    np.testing.assert_array_equal(back.eval(wi, wo, WL), material.eval(wi, wo, WL))


def test_family_eval_hd_and_rgb_agree_with_eval():
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff

    m = _examples()[0]
    rng = np.random.default_rng(3)
    th, td, pd = rng.uniform(0, 1.4, 200), rng.uniform(0, 1.4, 200), rng.uniform(0, np.pi, 200)
    wi, wo = io_from_half_diff(th, td, pd)
    np.testing.assert_allclose(m.eval_hd(th, td, pd, WL), m.eval(wi, wo, WL), rtol=1e-8, atol=1e-12)
    assert m.eval_rgb(wi, wo).shape == (200, 3)


def test_thin_film_of_zero_thickness_is_the_bare_interface():
    c = np.linspace(0.0, 1.0, 21)
    eta, k = metal_ior("Au", WL)
    metal = ThinFilm("z", "train", 0.1, 1.5, 0.0, Conductor("Au"))
    np.testing.assert_allclose(metal.film_reflectance(c, WL), fresnel_conductor(c[:, None], eta, k), atol=1e-10)
    diel = ThinFilm("z", "train", 0.1, 1.8, 0.0, Dielectric(1.5, 0.0))
    np.testing.assert_allclose(diel.film_reflectance(c, WL), np.broadcast_to(fresnel_dielectric(c[:, None], 1.5), (c.size, WL.size)), atol=1e-10)


def test_airy_reflectance_matches_hand_computed_films():
    # quarter-wave antireflection coating: n_f = √n_s, d = λ / (4 n_f) gives R = 0 at normal incidence
    ns, lam = 1.9, 550.0
    nf = np.sqrt(ns)
    assert airy_reflectance(np.array([1.0]), np.array([lam]), nf, lam / (4 * nf), np.array([ns]))[0] < 1e-20
    # half-wave film is absent at normal incidence: R = ((1 − n_s)/(1 + n_s))²
    r_bare = ((1 - ns) / (1 + ns)) ** 2
    half = airy_reflectance(np.array([1.0]), np.array([lam]), 1.38, lam / (2 * 1.38), np.array([ns]))[0]
    assert half == pytest.approx(r_bare, abs=1e-12)
    # quarter-wave high-index film (n_f = 2.3 on 1.5): R = ((n_s − n_f²)/(n_s + n_f²))², by hand
    nf, ns = 2.3, 1.5
    quarter = airy_reflectance(np.array([1.0]), np.array([lam]), nf, lam / (4 * nf), np.array([ns]))[0]
    assert quarter == pytest.approx(((ns - nf ** 2) / (ns + nf ** 2)) ** 2, abs=1e-12)


def test_thin_film_colour_shifts_with_angle():
    m = ThinFilm("tf", "train", 0.05, 1.33, 400.0, Dielectric(1.5, 0.0))
    r = m.film_reflectance(np.array([1.0, 0.5]), np.linspace(400, 700, 61))
    peaks = np.argmax(r, axis=1)
    assert peaks[0] != peaks[1]  # the interference maxima move (towards blue) off normal incidence


def test_distributions_are_normalised():
    quad = hemisphere_quadrature(96, 96)
    mu = np.linspace(0, 1, 4001)[1:]
    for d in (lambda c: gtr_d(c, 0.2, 1.5), lambda c: gtr_d(c, 0.2, 2.0), lambda c: charlie_d(c, 0.5)):
        # ∫ D cos θh dω = 2π ∫₀¹ D(μ) μ dμ = 1
        assert 2 * np.pi * np.trapz(d(mu) * mu, mu) == pytest.approx(1.0, abs=2e-3)
    np.testing.assert_allclose(gtr_d(mu, 0.3, 2.0), ggx_d(mu, 0.3), rtol=1e-12)
    assert quad.cos_i.size > 0


def test_back_vector_lobe_peaks_in_the_retro_direction():
    # ωo = ωi: the back vector is the normal (cos θb = 1) and ωi·b = cos θi
    cos_b, i_dot_b = back_vector_cosines(np.array([0.8]), np.array([0.8]), np.array([1.0]))
    assert cos_b[0] == pytest.approx(1.0) and i_dot_b[0] == pytest.approx(0.8)
    m = Lobes("r", "train", 0.3, 2.0, Dielectric(1.5, 0.0), None, 1.0, 0.2)
    wi = np.array([[0.6, 0.0, 0.8]])
    retro = m.eval(wi, wi, WL)[0, 0]
    side = m.eval(wi, np.array([[0.0, 0.6, 0.8]]), WL)[0, 0]
    assert retro > 3 * side


def test_tinted_coat_colours_the_highlight_of_a_silver_base():
    tint = _measured(5)
    m = TintedCoat("tc", "train", Material("b", "train", 0.05, Conductor("Ag")), ClearCoat(0.2, 1.5), tint, 1.0)
    wl = np.linspace(400, 700, 31)
    w = np.array([[0.0, 0.0, 1.0]])
    peak = m.eval(w, w, wl)[0] - m.eval(w, w, wl)[0].min() * 0
    bare = Material("b", "train", 0.05, Conductor("Ag")).eval(w, w, wl)[0]
    ratio = peak / bare
    # Beer–Lambert at normal incidence through a coat of index η: T = τ(λ)^(2·density), times the coat's
    # two interface crossings (the same at every λ), plus the coat's own weak reflection
    expected = np.maximum(tint.at(wl), 1e-3) ** 2.0
    corr = np.corrcoef(ratio, expected)[0, 1]
    assert corr > 0.99


def test_car_paint_of_bare_flakes_equals_a_coated_classic_metal():
    # coverage 1: the pigment vanishes and the flakes are a GGX conductor under the coat, which the
    # classic recipe (an independent implementation) also builds
    coat = ClearCoat(0.05, 1.5)
    paint = CarPaint("cp", "train", _measured(3), Conductor("Al"), 0.3, 1.0, coat)
    metal = Material("m", "train", 0.3, Conductor("Al"), None, coat)
    wi, wo = _random_pairs(500)
    np.testing.assert_allclose(paint.eval(wi, wo, WL), metal.eval(wi, wo, WL), rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def mixed():
    return generate_mixed_corpus(300, seed=0)


def test_mixed_corpus_is_reproducible_and_prefix_stable(mixed):
    assert generate_mixed_corpus(40, seed=0) == mixed[:40]
    assert generate_mixed_corpus(40, seed=1) != mixed[:40]
    fams = {material_family(m) for m in mixed}
    assert fams == set(FAMILY_MIX)


def _spectra_and_metals(m) -> tuple[list[np.ndarray], list[str]]:
    specs, metals = [], []
    for v in ([m] + [getattr(m, f) for f in ("base",) if hasattr(m, f)]):
        for field in ("diffuse", "tint", "base_color", "sheen_color"):
            r = getattr(v, field, None)
            if isinstance(r, Reflectance):
                specs.append(np.asarray(r.values))
        for field in ("interface", "substrate", "flake_metal"):
            c = getattr(v, field, None)
            if isinstance(c, Conductor):
                metals.append(c.metal)
    return specs, metals


def test_mixed_corpus_holds_out_whole_spectra_and_metals(mixed):
    by_split: dict[str, tuple[list, set]] = {s: ([], set()) for s in ("train", "val", "test")}
    for m in mixed:
        specs, metals = _spectra_and_metals(m)
        by_split[m.split][0].extend(specs)
        by_split[m.split][1].update(metals)
    train = np.stack(by_split["train"][0])
    test = np.stack(by_split["test"][0])
    d = np.sqrt(((test[:, None, :] - train[None]) ** 2).mean(-1))
    assert d.min() > 0.0  # no test spectrum appears in training
    assert not (by_split["test"][1] & by_split["train"][1])


def test_family_mix_is_checked_before_any_work():
    with pytest.raises(SpecGenError, match="unknown material family 'velvet'"):
        check_mix({"velvet": 1.0})
    with pytest.raises(SpecGenError, match="non-negative"):
        check_mix({"sheen": -1.0})
    assert check_mix({"sheen": 2, "lobes": 2}) == {"sheen": 0.5, "lobes": 0.5}


@pytest.mark.parametrize("argv, message", [
    (["--n", "0"], "--n must be between"),
    (["--n", "5", "--seed", "-1"], "--seed must be"),
    (["--n", "5", "--families", "velvet=1"], "unknown material family"),
    (["--n", "5", "--families", "sheen=lots"], "not a number"),
    (["--n", "5", "--bands", "0"], "--bands must be"),
])
def test_corpus_command_refuses_bad_sizes_seeds_and_families(tmp_path, capsys, argv, message):
    from specgen_addon.cli.app import main as cli_main

    out = tmp_path / "c"
    assert cli_main(["corpus", "--out", str(out), "--quiet", *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_corpus_command_writes_a_mixed_manifest_that_loads_back(tmp_path):
    from specgen_addon.cli.app import main as cli_main
    from specgen_addon.corpus import load_manifest

    out = tmp_path / "c"
    assert cli_main(["corpus", "--n", "12", "--families", "sheen=1,thin_film=1", "--out", str(out),
                     "--quiet"]) == 0
    mats = load_manifest(out / "manifest.json")
    assert mats == generate_mixed_corpus(12, 0, {"sheen": 1, "thin_film": 1})
    assert {material_family(m) for m in mats} == {"sheen", "thin_film"}


def _lobe_alphas(m) -> list[float]:
    if isinstance(m, TintedCoat):
        return [m.base.alpha, m.coat.alpha]
    if isinstance(m, CarPaint):
        return [m.flake_alpha, m.coat.alpha]
    return [m.alpha] if hasattr(m, "alpha") else []


@pytest.mark.parametrize("material", _examples(), ids=lambda m: m.name)
def test_family_albedo_is_at_most_one_by_independent_monte_carlo(material):
    # balance-heuristic MIS of GGX visible-normal and cosine sampling (tests/corpus/test_corpus.py's
    # estimator, independent of the families' quadratures), at normal, oblique and grazing incidence
    from scipy.stats import qmc
    from tests.corpus.test_corpus import _vndf_pdf, _vndf_sample

    alphas, n = _lobe_alphas(material), 4096
    u = qmc.Sobol(2, seed=0).random(n)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    cosine = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0, 1 - r * r))], -1)
    for theta in (0.0, 45.0, 75.0, 87.0):
        t = np.radians(theta)
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        total = np.zeros(WL.size)
        for wo in [_vndf_sample(wi, a, u) for a in alphas] + [cosine]:
            pdf = sum(_vndf_pdf(wi, wo, a) for a in alphas) + np.maximum(wo[:, 2], 0) / np.pi
            w = np.where(wo[:, 2] > 0, wo[:, 2] / (n * np.where(pdf > 0, pdf, 1.0)), 0.0)
            total += w @ material.eval(np.broadcast_to(wi, wo.shape), wo, WL)
        assert total.max() <= 1.0 + 1e-2, (material.name, theta, total.max())
        assert total.min() > 0.0
