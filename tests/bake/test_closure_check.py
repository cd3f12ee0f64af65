"""The closure fit's rendered check (specgen_addon.bake.closure_fit.closures, ``check=True``):
a first fit that renders within a just-noticeable difference is kept without the second weighting."""

from __future__ import annotations

import numpy as np

from specgen_addon.bake.closure_fit import closures
from specgen_addon.bake.closure_fit.closures import GOOD_ENOUGH_DELTA_E, WEIGHTINGS, fit_closures, ggx_lobe
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([420.0, 500.0, 580.0, 660.0])


def _lambert_ggx(th, td, pd):
    wi, wo = io_from_half_diff(th, td, pd)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return above * np.array([0.1, 0.5, 0.3, 0.2]) / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * 0.2


def _counting_checks(monkeypatch, errors: list[float]) -> list[float]:
    """Make each rendered check return the next of ``errors`` and record the ones returned."""
    returned: list[float] = []

    def check(fit, table):
        returned.append(errors[len(returned)])
        return returned[-1]

    monkeypatch.setattr(closures, "rendered_fit_error", check)
    return returned


def test_a_first_fit_within_a_just_noticeable_difference_is_kept_without_the_second(monkeypatch):
    table = BRDFTable.tabulate(_lambert_ggx, WL)
    returned = _counting_checks(monkeypatch, [0.5 * GOOD_ENOUGH_DELTA_E, 0.0])
    fit = fit_closures(table, check=True)
    assert returned == [0.5 * GOOD_ENOUGH_DELTA_E]
    plain = fit_closures(table, weighting=WEIGHTINGS[0])
    np.testing.assert_array_equal(fit.diffuse, plain.diffuse)
    np.testing.assert_array_equal(fit.roughness, plain.roughness)


def test_a_first_fit_that_renders_visibly_off_is_compared_with_the_second(monkeypatch):
    table = BRDFTable.tabulate(_lambert_ggx, WL)
    returned = _counting_checks(monkeypatch, [2.0 * GOOD_ENOUGH_DELTA_E, 1.5 * GOOD_ENOUGH_DELTA_E])
    fit = fit_closures(table, check=True)
    assert len(returned) == len(WEIGHTINGS)
    assert fit.rendered_error == 1.5 * GOOD_ENOUGH_DELTA_E
