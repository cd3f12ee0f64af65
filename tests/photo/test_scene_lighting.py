"""'Lit like this scene' without Blender: frames, units and colours of a scene's lights and world as
a photo's lighting (specgen_addon.photo.scene_lighting)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from specgen_addon.photo.photo_lighting import InputLighting, LightingError, parse_light, parse_lighting
from specgen_addon.photo.scene_lighting import (
    SceneLighting,
    euler_xyz,
    inside_cone,
    light_colour,
    mapping_matrix,
    point_light,
    rotation_part,
    sun_light,
    to_camera_frame,
    world_in_camera_frame,
)

#: Blender's front view: a camera at −Y looking along +Y, +Z up (the renderer's own frame).
FRONT = euler_xyz((math.pi / 2, 0.0, 0.0))


def _sun_towards(direction) -> np.ndarray:
    """A sun rotation whose local +Z (the direction towards it) is ``direction`` (world)."""
    z = np.asarray(direction, float) / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], -1)


def test_a_camera_frame_is_the_cameras_local_frame():
    np.testing.assert_allclose(to_camera_frame(np.eye(3), (0, 0, 1)), (0, 0, 1))   # behind the camera
    np.testing.assert_allclose(to_camera_frame(FRONT, (0, 0, 1)), (0, 1, 0), atol=1e-12)    # world up is up
    np.testing.assert_allclose(to_camera_frame(FRONT, (0, -1, 0)), (0, 0, 1), atol=1e-12)   # towards the camera
    np.testing.assert_allclose(to_camera_frame(FRONT, (1, 0, 0)), (1, 0, 0), atol=1e-12)    # right is right
    scaled = np.diag([2.0, 3.0, 0.5]) @ np.eye(3)
    np.testing.assert_allclose(rotation_part(scaled), np.eye(3))


def test_a_sun_is_the_cli_light_of_the_same_direction_and_power():
    az, el, power = 30.0, 20.0, 2.0
    cli = parse_light(f"{az},{el},{power}")
    towards = FRONT @ np.asarray(cli.direction)            # the same direction in Blender's world
    sun = sun_light(FRONT, _sun_towards(towards), strength_w_m2=power * math.pi, rgb=(1, 1, 1))
    np.testing.assert_allclose(sun.direction, cli.direction, atol=1e-9)
    assert sun.power == pytest.approx(power) and sun.colour == "D65"
    assert SceneLighting(lights=[sun]).lighting() == parse_lighting(None, lights=(cli,))


def test_a_far_point_light_is_a_distant_light_of_its_irradiance():
    p, d = 1000.0, 5.0
    light = point_light(np.eye(3), (0, 0, d), (0, 0, 0), p, (1, 1, 1))
    np.testing.assert_allclose(light.direction, (0, 0, 1))
    assert light.power == pytest.approx(p / (4 * math.pi * d * d) / math.pi)   # E / π
    with pytest.raises(LightingError, match="distance 0"):
        point_light(np.eye(3), (1, 2, 3), (1, 2, 3), p, (1, 1, 1))


def test_a_spot_counts_only_when_the_ball_is_inside_its_cone():
    down = np.eye(3)                                                 # shines along −Z
    assert inside_cone(down, (0, 0, 5), (0, 0, 0), math.radians(45))
    assert not inside_cone(down, (0, 0, 5), (5, 0, 0), math.radians(45))


@pytest.mark.parametrize("kelvin", [1900, 3200, 5000, 10000])
def test_a_black_body_colour_comes_back_as_its_temperature(kelvin):
    from specgen_addon.photo.photo_lighting import Light

    rgb = Light((0, 0, 1), 1.0, f"{kelvin}K").distant_light().rgb() / math.pi
    colour = light_colour(2.0 * rgb)
    assert colour.name.endswith("K") and float(colour.name[:-1]) == pytest.approx(kelvin, rel=0.003)
    assert colour.luminance == pytest.approx(2.0, rel=1e-3) and not colour.changed


def test_white_is_d65_and_a_saturated_colour_is_reported_as_changed():
    assert light_colour((0.5, 0.5, 0.5)).name == "D65"
    assert light_colour((1.0, 0.0, 0.0)).changed
    with pytest.raises(LightingError, match="no brightness"):
        light_colour((0.0, 0.0, 0.0))


def test_the_texture_mapping_is_the_inverse_of_the_point_mapping():
    rot, scale = (0.3, -0.2, 1.1), (1.0, 2.0, 0.5)
    np.testing.assert_allclose(mapping_matrix("TEXTURE", rot, scale) @ mapping_matrix("POINT", rot, scale),
                               np.eye(3), atol=1e-12)
    with pytest.raises(LightingError, match="zero scale"):
        mapping_matrix("POINT", rot, (1, 0, 1))


def _test_map(h: int = 16) -> np.ndarray:
    rng = np.random.default_rng(3)
    return rng.random((h, 2 * h, 3)).astype(np.float32)


def test_a_front_camera_sees_the_world_as_the_renderer_does():
    rgb = _test_map()
    np.testing.assert_allclose(world_in_camera_frame(rgb, FRONT, width=32), rgb, atol=1e-5)


def test_a_mapping_turn_about_z_is_the_panoramas_rotation():
    """Blender's Mapping Z rotation θ is the photo lighting's rotation θ (--input-rotation)."""
    from specgen_addon.render.environment import Environment, _texel_directions

    rgb, w = _test_map(), 32
    theta = 2 * math.pi * 3 / w                             # three texels: no interpolation
    turned = world_in_camera_frame(rgb, FRONT, mapping_matrix("POINT", (0, 0, theta)), width=w)
    want = Environment(rgb, rotation_rad=theta).radiance_rgb(_texel_directions(w // 2, w, 0.0))
    np.testing.assert_allclose(turned, want, atol=1e-5)


def test_a_camera_looking_up_sees_the_sky_in_front():
    """Tilted cameras move the whole panorama, not only its azimuth: the zenith lands ahead."""
    rgb = np.zeros((16, 32, 3), np.float32)
    rgb[:2] = 1.0                                          # a bright sky cap
    cam = world_in_camera_frame(rgb, euler_xyz((math.pi, 0, 0)), width=32)   # a camera looking up (+Z)
    from specgen_addon.render.environment import _bilinear_equirect

    ahead = _bilinear_equirect(cam, np.array([[0.0, 0.0, -1.0]]), 0.0)[0]   # straight ahead of the camera
    behind = _bilinear_equirect(cam, np.array([[0.0, 0.0, 1.0]]), 0.0)[0]
    assert ahead.min() > 0.9 and behind.max() < 0.1


def test_the_world_becomes_a_calibrated_panorama_with_its_strength(tmp_path):
    pano = np.full((8, 16, 3), 0.25, np.float32)
    lighting = SceneLighting(panorama=pano, strength=2.0).lighting(tmp_path / "scene_env.exr")
    assert lighting.calibrated and lighting.exposure == 2.0 and lighting.is_file and not lighting.key_light
    env = lighting.environment()
    assert float(env.rgb.mean()) == pytest.approx(0.5, rel=1e-4)


def test_a_scene_without_light_is_refused_naming_what_was_left_out():
    scene = SceneLighting(not_taken=["area light 'Panel'", "the world's procedural Sky Texture"])
    with pytest.raises(LightingError, match="no light to take.*area light 'Panel'"):
        scene.lighting()
    assert "area light 'Panel'" in scene.warning()
    assert SceneLighting().warning() is None


def test_a_panorama_rewritten_in_place_is_read_again(tmp_path):
    """The photo lighting's caches follow a map file written anew under the same name (a
    long-running Blender session generating twice)."""
    from specgen_addon.common.image_io import write_exr

    path = tmp_path / "room.exr"
    light = InputLighting(str(path), calibrated=True)
    for level in (0.5, 2.0):
        write_exr(path, {c: np.full((8, 16), level, np.float32) for c in "RGB"}, overwrite=True)
        assert light.white_sphere_rgb().mean() == pytest.approx(level * light.image_exposure, rel=5e-3)


def test_a_lights_exposure_and_temperature_reach_its_power_and_colour():
    from specgen_addon.photo.scene_lighting import emitted_rgb

    np.testing.assert_allclose(emitted_rgb((1, 1, 1), exposure=1.0), (2, 2, 2))
    colour = light_colour(emitted_rgb((1, 1, 1), temperature_k=3200))
    assert float(colour.name[:-1]) == pytest.approx(3200, rel=0.003) and colour.luminance == pytest.approx(1.0)
