import numpy as np
import pytest

from specgen_addon.brdf.rusinkiewicz import fold_phi_d, half_diff_from_io, io_from_half_diff


def _hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _dir(theta, phi=0.0):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def test_round_trip_recovers_directions_to_1e6():
    rng = np.random.default_rng(1)
    wi, wo = _hemisphere(rng, 2000), _hemisphere(rng, 2000)
    th, td, pd = half_diff_from_io(wi, wo)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    wi2, wo2 = io_from_half_diff(th, td, pd, np.arctan2(h[:, 1], h[:, 0]))
    assert np.abs(wi2 - wi).max() < 1e-6
    assert np.abs(wo2 - wo).max() < 1e-6


def test_round_trip_from_angles():
    rng = np.random.default_rng(2)
    th = rng.uniform(0, np.pi / 2, 500)
    td = rng.uniform(0, np.pi / 2, 500)
    pd = rng.uniform(-np.pi, np.pi, 500)
    back = half_diff_from_io(*io_from_half_diff(th, td, pd))
    for a, b in zip(back, (th, td, pd)):
        assert np.abs(np.angle(np.exp(1j * (a - b)))).max() < 1e-6


def test_swapping_wi_and_wo_gives_same_folded_coordinates():
    rng = np.random.default_rng(3)
    wi, wo = _hemisphere(rng, 1000), _hemisphere(rng, 1000)
    a, b = half_diff_from_io(wi, wo), half_diff_from_io(wo, wi)
    assert np.allclose(a[0], b[0], atol=1e-9)
    assert np.allclose(a[1], b[1], atol=1e-9)
    fa, fb = fold_phi_d(a[2]), fold_phi_d(b[2])
    assert np.allclose(np.minimum(np.abs(fa - fb), np.pi - np.abs(fa - fb)), 0, atol=1e-9)


def test_fold_phi_d_lands_in_half_open_range():
    x = np.linspace(-4 * np.pi, 4 * np.pi, 1001)
    f = fold_phi_d(x)
    assert f.min() >= 0 and f.max() < np.pi


def test_normal_incidence_is_origin():
    th, td, _ = half_diff_from_io(_dir(0.0), _dir(0.0))
    assert th == pytest.approx(0, abs=1e-12) and td == pytest.approx(0, abs=1e-12)


def test_grazing_mirror_pair_has_half_vector_at_normal():
    a = np.deg2rad(89.5)
    th, td, _ = half_diff_from_io(_dir(a, 0.0), _dir(a, np.pi))
    assert th == pytest.approx(0, abs=1e-9)
    assert td == pytest.approx(a, abs=1e-9)


def test_retro_reflection_has_zero_difference_angle():
    a = np.deg2rad(60)
    th, td, _ = half_diff_from_io(_dir(a, 0.3), _dir(a, 0.3))
    assert th == pytest.approx(a, abs=1e-9)
    assert td == pytest.approx(0, abs=1e-7)


def test_one_direction_at_normal_splits_angle_in_half():
    a = np.deg2rad(40)
    th, td, pd = half_diff_from_io(_dir(a, 0.0), _dir(0.0))
    assert th == pytest.approx(a / 2, abs=1e-9)
    assert td == pytest.approx(a / 2, abs=1e-9)
    assert fold_phi_d(pd) == pytest.approx(0.0, abs=1e-9)
