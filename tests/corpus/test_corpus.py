"""Synthetic spectral BRDF corpus: physics (reciprocity, energy, Fresnel), tables, splits, I/O."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import qmc

from specgen_addon.cli.app import main as cli_main
from specgen_addon.corpus import (SPLITS, ClearCoat, Conductor, Dielectric, Material, Reflectance,
                                  generate_corpus, load_manifest, make_material, metal_ior,
                                  save_manifest)
from specgen_addon.corpus.fresnel import cauchy_ior, fresnel_conductor, fresnel_dielectric
from specgen_addon.corpus.microfacet import ggx_d, smith_lambda
from specgen_addon.corpus.spectra_sources import (DUPLICATE_RMS, REFLECTANCE_GRID_NM,
                                                  measured_spectra, rms_distance)
from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM as WL
from specgen_addon.brdf.table import grid_angles

FLAT_WHITE = Reflectance("flat white", (1.0,) * REFLECTANCE_GRID_NM.size)


@pytest.fixture(scope="module")
def corpus() -> list[Material]:
    return generate_corpus(200, seed=0)


def _one_of_each_kind(materials: list[Material], per_kind: int = 2) -> list[Material]:
    picked: dict[str, list[Material]] = {}
    for m in materials:
        kind = m.kind.split(":")[0] + ("+coat" if m.coat else "")
        if len(picked.setdefault(kind, [])) < per_kind:
            picked[kind].append(m)
    return [m for ms in picked.values() for m in ms]


def _direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _random_hemisphere(rng: np.random.Generator, n: int, min_cos: float = 0.0) -> np.ndarray:
    z = rng.uniform(min_cos, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


# --- directional albedo by multiple importance sampling (independent of the albedo table) ----

def _vndf_sample(wi: np.ndarray, alpha: float, u: np.ndarray) -> np.ndarray:
    """Outgoing directions via GGX visible-normal sampling (Heitz 2018, JCGT 7(4))."""
    v = np.array([alpha * wi[0], alpha * wi[1], wi[2]])
    v /= np.linalg.norm(v)
    lensq = v[0] ** 2 + v[1] ** 2
    t1 = np.array([-v[1], v[0], 0.0]) / np.sqrt(lensq) if lensq > 1e-14 else np.array([1.0, 0, 0])
    t2 = np.cross(v, t1)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    a, b = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1 + v[2])
    b = (1 - s) * np.sqrt(1 - a * a) + s * b
    nh = a[:, None] * t1 + b[:, None] * t2 + np.sqrt(np.maximum(0, 1 - a * a - b * b))[:, None] * v
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 1e-9)], -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return 2 * (h @ wi)[:, None] * h - wi


def _vndf_pdf(wi: np.ndarray, wo: np.ndarray, alpha: float) -> np.ndarray:
    """Solid-angle density of :func:`_vndf_sample`: ``G1(wi) D(h) / (4 cos θi)``."""
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    g1 = 1 / (1 + smith_lambda(wi[2], alpha))
    return np.where(wo[:, 2] > 0, g1 * ggx_d(h[:, 2], alpha) / (4 * wi[2]), 0.0)


def directional_albedo(m: Material, wi: np.ndarray, n: int = 4096) -> np.ndarray:
    """``∫ f_r(wi, wo, λ) cos θo dωo`` per band: balance-heuristic MIS of VNDF (base and coat
    roughness) and cosine sampling, Sobol points. Weights ``f cos / Σ p`` stay bounded, so the
    estimate is accurate to ~1e-3 even for near-mirror lobes."""
    alphas = [m.alpha] + ([m.coat.alpha] if m.coat else [])
    u = qmc.Sobol(2, seed=0).random(n)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    cosine = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0, 1 - r * r))], -1)
    total = np.zeros(WL.size)
    for wo in [_vndf_sample(wi, a, u) for a in alphas] + [cosine]:
        pdf = sum(_vndf_pdf(wi, wo, a) for a in alphas) + np.maximum(wo[:, 2], 0) / np.pi
        w = np.where(wo[:, 2] > 0, wo[:, 2] / (n * np.where(pdf > 0, pdf, 1.0)), 0.0)
        total += w @ m.eval(np.broadcast_to(wi, wo.shape), wo, WL)
    return total


GRAZING_SWEEP_DEG = (0.0, 45.0, 75.0, 85.0, 89.0)


# --- physics --------------------------------------------------------------------------------

def test_helmholtz_reciprocity_holds_for_random_corpus_materials(corpus):
    rng = np.random.default_rng(1)
    wi = _random_hemisphere(rng, 4000)
    wo = _random_hemisphere(rng, 4000)
    wi[:500, 2] = 1e-3  # grazing incidence
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    for m in corpus[:40]:
        a, b = m.eval(wi, wo, WL), m.eval(wo, wi, WL)
        assert np.all(a >= 0)
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=m.kind)


def test_white_plastic_conserves_energy_exactly_at_every_angle_and_roughness():
    # Kelemen coupling: albedo = E(μ) + ρ (1 − E(μ)) = 1 for ρ = 1, whatever E is.
    for alpha, eta in ((0.02, (1.5, 0.0)), (0.3, (1.33, 0.004)), (0.8, (1.7, 0.012))):
        m = Material("white", "train", alpha, Dielectric(*eta), FLAT_WHITE)
        for theta in GRAZING_SWEEP_DEG:
            albedo = directional_albedo(m, _direction(theta))
            np.testing.assert_allclose(albedo, 1.0, atol=2e-3, err_msg=f"α={alpha}, θi={theta}")


def test_directional_albedo_is_at_most_one_for_corpus_materials(corpus):
    # Tolerance 2e-3: the white-plastic test above bounds table + quadrature error by that.
    extremes = [Material("ag", "train", 0.02, Conductor("Ag")),
                Material("ag+coat", "train", 0.02, Conductor("Ag"), coat=ClearCoat(0.02, 1.6)),
                Material("white+coat", "train", 0.05, Dielectric(1.5, 0.01), FLAT_WHITE,
                         ClearCoat(0.3, 1.45))]
    for m in _one_of_each_kind(corpus) + extremes:
        for theta in GRAZING_SWEEP_DEG:
            albedo = directional_albedo(m, _direction(theta, 30.0))
            assert albedo.max() <= 1.0 + 2e-3, (m.kind, theta, albedo.max())
            assert albedo.min() > 0.0


def test_brdf_is_zero_below_the_horizon():
    m = Material("p", "train", 0.2, Dielectric(1.5, 0.005), FLAT_WHITE, ClearCoat(0.1, 1.5))
    up, down = _direction(30.0), _direction(120.0)
    f = m.eval(np.stack([up, down, down]), np.stack([down, up, down]), WL)
    assert np.all(f == 0.0)


def test_eval_broadcasts_one_direction_against_many_and_defaults_to_21_bands():
    m = Material("p", "train", 0.2, Dielectric(1.5, 0.005), FLAT_WHITE)
    wo = _random_hemisphere(np.random.default_rng(9), 50)
    wi = _direction(20.0)
    f = m.eval(wi, wo, None)
    assert f.shape == (50, WL.size)
    np.testing.assert_array_equal(f, m.eval(np.repeat(wi[None], 50, 0), wo, WL))
    with pytest.raises(SpecGenError, match="broadcast"):
        m.eval(wo[:3], wo[:4], WL)


def test_ggx_distribution_projects_to_unit_area():
    # ∫ D(h) cos θh dωh = 2π ∫₀¹ D(c) c dc = 1 (Walter et al. 2007), adaptive quadrature.
    from scipy.integrate import quad

    for alpha in (0.02, 0.3, 0.8):
        value, _ = quad(lambda c: float(ggx_d(c, alpha)) * c, 0.0, 1.0, points=[1 - alpha ** 2],
                        limit=200, epsabs=1e-10)
        assert 2 * np.pi * value == pytest.approx(1.0, abs=1e-6)


def test_conductor_fresnel_matches_normal_incidence_closed_form_and_dielectric_limit():
    n, k = metal_ior("Au", WL)
    closed = ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2)
    np.testing.assert_allclose(fresnel_conductor(1.0, n, k), closed, rtol=1e-12)
    c = np.linspace(0, 1, 50)
    np.testing.assert_allclose(fresnel_conductor(c, 1.5, 0.0), fresnel_dielectric(c, 1.5), atol=1e-12)
    assert fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04)
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)


def test_metals_reflect_like_their_known_colours():
    r = {m: Conductor(m).fresnel(np.array(1.0), np.array([450.0, 600.0, 650.0])) for m in
         ("Au", "Ag", "Cu", "Al")}
    assert r["Au"][2] > 0.9 and r["Au"][0] < 0.5  # gold: red, not blue
    assert r["Cu"][2] > r["Cu"][0] + 0.3  # copper: reddish
    assert r["Ag"][1] > 0.95  # silver ~0.97 at 600 nm
    assert 0.85 < r["Al"].min() and np.ptp(r["Al"]) < 0.03  # aluminium: bright and neutral


def test_fresnel_lookup_matches_the_formulas():
    rng = np.random.default_rng(2)
    cos_d = rng.uniform(0, 1, 2000)
    for m in (Material("d", "train", 0.5, Dielectric(1.6, 0.01)), Material("c", "train", 0.5, Conductor("Cu"))):
        # A lone GGX lobe at θh = 0 isolates F(cos θd) times a known geometric factor.
        th = np.zeros_like(cos_d)
        got = m.eval_hd(th, np.arccos(cos_d), np.zeros_like(cos_d), WL)
        ref = m.interface.fresnel(cos_d, WL) * (ggx_d(1.0, 0.5) / (1 + 2 * smith_lambda(cos_d, 0.5))
                                                  / (4 * cos_d * cos_d))[:, None]
        np.testing.assert_allclose(got, ref, rtol=1e-5)


def test_cauchy_dispersion_raises_index_towards_blue():
    eta = cauchy_ior(WL, 1.5, 0.0042)
    assert np.all(np.diff(eta) < 0) and eta[0] == pytest.approx(1.5 + 0.0042 / 0.38 ** 2)


# --- evaluation paths -----------------------------------------------------------------------

def test_eval_hd_equals_eval_at_the_directions_of_io_from_half_diff(corpus):
    rng = np.random.default_rng(3)
    th, td, pd = rng.uniform(0, 1.5, 3000), rng.uniform(0, 1.5, 3000), rng.uniform(0, 2 * np.pi, 3000)
    wi, wo = io_from_half_diff(th, td, pd)
    for m in _one_of_each_kind(corpus, 1):
        np.testing.assert_allclose(m.eval_hd(th, td, pd, WL), m.eval(wi, wo, WL), rtol=1e-8, atol=1e-10)


def test_spectrally_flat_material_gives_neutral_rgb_under_d65():
    m = Material("grey", "train", 0.4, Dielectric(1.5, 0.0),
                 Reflectance("flat 0.5", (0.5,) * REFLECTANCE_GRID_NM.size))
    rng = np.random.default_rng(4)
    wi, wo = _random_hemisphere(rng, 500, 0.1), _random_hemisphere(rng, 500, 0.1)
    rgb = m.eval_rgb(wi, wo)
    spectrum = m.eval(wi, wo, WL)
    assert np.ptp(spectrum, axis=1).max() < 1e-9 * spectrum.max()
    np.testing.assert_allclose(rgb, np.repeat(spectrum[:, :1], 3, axis=1), rtol=2e-3)


def test_rgb_of_a_red_reflectance_is_red():
    red = next(s for s in measured_spectra() if s.id == "ColorChecker N Ohta/red")
    m = Material("red", "train", 0.6, Dielectric(1.5, 0.0), Reflectance(red.id, tuple(red.values)))
    rgb = m.eval_rgb(_direction(0.0)[None], _direction(40.0, 90.0)[None])[0]
    assert rgb[0] > 3 * rgb[1] and rgb[0] > 3 * rgb[2]


def test_table_of_a_rough_material_agrees_with_analytic_evaluation():
    red = next(s for s in measured_spectra() if s.id == "CIE TCS/TCS09")
    m = Material("rough", "train", 0.5, Dielectric(1.5, 0.008), Reflectance(red.id, tuple(red.values)),
                 ClearCoat(0.4, 1.5))
    table = m.tabulate(WL)
    assert table.is_spectral and np.array_equal(table.wavelengths, WL)
    rng = np.random.default_rng(5)
    th, td, pd = grid_angles()
    i, j, k = rng.integers(0, 90, 800), rng.integers(0, 90, 800), rng.integers(0, 180, 800)
    exact = m.eval_hd(th[i], td[j], pd[k], WL)
    np.testing.assert_allclose(table.eval_hd(th[i], td[j], pd[k]), exact, rtol=1e-6, atol=1e-7)

    # Between nodes: trilinear error ~ (step / lobe width)² / 8 per axis. The MERL steps are ≤ 2°
    # (θh), 1° (θd), 1° (φd); lobes with α ≥ 0.3 are ≥ 17° wide, so ≲ 0.2 % per axis: allow 1 %.
    # Cells that straddle the horizon (analytic zero beyond it) are excluded: cos θi,o > 0.2.
    n = 20000
    th, td, pd = rng.uniform(0, 1.4, n), rng.uniform(0, 1.4, n), rng.uniform(0, 2 * np.pi, n)
    wi, wo = io_from_half_diff(th, td, pd)
    keep = np.minimum(wi[:, 2], wo[:, 2]) > 0.2
    exact = m.eval_hd(th[keep], td[keep], pd[keep], WL)
    approx = table.eval_hd(th[keep], td[keep], pd[keep])
    np.testing.assert_allclose(approx, exact, rtol=1e-2)
    np.testing.assert_allclose(table.eval(wi[keep], wo[keep], WL), exact, rtol=1e-2)


# --- corpus generation, splits, I/O --------------------------------------------------------

def test_generation_is_deterministic_by_seed_and_prefix_stable():
    a, b = generate_corpus(30, seed=7), generate_corpus(30, seed=7)
    assert a == b
    assert generate_corpus(10, seed=7) == a[:10]
    # A material is reproducible alone (Otsu draws also depend on earlier draws, see generate.py).
    alone = [i for i, m in enumerate(a) if not (m.diffuse and m.diffuse.source.startswith("Otsu2018/"))]
    assert len(alone) > 10 and all(make_material(7, i) == a[i] for i in alone)
    assert generate_corpus(30, seed=8) != a


def test_corpus_spans_kinds_splits_and_roughness(corpus):
    kinds = {m.kind.split(":")[0] for m in corpus}
    assert {"plastic", "metal"} <= kinds and any(m.coat for m in corpus)
    counts = {s: sum(m.split == s for m in corpus) for s in SPLITS}
    assert counts["train"] > counts["test"] > 0 and counts["val"] > 0
    alphas = np.array([m.alpha for m in corpus])
    assert alphas.min() < 0.04 and alphas.max() > 0.5
    metals = {m.interface.metal for m in corpus if isinstance(m.interface, Conductor)}
    assert len(metals) >= 4


def test_test_split_shares_no_spectrum_source_or_metal_with_train(corpus):
    by_split = {s: [m for m in corpus if m.split == s] for s in SPLITS}
    for held_out in ("test", "val"):
        train_sources = {m.diffuse.source for m in by_split["train"] if m.diffuse}
        held_sources = {m.diffuse.source for m in by_split[held_out] if m.diffuse}
        assert held_sources and not held_sources & train_sources
        train_metals = {m.interface.metal for m in by_split["train"] if isinstance(m.interface, Conductor)}
        held_metals = {m.interface.metal for m in by_split[held_out] if isinstance(m.interface, Conductor)}
        assert held_metals and not held_metals & train_metals
        # No near-duplicate either: the same patch measured twice counts as the same source.
        train_spectra = np.array([m.diffuse.values for m in by_split["train"] if m.diffuse])
        held_spectra = np.array([m.diffuse.values for m in by_split[held_out] if m.diffuse])
        assert rms_distance(held_spectra, train_spectra).min() >= DUPLICATE_RMS


def test_measured_spectra_come_from_colour_science_and_stay_in_unit_range():
    spectra = measured_spectra()
    ids = {s.id for s in spectra}
    assert {"BabelColor Average/dark skin", "CIE TCS/TCS01", "NIST CQS 9.0/VS1", "PMC/Carrot"} <= ids
    values = np.stack([s.values for s in spectra])
    assert values.shape[1] == REFLECTANCE_GRID_NM.size and values.min() >= 0 and values.max() <= 1
    # The same ColorChecker patch from two labs always lands in one split.
    split_of = {s.id: s.split for s in spectra}
    for patch in ("dark skin", "cyan", "neutral 5 (.70 D)"):
        assert split_of[f"BabelColor Average/{patch}"] == split_of[f"ColorChecker N Ohta/{patch}"]


def test_manifest_round_trips_and_refuses_to_overwrite(tmp_path):
    mats = generate_corpus(12, seed=2)
    path = save_manifest(tmp_path / "manifest.json", mats, seed=2)
    assert load_manifest(path) == mats
    doc = json.loads(path.read_text())
    assert doc["count"] == 12 and sum(doc["splits"].values()) == 12
    with pytest.raises(OutputExistsError):
        save_manifest(path, mats[:3])
    assert load_manifest(path) == mats
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something else"}')
    with pytest.raises(SpecGenError, match="not a SpecGen corpus manifest"):
        load_manifest(bad)


def test_material_rejects_inconsistent_parameters():
    with pytest.raises(SpecGenError, match="conductor has no diffuse"):
        Material("x", "train", 0.1, Conductor("Au"), FLAT_WHITE)
    with pytest.raises(SpecGenError, match="roughness"):
        Material("x", "train", 2.0, Conductor("Au"))
    with pytest.raises(SpecGenError, match="unknown metal"):
        Conductor("Unobtainium")
    with pytest.raises(SpecGenError, match="split"):
        Material("x", "holdout", 0.1, Conductor("Au"))


def test_corpus_cli_writes_manifest_and_a_table(tmp_path, capsys):
    out = tmp_path / "corpus"
    assert cli_main(["corpus", "--n", "6", "--seed", "4", "--out", str(out), "--quiet"]) == 0
    assert load_manifest(out / "manifest.json") == generate_corpus(6, seed=4)
    # Re-running with the same arguments is fine; other materials need --overwrite.
    assert cli_main(["corpus", "--n", "6", "--seed", "4", "--out", str(out), "--quiet",
                     "--tabulate", "mat0002", "--bands", "3"]) == 0
    from specgen_addon.brdf.table import BRDFTable

    table = BRDFTable.load(out / "mat0002.npz")
    assert table.values.shape == (90, 90, 180, 3)
    assert cli_main(["corpus", "--n", "7", "--out", str(out), "--quiet"]) == 2
    assert cli_main(["corpus", "--n", "6", "--seed", "4", "--out", str(out), "--quiet",
                     "--tabulate", "nosuch"]) == 2
    assert "no material 'nosuch'" in capsys.readouterr().err
