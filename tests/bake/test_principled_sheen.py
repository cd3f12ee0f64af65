"""The Principled stand-in's sheen is fitted, not fixed at 0: a velvet-like material (Lambert plus
a Charlie sheen) gets its sheen colour and roughness back; a plastic gets none."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.bake.closure_fit import ClosureFit, fit_closures, ggx_lobe
from specgen_addon.bake.closure_fit.closures import srgb_weights
from specgen_addon.bake.closure_fit.principled import principled_from_closures
from specgen_addon.bake.closure_fit.sheen import charlie_sheen, fit_sheen
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([400.0, 500.0, 600.0, 700.0])
BASE = np.array([0.3, 0.2, 0.1, 0.1])
SHEEN = np.array([0.1, 0.3, 0.6, 0.8])


def _table(sheen: bool) -> BRDFTable:
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        lobe = charlie_sheen(wi, wo, 0.4)[:, None] * SHEEN if sheen else ggx_lobe(wi, wo, 0.3)[:, None] * 0.05
        return above * BASE / np.pi + lobe
    return BRDFTable.tabulate(fn, WL)


def test_charlie_sheen_is_reciprocal_and_brightest_at_grazing_backscatter():
    wi = np.array([[np.sin(1.4), 0.0, np.cos(1.4)], [0.0, 0.0, 1.0]])
    wo = np.array([[np.sin(1.3), 0.0, np.cos(1.3)], [np.sin(0.3), 0.0, np.cos(0.3)]])
    np.testing.assert_allclose(charlie_sheen(wi, wo, 0.5), charlie_sheen(wo, wi, 0.5))
    assert charlie_sheen(wi, wo, 0.5)[0] > 10 * charlie_sheen(wi, wo, 0.5)[1]


@pytest.mark.slow
def test_a_velvet_gets_its_sheen_back_in_the_principled_stand_in():
    table = _table(sheen=True)
    fit = fit_closures(table)
    sheen = fit_sheen(lambda wi, wo: table.eval(wi, wo), fit)
    assert sheen is not None and sheen.roughness == pytest.approx(0.4)
    expected = SHEEN @ srgb_weights(WL)
    np.testing.assert_allclose(sheen.colour, expected, rtol=0.05, atol=0.01)
    np.testing.assert_allclose(sheen.diffuse, BASE @ srgb_weights(WL), rtol=0.05, atol=0.01)
    fit.sheen = sheen.to_dict()
    p = principled_from_closures(ClosureFit.from_json(fit.to_json()))       # kept through the JSON
    assert p.sheen_weight == pytest.approx(min(expected.max(), 1.0), rel=0.05)
    np.testing.assert_allclose(p.sheen_tint, expected / expected.max(), rtol=0.05, atol=0.01)
    assert p.sheen_roughness == pytest.approx(0.4) and p.metallic == 0.0


@pytest.mark.slow
def test_a_plastic_gets_no_sheen():
    table = _table(sheen=False)
    fit = fit_closures(table)
    assert fit_sheen(lambda wi, wo: table.eval(wi, wo), fit) is None
    assert principled_from_closures(fit).sheen_weight == 0.0
