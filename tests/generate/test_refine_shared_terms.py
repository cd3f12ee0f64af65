"""The refinement's normal equations made once and shared: the same answers as made afresh."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.generate.refine.holdout import block_folds, holdout_error, holdout_errors
from specgen_addon.generate.refine.refinement import _data_terms, _with_columns


def test_a_design_with_other_body_columns_has_the_data_term_made_afresh():
    rng = np.random.default_rng(3)
    design, photo = rng.random((80, 3, 12)), rng.random((80, 3))
    other = design.copy()
    other[:, :, 6:9] = rng.random((80, 3, 3))
    updated = _with_columns(_data_terms(design, photo, 0.5), other, photo, slice(6, 9))
    fresh = _data_terms(other, photo, 0.5)
    np.testing.assert_allclose(updated.gram, fresh.gram, rtol=1e-12)
    np.testing.assert_allclose(updated.rhs, fresh.rhs, rtol=1e-12)
    assert updated.yy == pytest.approx(fresh.yy) and updated.n_obs == fresh.n_obs


def test_hold_out_errors_of_several_fits_equal_each_fit_held_out_alone():
    rng = np.random.default_rng(4)
    design, photo = rng.random((64, 3, 5)), rng.random((64, 3))
    folds = block_folds((8, 8), np.arange(64), block_px=2)
    least_squares = lambda d, y: np.linalg.lstsq(d.reshape(-1, 5), y.reshape(-1), rcond=None)[0]
    half = lambda d, y: 0.5 * least_squares(d, y)
    together = holdout_errors(design, photo, folds, [least_squares, half])
    assert together == [holdout_error(design, photo, folds, least_squares), holdout_error(design, photo, folds, half)]
    assert together[0] != together[1]
