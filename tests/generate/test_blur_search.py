"""The refinement's search for the photo's blur: the walk lands where trying every candidate does."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX, gaussian_blur_stack, search_blur


@pytest.mark.parametrize("minimum", range(len(BLUR_CANDIDATES_PX)))
def test_the_walk_finds_the_minimum_of_a_residual_with_one_minimum(minimum):
    n = len(BLUR_CANDIDATES_PX)
    values = [(k - minimum) ** 2 + 0.1 * k for k in range(n)]
    calls: list[int] = []

    def residual(k: int) -> float:
        calls.append(k)
        return values[k]

    assert search_blur(residual, n, "walk") == int(np.argmin(values)) == search_blur(values.__getitem__, n, "all")
    assert len(calls) == len(set(calls)) < n          # each candidate once, fewer than all of them


def test_a_flat_residual_keeps_the_walks_start_and_all_keeps_the_sharpest():
    flat = [1.0] * len(BLUR_CANDIDATES_PX)
    assert search_blur(flat.__getitem__, len(flat), "all") == 0
    assert search_blur(flat.__getitem__, len(flat), "walk", start=2) == 2


def test_an_unknown_search_is_refused():
    with pytest.raises(ValueError):
        search_blur(lambda k: 0.0, 3, "sideways")


def test_the_float32_blur_agrees_with_the_float64_blur():
    img = np.random.default_rng(1).random((40, 36, 5))
    for sigma in BLUR_CANDIDATES_PX[1:]:
        single = gaussian_blur_stack(img, sigma, dtype=np.float32)
        assert single.dtype == np.float32
        np.testing.assert_allclose(single, gaussian_blur_stack(img, sigma), rtol=1e-5, atol=1e-6)
