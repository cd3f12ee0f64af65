"""The room's light from a chrome ball (Debevec 1998) and estimated from the diffuse ball itself,
on synthetic balls whose light is known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from specgen_addon.photo import light_estimate
from specgen_addon.photo import light_probe


def _lambert_ball(size: int, direction, ambient: float = 0.05, albedo: float = 0.6) -> np.ndarray:
    n, inside = light_probe.ball_normals(size)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    lum = albedo * (np.maximum(n @ d, 0.0) + ambient)
    return np.where(inside[..., None], lum[..., None] * np.ones(3), 0.0)


@pytest.mark.parametrize("direction", [(0.4, 0.48, 0.78), (-0.33, 0.49, 0.81), (0.1, 0.05, 0.99)])
def test_one_light_is_estimated_from_a_lambertian_ball(direction):
    est = light_estimate.estimate_lights(_lambert_ball(96, direction))
    assert len(est.directions) == 1
    truth = np.asarray(direction) / np.linalg.norm(direction)
    angle = np.degrees(np.arccos(np.clip(np.dot(est.directions[0], truth), -1, 1)))
    assert angle < 2.0 and est.residual_db > 35
    assert "estimated from the ball" in est.text()
    assert est.lighting().lights[0].direction == pytest.approx(est.directions[0])


def test_a_mirror_ball_unwraps_to_the_light_it_reflects():
    """A mirror ball whose only bright spot reflects a light from (0.4, 0.5, 0.77): the unwrapped map
    is brightest in that direction, and a clipped spot becomes a distant light there."""
    from specgen_addon.render.environment import _texel_directions

    size = 256
    n, inside = light_probe.ball_normals(size)
    light = np.array([0.4, 0.5, 0.77])
    light /= np.linalg.norm(light)
    r = light_probe.reflected(n)
    crop = np.where(inside[..., None], 0.02, 0.0) * np.ones(3)
    spot = inside & (r @ light > np.cos(np.radians(3)))
    crop[spot] = 1.0
    env, sat = light_probe.unwrap(crop, reflectance=0.5, saturated=spot)
    d = _texel_directions(*env.shape[:2], 0.0)
    peak = d.reshape(-1, 3)[np.argmax(env[..., 0])]
    assert np.degrees(np.arccos(peak @ light)) < 4.0
    assert env.max() == pytest.approx(2.0, rel=1e-3)           # divided by the reflectance
    sources = light_probe.clipped_sources(sat, env.shape[1])
    assert len(sources) == 1 and np.degrees(np.arccos(sources[0][0] @ light)) < 2.0


def _clipped_probe() -> tuple[light_probe.Probe, np.ndarray]:
    """A probe with one clipped source and the diffuse ball it lights (power 1 in photo units)."""
    direction = np.array([0.3, 0.4, 0.866])
    direction /= np.linalg.norm(direction)
    probe = light_probe.Probe(np.full((64, 128, 3), 0.01, np.float32), [(direction, 0.01)])
    return probe, _lambert_ball(96, direction, ambient=0.0, albedo=0.5) * 2.0   # power 2 × albedo 0.5 → 1


def test_a_clipped_sources_power_is_fitted_to_the_diffuse_ball():
    probe, photo = _clipped_probe()
    # the albedo is capped at 1: the brightest a light of power p can make the ball is p × cos
    powers = light_probe.fit_clipped_powers(probe, photo)
    assert powers[0] == pytest.approx(1.0, rel=0.05)


def test_a_bad_reflectance_is_refused():
    with pytest.raises(light_probe.ProbeError, match="reflectance must lie in"):
        light_probe.unwrap(np.zeros((16, 16, 3)), reflectance=1.5)


def test_the_fitted_power_is_reported_as_the_lighting_label_gives_it(tmp_path):
    probe, photo = _clipped_probe()
    lighting = light_probe.probe_lighting(probe, tmp_path / "probe.exr", photo)
    power = lighting.lights[0].power
    assert f"×{power:g}" in lighting.label
    assert f"fitted to the diffuse ball: ×{power:g} (1: the canonical key light)" in probe.notes[-1]


def _png(path, width: int, height: int, value: int = 0):
    from PIL import Image

    Image.fromarray(np.full((height, width, 3), value, np.uint8)).save(path)
    return path


def test_a_missing_chrome_ball_photo_is_named_as_missing(tmp_path):
    with pytest.raises(light_probe.ProbeError) as err:
        light_probe.read_probe(tmp_path / "nope.png")
    assert str(err.value) == f"{tmp_path / 'nope.png'}: chrome ball photo not found"


def test_a_chrome_ball_mask_of_the_wrong_size_is_not_called_a_ball_not_found(tmp_path):
    photo, mask = _png(tmp_path / "chrome.png", 96, 64), _png(tmp_path / "mask.png", 32, 32, 255)
    with pytest.raises(light_probe.ProbeError) as err:
        light_probe.read_probe(photo, mask=mask)
    message = str(err.value)
    assert "the mask is 32×32 pixels, the photo 96×64" in message
    assert "not found" not in message and "give its mask or circle" not in message


def test_a_chrome_ball_not_found_asks_for_its_mask_or_circle_once(tmp_path):
    not_found = r"^chrome ball not found: .*\(give its mask or circle\)$"
    with pytest.raises(light_probe.ProbeError, match=not_found):
        light_probe.read_probe(_png(tmp_path / "black.png", 64, 64))
    disc = np.zeros((64, 64, 3), np.uint8)                      # a bright square: found, not a circle
    disc[20:44, 10:54] = 255
    from PIL import Image
    Image.fromarray(disc).save(tmp_path / "square.png")
    with pytest.raises(light_probe.ProbeError) as err:
        light_probe.read_probe(tmp_path / "square.png")
    assert str(err.value).count("give") == 1, str(err.value)


def test_a_reflectance_of_zero_is_refused_not_replaced_by_the_default(tmp_path):
    from specgen_addon.photo.sphere_image import PhotoSource

    photo = Path(__file__).resolve().parents[2] / "examples" / "sphere.png"
    with pytest.raises(light_probe.ProbeError, match=r"reflectance must lie in \(0, 1\], got 0"):
        light_probe.lighting_from_probe(photo, PhotoSource(photo), tmp_path / "probe.exr",
                                        circle=(64.0, 64.0, 64.0), reflectance=0.0)
    assert not (tmp_path / "probe.exr").exists()
