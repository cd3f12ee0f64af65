"""The numpy stand-ins for scipy.ndimage (the panel's path in a stock Blender) against scipy itself."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.photo import ndimage_np

scipy_ndimage = pytest.importorskip("scipy.ndimage", reason="scipy is the independent reference here")


@pytest.mark.parametrize("mode", ["constant", "nearest"])
@pytest.mark.parametrize("shape, sigma", [
    ((128, 128, 7), (1.4, 1.4, 0.0)),      # the refinement's design stacks: both axes as matrices
    ((3, 2), (1.0, 1.0)),                  # the kernel reaches past both edges
    ((300, 9), (2.0, 0.6)),                # an axis longer than MATRIX_AXIS_MAX: tap by tap
    ((40, 33), (0.35, 0.0)),
])
def test_gaussian_filter_equals_scipy_on_matrix_and_tap_axes(shape, sigma, mode):
    a = np.random.default_rng(len(shape) + shape[0]).normal(size=shape)
    ours = ndimage_np.gaussian_filter(a, sigma, mode=mode)
    want = scipy_ndimage.gaussian_filter(a, sigma=sigma, mode=mode)
    assert ours.shape == want.shape and ours.flags.c_contiguous
    assert np.abs(ours - want).max() < 1e-12


def test_gaussian_filter_uses_both_strategies_in_these_tests():
    assert 128 <= ndimage_np.MATRIX_AXIS_MAX < 300


def _spiral(n: int = 120) -> np.ndarray:
    """A one-pixel wall wound into a spiral: one component a label must travel far along."""
    m = np.zeros((n, n), bool)
    for k in range(0, n // 2 - 2, 4):
        m[k, k:n - k] = True
        m[k:n - k, n - k - 1] = True
        m[n - k - 1, k + 2:n - k] = True
        m[k + 2:n - k, k + 2] = True
    return m


@pytest.mark.parametrize("seed", range(6))
def test_label_equals_scipy_on_noise_and_a_spiral(seed):
    rng = np.random.default_rng(seed)
    masks = [rng.random(tuple(rng.integers(1, 60, 2))) < rng.random() for _ in range(20)]
    masks += [_spiral(), ~_spiral(), np.zeros((5, 7), bool), np.ones((3, 4), bool)]
    for m in masks:
        ours, n = ndimage_np.label(m)
        want, count = scipy_ndimage.label(m)
        assert n == count and np.array_equal(ours, want)
        np.testing.assert_array_equal(ndimage_np.binary_fill_holes(m), scipy_ndimage.binary_fill_holes(m))
