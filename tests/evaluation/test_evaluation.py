"""The paper-style evaluation: uplifting baselines, table writer, and a smoke run of paper-tables."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.spectral import spectra
from specgen_addon.evaluation import baselines, report

WL = spectra.wavelength_grid(400.0, 780.0, 20)


@pytest.fixture(scope="module", autouse=True)
def isolated_cache(tmp_path_factory):
    """Uplifting tables and shapes are built into a fresh cache (as on a clean clone)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("SPECGEN_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
    baselines.face_table.cache_clear()
    yield
    baselines.face_table.cache_clear()
    mp.undo()


def _random_colours(n: int, seed: int = 0) -> np.ndarray:
    """In-gamut linear sRGB radiances of brightness 0.05–3 (highlights exceed 1)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, (n, 3)) * rng.uniform(0.05, 3.0, (n, 1))


@pytest.mark.parametrize("method, lut_size, tol_median, tol_max", [
    (baselines.MALLETT2019, None, 0.01, 0.02),
    (baselines.OTSU2018, None, 0.01, 0.15),
    (baselines.JAKOB2019, 5, 0.01, 0.03),
    # Smits (1999) is known not to reproduce its input colour exactly (its seven spectra are
    # fitted, not solved per colour); colour-science's own integration shows the same error.
    (baselines.SMITS1999, None, 0.12, 0.25),
])
def test_uplifting_round_trips_rgb(method, lut_size, tol_median, tol_max):
    rgb = _random_colours(300)
    radiance = baselines.uplift_radiance_image(rgb[None], method, WL, lut_size=lut_size)[0]
    back = spectra.spectral_to_linear_srgb(radiance, WL)
    rel = np.abs(back - rgb).max(axis=1) / rgb.max(axis=1)
    assert np.median(rel) < tol_median
    assert rel.max() < tol_max
    assert np.all(radiance >= 0.0)


def test_uplifting_white_gives_the_white_illuminant():
    # Otsu 2018 is left out: its learned PCA prior maps grey to a non-flat spectrum by design.
    for method in (baselines.MALLETT2019, baselines.SMITS1999, baselines.JAKOB2019):
        lut = 5 if method == baselines.JAKOB2019 else None
        out = baselines.uplift_radiance_image(np.full((1, 1, 3), 2.0), method, WL, lut_size=lut)[0, 0]
        np.testing.assert_allclose(out, 2.0 * spectra.illuminant_spd("D65", WL), rtol=0.03,
                                   err_msg=method)


def test_uplifting_is_homogeneous_in_brightness():
    rgb = _random_colours(50, seed=3)
    for method in (baselines.SMITS1999, baselines.OTSU2018):
        a = baselines.uplift_reflectance(rgb, method, WL)
        b = baselines.uplift_reflectance(4.0 * rgb, method, WL)
        np.testing.assert_allclose(b, 4.0 * a, rtol=1e-9, atol=1e-12)


def test_face_table_lookup_matches_colour_science_per_colour():
    """Between grid nodes Smits (piecewise linear in RGB) is reproduced by the bilinear lookup."""
    rng = np.random.default_rng(7)
    chroma = rng.uniform(0.0, 0.5, (40, 3))
    chroma[np.arange(40), rng.integers(0, 3, 40)] = baselines.CHROMA_MAX
    single = baselines._single_colour_fn(baselines.SMITS1999)
    direct = np.stack([single(c, None)[0] for c in chroma])
    table = baselines.uplift_reflectance(chroma, baselines.SMITS1999, baselines.LUT_WAVELENGTHS_NM)
    err = np.abs(table - direct).max(axis=1)
    assert np.median(err) < 1e-3


def test_black_pixels_uplift_to_zero():
    for method in (baselines.MALLETT2019, baselines.OTSU2018):
        out = baselines.uplift_radiance_image(np.zeros((2, 2, 3)), method, WL)
        assert out.shape == (2, 2, WL.size) and np.all(out == 0.0)


# -- table writer ---------------------------------------------------------------------------------

def _cells():
    data = {("a", "m1", "r"): (30.0, 0.9), ("a", "m2", "r"): (20.0, 0.7),
            ("b", "m1", "r"): (25.0, 0.95), ("b", "m2", "r"): (27.0, 0.8)}
    return lambda arm, mat, role: (None if (arm, mat, role) not in data else
                                   {"psnr_mean": data[arm, mat, role][0], "ssim_mean": data[arm, mat, role][1]})


def test_markdown_table_layout():
    text = report.md_table(["A", "B"], [["x", "1"], ["y", "2"]])
    assert text.splitlines() == ["| A | B |", "| :-- | --: |", "| x | 1 |", "| y | 2 |"]
    with pytest.raises(ValueError):
        report.md_table(["A", "B"], [["only one"]])


def test_methods_table_averages_and_bolds_the_best():
    text = report.methods_table(_cells(), ["m1", "m2"], {"r": "light"}, ["a", "b"], {"a": "A", "b": "B"})
    lines = text.splitlines()
    assert lines[2] == "| m1 | light | **30.00 / 0.9000** | 25.00 / 0.9500 |"
    assert lines[3] == "| m2 | light | 20.00 / 0.7000 | **27.00 / 0.8000** |"
    # averages: a = 25.00 / 0.80, b = 26.00 / 0.875
    assert lines[4] == "| **Average** | light | 25.00 / 0.8000 | **26.00 / 0.8750** |"


def test_rows_table_bolds_the_best_of_each_column_and_adds_extra_columns():
    text = report.rows_table(_cells(), ["m1", "m2"], {"r": "light"}, [("a", "A"), ("b", "B")],
                             [report.Column("Extra", lambda arm: arm.upper())])
    lines = text.splitlines()
    assert lines[0] == "| Method | light PSNR / SSIM | Average PSNR / SSIM | Extra |"
    assert lines[2] == "| A | 25.00 / 0.8000 | 25.00 / 0.8000 | A |"
    assert lines[3] == "| B | **26.00 / 0.8750** | **26.00 / 0.8750** | B |"


def test_photo_only_targets_compare_with_the_best_baseline():
    from specgen_addon.evaluation import report_photo, tables

    psnr = {"sg": 33.0, tables.refined_arm("sg"): 36.0, tables.photo_arm("mallett2019"): 30.0,
            tables.photo_arm("otsu2018"): 32.0}
    get = lambda arm, mat, role: {"psnr_mean": psnr[arm], "ssim_mean": 0.9} if arm in psnr else None
    rows = report_photo.target_rows(get, ["m"], "sg", ["mallett2019", "otsu2018"])
    # the margin over Otsu, the better baseline, for the network alone and the refined table
    assert [r[1] for r in rows] == pytest.approx([1.0, 4.0, 1.0, 4.0])
    assert all(r[2] == report_photo.TARGET_MARGIN_DB for r in rows)


def test_missing_cells_show_a_dash_and_gaps_use_shared_cells():
    get = _cells()
    assert report.fmt(get("c", "m1", "r")) == "—"
    assert report.psnr_gap(get, ["m1", "m2"], ["r"], "b", "a") == pytest.approx(1.0)
    assert report.psnr_gap(get, ["m1"], ["r"], "c", "a") is None


def test_targets_table_marks_missed_targets():
    text = report.targets_table([("beats X by 8 dB", 9.0, 8.0, "≥ +8 dB"),
                                 ("beats Y", -0.5, 0.0, "> 0 dB"), ("Z", None, 0.0, "> 0 dB")])
    lines = text.splitlines()
    assert lines[2].endswith("| met |") and "+9.00 dB" in lines[2]
    assert lines[3].endswith("| **missed** |")
    assert lines[4].endswith("| not measured |")


# -- smoke run of the command --------------------------------------------------------------------

@pytest.mark.slow
def test_paper_tables_smoke_run_writes_every_table_and_resumes(tmp_path, monkeypatch):
    """`paper-tables --smoke` end to end in a temp dir, then again: the rerun recomputes nothing.

    The network is a freshly initialised one (the pipeline is under test here, not the shipped
    weights' quality, which the model's own tests and docs/results.md cover).
    """
    import torch

    from specgen_addon.cli.app import main
    from specgen_addon.model import Config, SpecGen, save_weights

    monkeypatch.setenv("SPECGEN_CACHE_DIR", str(tmp_path / "cache"))
    torch.manual_seed(0)
    weights = save_weights(SpecGen(Config()), tmp_path / "w.pt")
    docs = tmp_path / "docs"
    docs.mkdir()
    out = docs / "results.md"
    args = ["paper-tables", "--out", str(out), "--smoke", "--quiet", "--weights", str(weights)]
    assert main(args) == 0
    text = out.read_text()
    for heading in ("## (a)", "## (b)", "## (c)", "## (e)", "## (f) Photo-only", "## (g) Per corpus family",
                    "## Real data", "## Targets"):
        assert heading in text
    assert "(d)" in text and "Hadamard" in text
    assert "(input under the map, lighting given, refined)" in text.split("## (b)")[1].split("## (c)")[0]
    for family in ("classic", "tinted_coat", "car_paint", "thin_film", "sheen", "lobes", "mean (synthetic)"):
        assert f"| {family}" in text or f"| **{family}**" in text
    for png in ("psnr_per_wavelength.png", "gt_vs_specgen_wavelengths.png", "spectral_curves.png"):
        assert (docs / "img" / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cells = sorted((docs / ".cache").rglob("cells/**/*.json"))
    assert cells
    stamps = {p: p.stat().st_mtime_ns for p in cells}
    assert main(args) == 0
    assert {p: p.stat().st_mtime_ns for p in cells} == stamps
    assert out.read_text().split("## Protocol")[1] == text.split("## Protocol")[1]


# -- protocol and direct network evaluation ----------------------------------------------------------

def test_shape_normal_maps_are_unit_and_face_the_camera():
    from specgen_addon.evaluation import protocol

    for normals, mask in (protocol.superellipsoid_normal_map(48),
                          protocol.suzanne_normal_map(48) or protocol.superellipsoid_normal_map(48)):
        n = normals[mask]
        assert mask.sum() > 0.2 * mask.size
        np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
        assert np.mean(n[:, 2] > 0) > 0.97   # seen from +z: (almost) every covered normal faces us


def test_superellipsoid_normals_match_the_implicit_gradient_numerically():
    from specgen_addon.evaluation import protocol

    normals, mask = protocol.superellipsoid_normal_map(64, power=4.0)
    # Height field z(x, y) of |x|^4 + |y|^4 + |z|^4 = 1 (x, y scaled by 1/0.95 as in the map):
    from specgen_addon.render.geometry import pixel_grid

    x, y = pixel_grid(64)
    x, y = x / 0.95, y / 0.95
    z = np.clip(1 - x ** 4 - y ** 4, 0, None) ** 0.25
    dzdx = np.gradient(z, x[0], axis=1)
    dzdy = np.gradient(z, y[:, 0], axis=0)
    n = np.stack([-dzdx, -dzdy, np.ones_like(z)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    inner = mask & (x ** 4 + y ** 4 < 0.6)
    assert np.abs(normals[inner] - n[inner]).max() < 0.05


def test_network_brdf_equals_the_generated_table_at_grid_points(tmp_path):
    """Direct queries (ablation scoring) and generate_brdf's table agree where the grid is sampled."""
    import torch

    from specgen_addon.model.runtime import inference as infer
    from specgen_addon.evaluation.network_brdf import NetworkBRDF
    from specgen_addon.model import Config, SpecGen, save_weights
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import grid_angles

    torch.manual_seed(3)
    model = SpecGen(Config())
    last = [m for m in model.mapping.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.bias.fill_(0.3)   # an untrained net's r' sits near 0; lift it so the values are non-trivial
    weights = save_weights(model, tmp_path / "w.pt")
    yy, xx = np.mgrid[-1:1:64j, -1:1:64j]
    image = np.where((xx ** 2 + yy ** 2 < 0.9)[..., None], np.array([0.6, 0.3, 0.1]) * (1 + yy[..., None]), 0.0)
    wl = np.array([420.0, 560.0, 700.0])
    table = infer.generate_brdf(image.astype(np.float32), weights=weights, wavelengths_nm=wl)
    net = NetworkBRDF(weights, image.astype(np.float32))
    th, td, pd = grid_angles()
    rng = np.random.default_rng(0)
    i, j, k = rng.integers(0, 90, 300), rng.integers(1, 90, 300), rng.integers(0, 180, 300)  # θd > 0: φd defined
    wi, wo = io_from_half_diff(th[i], td[j], pd[k])
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    expected = table.values[i, j, k][ok]
    assert expected.max() > 1e-3
    np.testing.assert_allclose(net.eval(wi[ok], wo[ok], wl), expected, rtol=1e-4, atol=1e-7)


def test_recorded_arms_round_trip(tmp_path):
    from pathlib import Path

    from specgen_addon.evaluation import ablation

    arm = ablation.ArmResult("joint-aff", "joint-aff-abc", "Joint (AFF)", "aff", True, Path("w/specgen.pt"),
                             500, 221.5, 0)
    settings = ablation.AblationSettings(steps=500, seeds=(0, 1), budget_note="(note)")
    ablation.save_arms(tmp_path / "arms.json", settings, {"joint-aff/seed0": arm})
    loaded_settings, loaded = ablation.load_arms(tmp_path / "arms.json")
    assert loaded == {"joint-aff/seed0": arm}
    assert (loaded_settings.steps, loaded_settings.seeds, loaded_settings.budget_note) == (500, (0, 1), "(note)")
    assert ablation.load_arms(tmp_path / "missing.json") == (None, {})


def test_paper_tables_settings_refuse_an_unknown_input_photo_and_key_the_cache_by_it():
    from specgen_addon.common.errors import SpecGenError
    from specgen_addon.evaluation import tables

    with pytest.raises(SpecGenError, match="input photo"):
        tables.Settings(input_photo="raw")
    kinds = {tables.Settings(input_photo=k).describe()["input_photo"] for k in tables.INPUT_PHOTOS}
    assert kinds == set(tables.INPUT_PHOTOS)
    assert tables.Settings().input_photo == "independent"  # the realistic photo is the default


@pytest.mark.skipif(__import__("importlib").util.find_spec("bpy") is None,
                    reason="the canonical lighting is an HDRI of the bpy wheel")
def test_harness_gives_every_method_the_photo_its_settings_name(tmp_path):
    """The network, its refinement and the photo fits all read Harness.input_photo: the canonical
    render for 'canonical', the independently sampled one (also under a map) for 'independent'."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.evaluation import protocol, tables
    from specgen_addon.render.analytic import GGXReflector

    mat = GGXReflector(alpha=0.1, f0=0.5, kd=0.3)
    mat.name = "probe"
    canon = tables.Harness(tables.Settings(input_photo="canonical"), tmp_path / "a", log=lambda s: None)
    indep = tables.Harness(tables.Settings(), tmp_path / "b", log=lambda s: None)
    np.testing.assert_array_equal(canon.input_photo(mat), input_image.render_input(mat))
    np.testing.assert_array_equal(indep.input_photo(mat), input_image.render_independent_input(mat))
    env = indep.envs.unseen[0]
    np.testing.assert_array_equal(indep.input_photo(mat, env),
                                  protocol.input_under_environment(mat, env, independent=True))
    assert not np.array_equal(indep.input_photo(mat, env), canon.input_photo(mat, env))
