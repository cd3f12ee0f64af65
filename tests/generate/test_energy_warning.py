"""The refinement warns when the refined material reflects more light than it receives (the
photo is brighter than its lighting allows), and only then."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.generate.refine import RefineOptions, refine_brdf, render_under
from specgen_addon.photo.photo_lighting import parse_light, parse_lighting

SIZE = 40
WL = np.linspace(380.0, 780.0, 9)


def _lambertian(albedo: float) -> BRDFTable:
    def f(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        return np.where(above[:, None], np.full(WL.size, albedo / np.pi), 0.0)

    return BRDFTable.tabulate(f, WL)


@pytest.fixture(scope="module")
def network():
    return _lambertian(0.5)


@pytest.mark.parametrize("photographed,warned", [(0.7, False), (1.6, True)])
def test_a_photo_brighter_than_its_light_allows_is_warned_about(network, photographed, warned):
    light = parse_lighting(None, lights=(parse_light("20,30"),), ambient=0.05)
    photo = render_under(_lambertian(photographed), light.scene(SIZE), light.image_exposure)
    res = refine_brdf(network, photo, light, RefineOptions(clip_level=None))
    said = [w for w in res.warnings if "reflects up to" in w]
    assert bool(said) == warned, res.warnings
    if warned:
        assert "its power too low for this material" in said[0] and "not energy conserving" in said[0]
