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


def test_a_channel_the_white_balance_raised_is_clipped_at_its_own_full_scale(ramp_table):
    """An 8-bit photo's camera clips before the white balance: a channel the balance multiplied
    by 1.6 is clipped at 1.6, so values between 1 and 1.6 are data, not clipped pixels."""
    light = parse_lighting(None, lights=(parse_light("20,30"),), ambient=0.05)
    photo = render_under(ramp_table, light.scene(SIZE), light.image_exposure)
    photo = photo * (0.9 / photo.max())                      # below full scale in every channel
    gains = np.array([1.6, 1.0, 1.0])
    balanced = photo * gains
    assert np.any(balanced[..., 0] > 1.0)                     # what a clip at 1 would take as clipped
    as_if_unbalanced = refine_brdf(ramp_table, balanced, light, RefineOptions())
    at_own_scale = refine_brdf(ramp_table, balanced, light, RefineOptions(full_scale=tuple(gains)))
    assert as_if_unbalanced.clipped_fraction > 0.0 and at_own_scale.clipped_fraction == 0.0
    core = refine_brdf(ramp_table, np.minimum(balanced * 1.2, gains), light, RefineOptions(full_scale=tuple(gains)))
    assert core.clipped_fraction > 0.0                         # a pixel at the balanced full scale still is
