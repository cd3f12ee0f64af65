"""Saturated pixels of any format are left out of the refinement's fit (RefineOptions.exclude)."""

from __future__ import annotations

import numpy as np

from specgen_addon.photo.photo_lighting import parse_light, parse_lighting
from specgen_addon.generate.refine import RefineOptions, refine_brdf, render_under

SIZE = 40
WL = np.linspace(380.0, 780.0, 9)


def test_excluded_pixels_are_counted_as_clipped_and_do_not_pull_the_fit(ramp_table):
    """A linear photo (no clip level) whose highlight core was flattened by the camera: marked as
    saturated, the flattened pixels neither count as data nor drag the fit down."""
    light = parse_lighting(None, lights=(parse_light("20,30"),), ambient=0.05)
    photo = render_under(ramp_table, light.scene(SIZE), light.image_exposure)
    core = photo.max(-1) > np.percentile(photo.max(-1), 97)
    flattened = photo.copy()
    flattened[core] = 0.5 * photo[core]          # a clipped core, far below the truth
    plain = refine_brdf(ramp_table, flattened, light, RefineOptions(clip_level=None))
    masked = refine_brdf(ramp_table, flattened, light, RefineOptions(clip_level=None, exclude=core))
    assert plain.clipped_fraction == 0.0 and masked.clipped_fraction > 0.0
    truth = render_under(ramp_table, light.scene(SIZE), light.image_exposure)

    def err(res):
        img = render_under(res.table, light.scene(SIZE), light.image_exposure)
        return float(np.mean((img[core] - truth[core]) ** 2))

    assert err(masked) < err(plain)
