"""The closure fit's kept products (specgen_addon.bake.closure_fit.closures._Samples) against the
normal equations built directly from the lobes' columns: what the fast paths assemble is exact."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.bake.closure_fit.closures import _band_equations, _ggx_cosines, _samples
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([450.0, 550.0, 650.0])


@pytest.fixture(scope="module")
def samples():
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        lobe = _ggx_cosines(*(np.minimum((wi + wo)[:, 2] / np.linalg.norm(wi + wo, axis=1), 1.0) ** 2,
                              np.clip(wi[:, 2], 0, 1), np.clip(wo[:, 2], 0, 1)), 0.3)
        return np.stack([0.2 / np.pi + lobe * s for s in (0.9, 0.5, 0.1)], -1)
    return _samples(BRDFTable.tabulate(fn, WL), WL, False, 1.5)


def _direct(s, roughness):
    """Diffuse and lobe columns scaled by √w, built from the textbook lobe, and their products."""
    lobes = []
    for r in roughness:
        g = _ggx_cosines(*s._cosines, r) * np.sqrt(s.weight)
        lobes += [g, g * s.fres]
    phi = np.concatenate([s.base, np.stack(lobes)]) if lobes else s.base
    return phi @ phi.T, phi @ s.target_w.T


@pytest.mark.parametrize("roughness", [[0.3], [0.15, 0.6]], ids=["one lobe", "two lobes"])
def test_normal_equations_from_kept_products_equal_the_direct_products(samples, roughness):
    gram, rhs = samples.normal_equations(roughness)
    ref_gram, ref_rhs = _direct(samples, roughness)
    np.testing.assert_allclose(gram, ref_gram, rtol=1e-10)
    np.testing.assert_allclose(rhs, ref_rhs, rtol=1e-10)


def test_per_band_equations_with_a_new_roughness_per_band_equal_the_direct_products(samples):
    rough = np.array([[0.2, 0.25, 0.3], [0.7, 0.65, 0.6]])      # values no lobe has kept
    gram, rhs = _band_equations(samples, rough, np.arange(3))
    for band in range(3):
        ref_gram, ref_rhs = _direct(samples, list(rough[:, band]))
        np.testing.assert_allclose(gram[band], ref_gram, rtol=1e-10)
        np.testing.assert_allclose(rhs[:, band], ref_rhs[:, band], rtol=1e-10)
