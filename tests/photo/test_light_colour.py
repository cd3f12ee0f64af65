"""A room light's colour: a CIE illuminant, a colour temperature or linear RGB; several lights and
an ambient term add up."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.photo_lighting import Light, parse_light, parse_lighting
from specgen_addon.spectral import spectra


def _rgb(colour: str) -> np.ndarray:
    return Light((0.0, 0.0, 1.0), 1.0, colour).distant_light().rgb()


@pytest.mark.parametrize("rgb", [(1.0, 0.5, 0.25), (0.2, 0.9, 0.4), (0.0, 0.0, 1.0), (3.0, 3.0, 3.0)])
def test_an_rgb_light_is_seen_in_its_own_colour(rgb):
    seen = _rgb("/".join(f"{v:g}" for v in rgb))
    want = np.asarray(rgb) / max(rgb)
    np.testing.assert_allclose(seen / seen.max(), want, atol=2e-3)


def test_a_lights_colour_never_changes_its_brightness():
    lum = [spectra.spectral_to_xyz(Light((0, 0, 1), 2.0, c).distant_light().spectrum(
        spectra.wavelength_grid(380, 780, 81)), spectra.wavelength_grid(380, 780, 81))[1]
        for c in ("D65", "A", "3200K", "1/0.5/0.25")]
    np.testing.assert_allclose(lum, 2.0 * np.pi, rtol=2e-3)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")   # colour's Planck at 0 nm
@pytest.mark.parametrize("kelvin", [2700.0, 3200.0, 5000.0, 6500.0])
def test_a_temperature_has_colour_sciences_planckian_chromaticity(kelvin):
    colour = pytest.importorskip("colour")
    uv = colour.temperature.CCT_to_uv(np.array([kelvin, 0.0]), method="Planck 1900")
    want = np.reshape(colour.UCS_uv_to_xy(uv), (-1, 2))[0]   # CCT → chromaticity, Planckian locus
    wl = spectra.wavelength_grid(360, 830, 471)
    xyz = spectra.spectral_to_xyz(Light((0, 0, 1), 1.0, f"{kelvin:g}K").distant_light().spectrum(wl), wl)
    np.testing.assert_allclose(xyz[:2] / xyz.sum(), want, atol=5e-4)


def test_a_light_takes_direction_power_and_an_rgb_colour():
    light = parse_light("30,20,2,1/0.8/0.6")
    assert light.power == 2.0 and light.colour == "1/0.8/0.6" and "1/0.8/0.6" in light.label


@pytest.mark.parametrize("colour", ["0/0/0", "1/-1/0", "1/nan/0"])
def test_a_bad_rgb_colour_is_one_sentence(colour):
    with pytest.raises(SpecGenError, match="three non-negative numbers"):
        parse_light(f"30,20,1,{colour}")


def test_several_lights_and_an_ambient_term_add_up():
    a, b = parse_light("30,20,1,3200K"), parse_light("-60,10,0.5,0.2/0.4/1")
    both = parse_lighting(None, lights=(a, b), ambient=0.1).white_sphere_rgb()
    parts = [parse_lighting(None, lights=(a,)), parse_lighting(None, lights=(b,)),
             parse_lighting(None, ambient=0.1)]
    np.testing.assert_allclose(both, sum(p.white_sphere_rgb() for p in parts), rtol=1e-6)
