"""The network's input under a given light: the photo refitted and re-rendered in the canonical studio."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.generate import canonical_input as ci
from specgen_addon.generate.analytic_fit import AnalyticRGB
from specgen_addon.photo.photo_lighting import InputLighting, Light, parse_lighting
from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop, photo_in_scene, render_input
from specgen_addon.render import sphere_geometry

SIZE = 64
#: A sun from the upper right front: about a tenth of the ball's visible side is in its shadow.
SUN = Light((0.4, 0.5, 0.77))


def test_a_lambertian_under_a_sun_re_rendered_in_the_studio_matches_its_studio_render():
    brdf = AnalyticRGB((0.62, 0.41, 0.18), (0.0, 0.0, 0.0), 0.5, edge=0.0)   # a Lambertian, RGB
    lighting = parse_lighting(None, lights=(SUN,))
    photo = photo_in_scene(brdf, lighting.scene(SIZE), EXPOSURE)
    made = ci.canonical_input(photo, lighting)
    direct = render_input(brdf, SIZE)
    inside = sphere_geometry(SIZE).mask
    # The photo lies in the fitted model's class (Lambert, no lobe), so the fit recovers the
    # albedo up to the solver's ridge (1e-12 relative) and the photo's float32 rounding (1e-7),
    # and both studio renders share one scene and its samples: 1e-4 of the brightest pixel leaves
    # three orders of margin, and still fails for a 0.1 % albedo error or any lobe left in.
    # The sun leaves part of the ball black; the studio lights all of it: that side is
    # extrapolated by the fit, which is the point.
    assert made.crop.copied
    np.testing.assert_allclose(made.crop.image[inside], direct[inside], rtol=0, atol=1e-4 * direct.max())
    np.testing.assert_allclose(made.fit.brdf.diffuse, (0.62, 0.41, 0.18), rtol=1e-4)


def test_the_canonical_studio_never_goes_through_the_refit(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the canonical path must not refit the photo")

    monkeypatch.setattr(ci, "fit_photo", refuse)
    photo = np.random.default_rng(0).uniform(0, 1, (SIZE, SIZE, 3)).astype(np.float32)
    for copied in (True, False):
        crop = SphereCrop(photo, copied)
        given, made = ci.network_crop(crop, photo, InputLighting())
        assert made is None and given.copied is copied
        assert given.image.tobytes() == (photo * InputLighting().network_gain()).tobytes()


def test_without_refit_a_photo_under_a_sun_goes_to_the_network_as_it_was(monkeypatch):
    # the pipeline's refined runs (refit=False) show the network the photo × gain, untouched
    def refuse(*args, **kwargs):
        raise AssertionError("refit=False must not refit the photo")

    monkeypatch.setattr(ci, "fit_photo", refuse)
    lighting = parse_lighting(None, lights=(SUN,))
    photo = np.random.default_rng(1).uniform(0, 1, (SIZE, SIZE, 3)).astype(np.float32)
    given, made = ci.network_crop(SphereCrop(photo, False), photo, lighting, refit=False)
    assert made is None and given.copied is False
    assert given.image.tobytes() == (photo * lighting.network_gain()).tobytes()


def test_a_photo_already_in_the_studio_is_not_re_rendered():
    with pytest.raises(ValueError, match="canonical studio"):
        ci.canonical_input(np.zeros((SIZE, SIZE, 3)), InputLighting())
