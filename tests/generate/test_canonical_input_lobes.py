"""The refit behind the network's canonical input has no clear coat."""

from __future__ import annotations

from specgen_addon.generate import canonical_input as ci
from specgen_addon.generate.analytic_fit import AnalyticRGB
from specgen_addon.photo.photo_lighting import Light, parse_lighting
from specgen_addon.photo.sphere_image import EXPOSURE, photo_in_scene

SIZE = 48
#: A sun from the upper right front, as a room's lamp.
SUN = Light((0.4, 0.5, 0.77))


def _photo(brdf: AnalyticRGB):
    lighting = parse_lighting(None, lights=(SUN,))
    return photo_in_scene(brdf, lighting.scene(SIZE), EXPOSURE), lighting


def test_the_network_input_refit_leaves_a_clear_coat_out():
    # a matte ball's gentle fall-off drew a broad coat from the fit, which the network read as a
    # gloss in the studio (lab/notebook/real-photos-network.md): the refit has no coat to offer
    photo, lighting = _photo(AnalyticRGB((0.5, 0.5, 0.5), (0.04, 0.04, 0.04), 0.6, coat=1.0, coat_alpha=0.1))
    made = ci.canonical_input(photo, lighting)
    assert made.fit.brdf.coat == 0.0 and made.fit.brdf.coat_alpha is None

