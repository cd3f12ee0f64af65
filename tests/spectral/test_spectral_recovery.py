"""Otsu 2018 reflectance recovery in numpy, against colour-science's implementation."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.otsu2018 import otsu2018_cluster, otsu2018_reflectance, xyz_of_reflectance

OTSU_GRID_NM = np.arange(380.0, 731.0, 10.0)


def _random_xyz(n: int, seed: int = 0) -> np.ndarray:
    colour = pytest.importorskip("colour")
    rgb = np.random.default_rng(seed).uniform(0.01, 0.95, size=(n, 3))
    return colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)


def test_numpy_otsu_2018_matches_colour_science_on_random_colours():
    colour = pytest.importorskip("colour")
    for xyz in _random_xyz(100):
        expected = colour.recovery.XYZ_to_sd_Otsu2018(xyz).values
        np.testing.assert_allclose(otsu2018_reflectance(xyz), expected, atol=2e-3)


def test_cluster_walk_matches_colour_science_dataset_selection():
    pytest.importorskip("colour")
    from colour.recovery.otsu2018 import DATASET_REFERENCE_OTSU2018 as dataset

    for xyz in _random_xyz(200, seed=3):
        xy = xyz[:2] / xyz.sum()
        assert otsu2018_cluster(xy) == dataset.select(xy)


def test_recovered_reflectance_has_the_colour_it_was_asked_for():
    """Away from the clip at 0 and 1 the recovered spectrum reproduces its XYZ exactly (D65)."""
    xyz = np.array([0.20, 0.18, 0.12])                # a muted warm colour, well inside [0, 1]
    r = otsu2018_reflectance(xyz)
    assert 0.0 < r.min() and r.max() < 1.0
    np.testing.assert_allclose(xyz_of_reflectance(r, OTSU_GRID_NM), xyz, rtol=2e-3)


def test_resampling_holds_the_last_value_beyond_730_nm():
    xyz = np.array([0.3, 0.3, 0.3])
    fine = otsu2018_reflectance(xyz, np.array([730.0, 760.0, 780.0]))
    assert np.allclose(fine, otsu2018_reflectance(xyz)[-1])


@pytest.mark.parametrize("xyz", [[0.0, 0.0, 0.0], [np.nan, 0.1, 0.1], [-0.1, -0.1, -0.1]])
def test_black_or_invalid_colours_are_refused(xyz):
    with pytest.raises(SpecGenError, match="positive CIE XYZ"):
        otsu2018_reflectance(np.array(xyz))
