"""The closure fit's small exact NNLS (all bands at once, every face enumerated) against
scipy.optimize.nnls, band by band."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

from specgen_addon.bake.closure_fit.closures import _nnls_small


def _problem(rng, n_rows: int, k: int, bands: int, per_band: bool, columns: str):
    designs = rng.uniform(-0.2, 1.0, (bands if per_band else 1, n_rows, k))
    if columns == "two equal":          # every face holding both is singular but for the ridge
        designs[..., k - 1] = designs[..., 0]
    elif columns == "one zero":         # the face of that column alone is exactly singular
        designs[..., k - 1] = 0.0
    y = rng.normal(0.3, 1.0, (n_rows, bands))
    a = [designs[b if per_band else 0] for b in range(bands)]
    gram = np.stack(a if per_band else a[:1])
    gram = np.einsum("bnk,bnj->bkj", gram, gram)
    rhs = np.stack([a[b].T @ y[:, b] for b in range(bands)], axis=1)
    return (gram if per_band else gram[0]), rhs, (y * y).sum(0), a, y


@pytest.mark.parametrize("per_band", [False, True], ids=["one design", "a design per band"])
@pytest.mark.parametrize("columns", ["independent", "two equal", "one zero"])
def test_small_nnls_matches_scipy_band_by_band(per_band, columns):
    rng = np.random.default_rng(3 + 2 * per_band + len(columns))
    gram, rhs, tt, a, y = _problem(rng, 40, 5, 7, per_band, columns)
    x, obj = _nnls_small(gram, rhs, tt)
    assert np.all(x >= 0)
    for b in range(y.shape[1]):
        ref, res = nnls(a[b], y[:, b])
        # the objective is unique; with two equal columns the split between them is not
        assert obj[b] == pytest.approx(res ** 2, rel=1e-9, abs=1e-9)
        assert np.sum((a[b] @ x[:, b] - y[:, b]) ** 2) == pytest.approx(res ** 2, rel=1e-9, abs=1e-9)
        if columns != "two equal":
            np.testing.assert_allclose(x[:, b], ref, rtol=1e-7, atol=1e-9)


def test_small_nnls_with_the_fits_six_columns_matches_scipy_in_every_band():
    # two diffuse and two lobes × (plain, Fresnel): the size the closure fit solves, with many
    # bands whose unconstrained optimum is negative somewhere (the KKT early stop decides them)
    rng = np.random.default_rng(11)
    gram, rhs, tt, a, y = _problem(rng, 60, 6, 40, True, "independent")
    x, obj = _nnls_small(gram, rhs, tt)
    some_zero = 0
    for b in range(y.shape[1]):
        ref, res = nnls(a[b], y[:, b])
        some_zero += bool(np.any(ref == 0))
        assert obj[b] == pytest.approx(res ** 2, rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(x[:, b], ref, rtol=1e-7, atol=1e-9)
    assert some_zero >= 10        # the constrained case is what is tested
