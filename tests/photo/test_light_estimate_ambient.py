"""The estimated ambient is measured where no light reaches, so a material flatter than a Lambertian
is not mistaken for ambient light (synthetic balls whose light is known)."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.photo import light_estimate
from specgen_addon.photo.light_probe import ball_normals
from specgen_addon.photo.sphere_image import EXPOSURE


def _ball(size: int, direction, shading, ambient: float = 0.0) -> np.ndarray:
    """A grey ball (S, S, 3): ``shading(cos)`` where the light reaches, plus a uniform ``ambient``."""
    n, inside = ball_normals(size)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    cos = n @ d
    lum = np.where(cos > 0, shading(np.clip(cos, 0.0, 1.0)), 0.0) + ambient
    return np.where(inside[..., None], lum[..., None] * np.ones(3), 0.0)


def _photo_units(ambient: float) -> float:
    return ambient * EXPOSURE * light_estimate.ASSUMED_ALBEDO


def test_the_ambient_is_measured_on_the_balls_unlit_side():
    truth = 0.02
    est = light_estimate.estimate_lights(_ball(96, (0.4, 0.48, 0.78), lambda c: 0.5 * c, truth), ambient_from="unlit")
    assert est.ambient_seen
    assert _photo_units(est.ambient) == pytest.approx(truth, rel=0.05)
    assert "measured on the ball's unlit side" in est.text()


def test_a_material_flatter_than_lambertian_is_not_taken_for_ambient_light():
    """Lit part 0.1 + 0.4 cos (a rough ball's flat shading), dark beyond the terminator: a Lambertian
    with ambient would explain the 0.1 as ambient light; the unlit side shows there is none."""
    direction = (0.5, 0.5, 0.7)
    lambertian = light_estimate._fit  # the plain fit the estimate starts from, for comparison
    est = light_estimate.estimate_lights(_ball(96, direction, lambda c: 0.1 + 0.4 * c), ambient_from="unlit")
    assert _photo_units(est.ambient) < 0.01
    n, inside = ball_normals(96)
    d = np.asarray(direction) / np.linalg.norm(direction)
    lit = inside & (n @ d > 0)
    y = 0.1 + 0.4 * (n[lit] @ d)
    coef, _ = lambertian([np.ones_like(y), n[lit] @ d], y)
    assert coef[0] > 0.05                       # what the Lambertian alone would have called ambient
    truth = np.asarray(direction) / np.linalg.norm(direction)
    assert np.degrees(np.arccos(np.clip(np.dot(est.directions[0], truth), -1, 1))) < 8.0


def test_with_no_unlit_side_in_view_the_ambient_is_left_at_zero_and_the_run_says_so():
    est = light_estimate.estimate_lights(_ball(96, (0.1, 0.05, 0.99), lambda c: 0.5 * c, 0.03), ambient_from="unlit")
    assert not est.ambient_seen and est.ambient == 0.0
    assert len(est.directions) == 1
    assert "no unlit side" in est.text()


def test_by_default_the_ambient_is_the_lambertian_fits_and_an_unknown_source_is_refused():
    photo = _ball(96, (0.5, 0.5, 0.7), lambda c: 0.1 + 0.4 * c)
    fitted = light_estimate.estimate_lights(photo)
    assert fitted.ambient_seen is None and _photo_units(fitted.ambient) > 0.05
    assert "unlit side" not in fitted.text()
    with pytest.raises(light_estimate.LightingError, match="one of fit, unlit"):
        light_estimate.estimate_lights(photo, ambient_from="shadow")
