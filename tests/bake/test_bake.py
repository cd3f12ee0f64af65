"""Bake numerics in the core (specgen_addon.bake.lookup): spectral basis, lookup atlas, environment
sampling density, closure fit stored with the atlas. No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.bake import lookup as bake
from specgen_addon.render.environment import srgb_luminance_weights
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([410.0, 480.0, 540.0, 600.0, 660.0, 720.0])

pytest.importorskip("OpenEXR")


@pytest.fixture(scope="module")
def rich_table() -> BRDFTable:
    """Five angular terms with five different spectra: the complete basis (Λ = 6) is needed."""
    rng = np.random.default_rng(0)
    spectra_ = rng.random((5, WL.size))

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).astype(float)
        h = np.cos(th)
        terms = np.stack([np.ones_like(th), h ** 20, h ** 200, (1 - np.cos(td)) ** 5,
                          np.clip(np.sum(wi * wo, -1), 0, 1) ** 4], -1)
        return above[:, None] * (terms @ spectra_) / np.pi
    return BRDFTable.tabulate(fn, WL)


def test_atlas_lookup_reproduces_the_tables_trilinear_interpolation(rich_table, tmp_path):
    table = rich_table
    info = bake.bake_atlas(table, tmp_path / "a.exr", tolerance=1e-6)
    assert info.n_coeffs == 6 and info.rel_error == 0.0  # five components > 3: complete (Λ = 6)
    assert info.n_renders == 2                           # 6 coefficients, four per render
    rng = np.random.default_rng(3)
    th, td, pd = rng.uniform(0, np.pi / 2, 500), rng.uniform(0, np.pi / 2, 500), rng.uniform(-np.pi, np.pi, 500)
    got = bake.atlas_lookup_reference(bake.read_atlas(info), info, th, td, pd)
    # float32 storage of the shifted coefficients: errors ~1e-7 of the table's peak
    np.testing.assert_allclose(got, table.eval_hd(th, td, pd), rtol=2e-4, atol=2e-7 * table.values.max())


def test_shifts_follow_the_first_coefficient_so_a_dim_body_keeps_float32_precision(tmp_path):
    """A peak 10⁵ times brighter than the body: with shifts proportional to c_0 the body's
    spectrum comes back from the float32 atlas to 1e-5, where a constant shift lost it."""
    wl = np.linspace(400, 700, 7)
    body = 0.05 + 0.1 * np.exp(-0.5 * ((wl - 620) / 40) ** 2)
    peak = 0.5 + 0.5 * np.linspace(1, 0, wl.size)

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).astype(float)
        lobe = 1e5 * np.exp(-(th / 0.01) ** 2)
        return above[:, None] * (body[None] + lobe[:, None] * peak[None])
    table = BRDFTable.tabulate(fn, wl)
    info = bake.bake_atlas(table, tmp_path / "a.exr", tolerance=1e-9)
    slots = bake.read_atlas(info)
    assert np.all(slots >= 0) and info.offsets[0] == 0.0 and np.all(np.isfinite(info.offsets))
    rng = np.random.default_rng(5)
    th, td, pd = rng.uniform(0.3, 1.0, 300), rng.uniform(0.1, 1.0, 300), rng.uniform(0, np.pi, 300)
    keep = np.all(table.eval_hd(th, td, pd) > 0, axis=1)
    got = bake.atlas_lookup_reference(slots, info, th[keep], td[keep], pd[keep])
    np.testing.assert_allclose(got, table.eval_hd(th[keep], td[keep], pd[keep]), rtol=1e-4)


def test_an_atlas_of_the_older_format_is_refused_with_a_clear_message(rich_table, tmp_path):
    import json

    info = bake.bake_atlas(rich_table, tmp_path / "a.exr")
    path = bake.save_atlas_info(info, tmp_path / "a.json")
    data = json.loads(path.read_text())
    data["version"] = 1
    path.write_text(json.dumps(data))
    with pytest.raises(bake.SpecGenError, match="older SpecGen"):
        bake.load_atlas_info(path)


def test_atlas_description_keeps_the_closure_fit(rich_table, tmp_path):
    info = bake.bake_atlas(rich_table, tmp_path / "a.exr")
    assert info.closures is not None and info.closures.wavelengths_nm.tolist() == WL.tolist()
    bake.save_atlas_info(info, tmp_path / "a.json")
    back = bake.load_atlas_info(tmp_path / "a.json")
    np.testing.assert_array_equal(back.closures.diffuse, info.closures.diffuse)
    np.testing.assert_array_equal(back.basis, info.basis)


def test_an_atlas_moved_with_its_folder_is_read_from_beside_its_description(rich_table, tmp_path):
    """The description holds the absolute path it was baked at; moved (a .blend's folder taken to
    another machine, a Windows one included), the textures beside it are the atlas; gone from
    both, a clear sentence."""
    import json

    info = bake.bake_atlas(rich_table, tmp_path / "baked" / "a_lookup.exr")
    bake.save_atlas_info(info, tmp_path / "baked" / "a_lookup.json")
    slots = bake.read_atlas(info)
    (tmp_path / "baked").rename(tmp_path / "moved")
    back = bake.load_atlas_info(tmp_path / "moved" / "a_lookup.json")
    assert back.path == tmp_path / "moved" / "a_lookup.exr"
    np.testing.assert_array_equal(bake.read_atlas(back), slots)
    described = json.loads((tmp_path / "moved" / "a_lookup.json").read_text())
    described["path"] = r"C:\Users\me\Projekt\specgen\a_lookup.exr"     # baked on Windows
    (tmp_path / "moved" / "a_lookup.json").write_text(json.dumps(described))
    assert bake.load_atlas_info(tmp_path / "moved" / "a_lookup.json").path == tmp_path / "moved" / "a_lookup.exr"
    back.group_paths[-1].unlink()
    with pytest.raises(bake.SpecGenError, match="baked lookup textures are missing"):
        bake.load_atlas_info(tmp_path / "moved" / "a_lookup.json")


def test_spectral_basis_is_exact_for_low_rank_spectra_and_reports_truncation():
    rng = np.random.default_rng(0)
    coeffs = rng.random((5000, 3))
    spectra = rng.random((3, 9))
    basis, err = bake.spectral_basis(coeffs @ spectra, tolerance=1e-6)
    assert basis.shape == (4, 9) and err < 1e-6       # rank 3 ≤ four slots: one render
    np.testing.assert_allclose(basis @ basis.T, np.eye(4), atol=1e-12)
    assert np.all(basis[0] >= 0)                      # B_0: the non-negative Perron vector
    full_rank = rng.random((5000, 9))
    basis, err = bake.spectral_basis(full_rank, tolerance=1e-6)
    assert basis.shape == (9, 9) and err == 0.0        # nothing smaller fits: complete, exact
    basis, err = bake.spectral_basis(full_rank, tolerance=1.0)
    assert basis.shape == (4, 9) and 0 < err <= 1.0     # loose tolerance: truncated, error reported
    # the reported error is the relative RMS residual of the entries' normalised spectra
    approx = (full_rank @ basis.T) @ basis
    norm2 = np.sum(full_rank ** 2, axis=1)
    w = 1.0 / (norm2 + bake.SHAPE_FLOOR ** 2 * norm2.max())
    direct = np.sqrt(np.sum(w * np.sum((approx - full_rank) ** 2, axis=1)) / np.sum(w * norm2))
    assert err == pytest.approx(direct, rel=1e-6)


def test_spectral_basis_keeps_a_dim_body_colour_beside_a_bright_peak():
    """Four spectral terms, three components: a bright peak whose tint varies (1 % of the entries,
    100–1000× brighter) and a body of two colours. An energy-weighted PCA spends two components on
    the peak and leaves the body 19 % wrong; the shape-weighted basis keeps the body to 0.3 %."""
    wl = np.linspace(380, 780, 21)
    body = 0.2 + 0.6 * np.exp(-0.5 * ((wl - 620) / 40) ** 2)        # orange-red body spectrum
    sheen = 0.1 + 0.05 * np.cos(wl / 30)                             # a second, wiggly body term
    peak, fresnel = np.ones_like(wl), np.linspace(-0.2, 0.2, wl.size)
    rng = np.random.default_rng(1)
    n = 20000
    amp_peak = np.where(rng.random(n) < 0.01, rng.uniform(50, 500, n), 0.0)[:, None]
    m = (rng.uniform(0.05, 0.3, n)[:, None] * body + amp_peak * peak
         + amp_peak * rng.uniform(0, 1, n)[:, None] * fresnel + rng.uniform(0.0, 0.3, n)[:, None] * sheen)
    body_rows = amp_peak[:, 0] == 0

    def worst_body_error(basis: np.ndarray) -> float:
        approx = (m[body_rows] @ basis.T) @ basis
        return float(np.max(np.linalg.norm(approx - m[body_rows], axis=1)
                            / np.linalg.norm(m[body_rows], axis=1)))

    basis, _ = bake.spectral_basis(m, max_coeffs=3)
    eig, vec = np.linalg.eigh(m.T @ m)                               # the energy-weighted PCA
    energy_basis = vec[:, np.argsort(eig)[::-1][:3]].T
    assert basis.shape == (3, 21)
    assert worst_body_error(basis) < 5e-3 < 0.1 < worst_body_error(energy_basis)


def test_environment_density_is_luminance_times_solid_angle():
    rng = np.random.default_rng(4)
    rgb = rng.random((8, 16, 3))
    p = bake.environment_density(rgb)
    assert p.sum() == pytest.approx(1.0)
    h = rgb.shape[0]
    # texel solid angle ∝ cos(elevation) at the row centre: (2π/W)(π/H) cos(el)
    el = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
    ref = (rgb @ srgb_luminance_weights()) * np.cos(el)[:, None]
    np.testing.assert_allclose(p, ref / ref.sum(), rtol=1e-12)
    assert bake.environment_density(np.zeros((4, 8, 3))).sum() == pytest.approx(1.0)  # black: uniform


def test_environment_directions_follow_the_density(tmp_path):
    rgb = np.zeros((16, 32, 3), np.float32)
    rgb[3, 5] = 100.0                                  # one bright texel
    rgb += 0.01
    env = bake.EnvironmentLight(rgb, n_list=4096)
    _, lst = bake.bake_environment(env, tmp_path / "m.exr", tmp_path / "l.exr")
    import OpenEXR

    with OpenEXR.File(str(lst), separate_channels=True) as f:
        ch = f.parts[0].channels
        d = np.stack([np.asarray(ch[c].pixels) for c in "RGB"], -1).reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-5)
    # Blender's equirect mapping of those directions lands in the bright texel as often as p says
    u = -np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi) + 0.5
    v = np.arcsin(np.clip(d[:, 2], -1, 1)) / np.pi + 0.5
    row, col = ((1 - v) * 16).astype(int), (u * 32).astype(int) % 32
    p = bake.environment_density(rgb)
    assert np.mean((row == 3) & (col == 5)) == pytest.approx(p[3, 5], abs=0.01)


def test_the_material_file_written_beside_the_bake_is_finished_before_a_cancel_is_raised(rich_table, tmp_path,
                                                                                         monkeypatch):
    import threading

    from specgen_addon.brdf.table import BRDFTable as Table
    from specgen_addon.common.errors import Cancelled

    started, saved = threading.Event(), []
    real_save = Table.save

    def slow_save(self, path, **kwargs):
        started.set()
        threading.Event().wait(0.5)            # still writing when the bake is cancelled
        saved.append(real_save(self, path, **kwargs))
        return saved[-1]

    monkeypatch.setattr(Table, "save", slow_save)
    with pytest.raises(Cancelled):
        bake.bake_lookup(rich_table, tmp_path, "ball", save_table=True,
                         cancel=lambda: started.wait(5.0))
    assert saved and saved[0].is_file()         # finished (so a clean-up after the raise sees it)
    assert not (tmp_path / "ball_lookup.json").exists()


def test_a_failing_material_file_fails_the_bake(rich_table, tmp_path, monkeypatch):
    from specgen_addon.brdf.table import BRDFTable as Table

    def broken(self, path, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(Table, "save", broken)
    with pytest.raises(OSError, match="disk full"):
        bake.bake_lookup(rich_table, tmp_path, "ball", save_table=True)
