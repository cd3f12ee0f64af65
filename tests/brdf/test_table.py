import numpy as np
import pytest

from specgen_addon.common.errors import BRDFFormatError, SpecGenError
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import (BRDFTable, grid_angles, mu_law_decode, mu_law_encode,
                                 theta_h_index)


def _smooth(th, td, pd):
    return np.stack([1 + np.cos(th), 1 + 0.5 * np.sin(td), 1 + 0.2 * np.cos(2 * pd)], axis=-1)


@pytest.fixture(scope="module")
def spectral_table():
    wl = np.array([400.0, 500.0, 600.0, 700.0])
    return BRDFTable.tabulate(lambda a, b, c: np.stack([(1 + i) * np.ones_like(a) + a for i in range(4)], -1),
                              wavelengths=wl, metadata={"source": "test"})


def test_tabulate_places_values_at_merl_sample_positions():
    t = BRDFTable.tabulate(_smooth)
    th, td, pd = grid_angles()
    i, j, k = 37, 12, 101
    assert np.allclose(t.values[i, j, k], _smooth(th[i], td[j], pd[k]), atol=1e-6)
    assert th[1] == pytest.approx((1 / 90) ** 2 * np.pi / 2)
    assert theta_h_index(th[45]) == pytest.approx(45)


def test_eval_hd_interpolates_a_function_linear_in_index_space_exactly():
    # f = index coordinates themselves: trilinear interpolation must reproduce them exactly.
    def idx(th, td, pd):
        return np.stack([theta_h_index(th), td / (np.pi / 2) * 90, np.cos(2 * pd)], -1)

    t = BRDFTable.tabulate(idx)
    rng = np.random.default_rng(0)
    th = (rng.uniform(0, 89, 500) / 90) ** 2 * np.pi / 2
    td = rng.uniform(0, 89, 500) / 90 * np.pi / 2
    got = t.eval_hd(th, td, np.zeros(500))
    assert np.allclose(got[:, 0], theta_h_index(th), atol=1e-4)
    assert np.allclose(got[:, 1], td / (np.pi / 2) * 90, atol=1e-4)


def test_eval_wraps_phi_d_periodically_and_folds_reciprocal_pairs():
    t = BRDFTable.tabulate(_smooth)
    wi, wo = io_from_half_diff(np.full(5, 0.3), np.full(5, 0.7), np.linspace(-3, 3, 5))
    assert np.allclose(t.eval(wi, wo), t.eval(wo, wi), atol=1e-6)


def test_eval_is_zero_below_horizon():
    t = BRDFTable.tabulate(_smooth)
    wi = np.array([[0.0, 0.6, -0.8]])
    wo = np.array([[0.0, 0.0, 1.0]])
    assert np.all(t.eval(wi, wo) == 0)


def test_wavelength_interpolation_is_linear_and_range_checked(spectral_table):
    wi = wo = np.array([[0.0, 0.0, 1.0]])
    v = spectral_table.eval(wi, wo, np.array([450.0, 700.0]))
    assert np.allclose(v, [[1.5, 4.0]], atol=1e-6)
    with pytest.raises(SpecGenError, match="outside"):
        spectral_table.eval(wi, wo, np.array([800.0]))


def test_save_load_round_trip_keeps_values_and_metadata(tmp_path, spectral_table):
    p = spectral_table.save(tmp_path / "t.npz")
    back = BRDFTable.load(p)
    assert np.array_equal(back.values, spectral_table.values)
    assert np.array_equal(back.wavelengths, spectral_table.wavelengths)
    assert back.metadata["source"] == "test" and back.metadata["units"] == "1/sr"


def test_save_refuses_to_overwrite_and_leaves_no_temp_files(tmp_path, spectral_table):
    p = spectral_table.save(tmp_path / "t.npz")
    with pytest.raises(SpecGenError, match="exists"):
        spectral_table.save(p)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["t.npz"]


def test_load_rejects_corrupt_and_foreign_files(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(BRDFFormatError, match="bad.npz"):
        BRDFTable.load(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, values=np.zeros(3))
    with pytest.raises(BRDFFormatError, match="foreign.npz"):
        BRDFTable.load(foreign)


def test_rgb_projection_of_flat_spectrum_is_grey():
    wl = np.linspace(380, 780, 21)
    t = BRDFTable.tabulate(lambda a, b, c: np.full((a.size, 21), 0.25), wavelengths=wl)
    rgb = t.to_rgb().values[10, 10, 10]
    assert np.allclose(rgb, 0.25, rtol=1e-3)


def test_mu_law_round_trip_and_range():
    r = np.concatenate([[0.0], np.logspace(-4, 3, 200)])
    assert np.allclose(mu_law_decode(mu_law_encode(r)), r, rtol=1e-10)
    assert mu_law_encode(np.array([1.0]))[0] == pytest.approx(1.0)
    assert mu_law_encode(np.array([0.0]))[0] == 0.0


def test_bad_values_counts_each_kind_and_passes_clean_tables():
    from specgen_addon.common.limits import MAX_BRDF_VALUE, bad_values

    clean = np.random.default_rng(0).random((3, 5_000_000)).astype(np.float32)   # several chunks
    assert bad_values(clean) is None
    dirty = clean.copy()
    dirty[2, -3:] = np.nan
    dirty[0, 0] = np.inf
    dirty[1, 7] = -0.5
    dirty[1, 8] = 10 * MAX_BRDF_VALUE
    assert bad_values(dirty) == "3 NaN, 1 infinite, 1 overflowing, 1 negative of 15,000,000 values"
    assert bad_values(np.float32([-0.5, 1.0]), allow_negative=True) is None
    assert bad_values(np.float32([-0.5, 1.0])) == "1 negative of 2 values"
