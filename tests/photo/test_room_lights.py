"""The room's light given by the user: distant lights by direction, power and colour, an ambient
term, a calibrated panorama; clear errors for a light without a direction and a panorama of the
wrong aspect (specgen_addon.photo.photo_lighting)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from specgen_addon.photo.photo_lighting import InputLighting, Light, LightingError, parse_light, parse_lighting


def test_azimuth_and_elevation_follow_the_camera_frame():
    np.testing.assert_allclose(parse_light("0,0").direction, (0, 0, 1), atol=1e-12)     # faces the camera
    np.testing.assert_allclose(parse_light("90,0").direction, (1, 0, 0), atol=1e-12)    # to the right
    np.testing.assert_allclose(parse_light("0,90").direction, (0, 1, 0), atol=1e-12)    # up
    light = parse_light("1,2,2,3,A", vector=True)
    np.testing.assert_allclose(light.direction, np.array([1, 2, 2]) / 3.0)
    assert light.power == 3 and light.colour == "A"


@pytest.mark.parametrize("text,vector", [("5", False), (",,2", False), ("a,b", False), ("1,2", True),
                                         ("0,0,0", True)])
def test_a_light_without_a_direction_is_refused_in_one_sentence(text, vector):
    with pytest.raises(LightingError, match="needs a direction"):
        parse_light(text, vector=vector)


def test_power_and_colour_are_checked():
    with pytest.raises(LightingError, match="power must be a positive number"):
        parse_light("0,0,-1")
    with pytest.raises(LightingError, match="light colour"):
        parse_light("0,0,1,nosuchlight")
    with pytest.raises(LightingError, match="outside 1000–40000 K"):
        parse_light("0,0,1,50K")


@pytest.mark.parametrize("text", ["27,29,1e300", "27,29,1.5e6", "27,29,inf"])
def test_an_absurd_power_is_refused_with_the_range_accepted(text):
    with pytest.raises(LightingError, match=r"power must be a positive number up to 1,000,000 "
                                            r"\(1: the canonical key light\)"):
        parse_light(text)
    assert parse_light("27,29,1e6").power == 1e6   # the bound itself is a light


@pytest.mark.parametrize("ambient", [1e30, 2e6, float("inf")])
def test_an_absurd_ambient_term_is_refused_with_the_range_accepted(ambient):
    with pytest.raises(LightingError, match="ambient term must be a non-negative number up to 1,000,000"):
        parse_lighting(None, lights=(parse_light("0,0"),), ambient=ambient)


@pytest.mark.parametrize("text,message", [
    ("30,95", "elevation must be a number of degrees in [-90, 90], got '30,95'"),
    ("30,-90.5", "elevation must be a number of degrees in [-90, 90], got '30,-90.5'"),
    ("400,20", "azimuth must be a number of degrees in [-360, 360], got '400,20'"),
    ("30,nan", "elevation must be a number of degrees in [-90, 90], got '30,nan'"),
    ("nan,30", "azimuth must be a number of degrees in [-360, 360], got 'nan,30'"),
])
def test_a_light_direction_out_of_range_is_refused_quoting_the_text(text, message):
    with pytest.raises(LightingError) as err:
        parse_light(text)
    assert message in str(err.value)


def test_a_light_vector_that_is_not_a_number_is_refused_quoting_the_text():
    with pytest.raises(LightingError, match="needs a direction: X,Y,Z.*got '1,nan,0'"):
        parse_light("1,nan,0", vector=True)


def test_the_range_ends_are_lights():
    assert parse_light("-360,-90").direction == pytest.approx((0.0, -1.0, 0.0), abs=1e-12)
    assert parse_light("360,90").direction == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)


@pytest.mark.parametrize("azimuth", [180, -180, 179.8, -179.8])
def test_a_light_straight_behind_is_labelled_180_degrees(azimuth):
    assert Light.from_angles(azimuth, 10).label.startswith("light az 180° el 10°")


def test_a_light_just_left_of_the_camera_is_labelled_0_not_minus_0_degrees():
    assert Light.from_angles(-0.3, -0.2).label.startswith("light az 0° el 0°")


def test_a_colour_temperature_is_plancks_law():
    colour = pytest.importorskip("colour")
    from specgen_addon.spectral.colour_tables import blackbody

    _, spd = blackbody(3200.0)
    sd = colour.sd_blackbody(3200.0, colour.SpectralShape(360, 830, 1))
    np.testing.assert_allclose(spd, sd.values / sd.values[200], rtol=1e-3)


def test_lights_alone_light_a_white_sphere_as_irradiance_over_pi():
    """One frontal light of power 1 (irradiance π): the white Lambertian photo's mean is the mean
    cosine over the disc (2/3) × the canonical exposure, in every channel (D65)."""
    light = parse_lighting(None, lights=(parse_light("0,0"),))
    assert light.env == "none" and light.environment() is None and "light az 0° el 0°" in light.label
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import sphere_geometry

    geo = sphere_geometry(64)
    expect = float(np.mean(geo.normals[geo.mask][:, 2])) * input_image.EXPOSURE
    np.testing.assert_allclose(light.white_sphere_rgb(64), expect, rtol=1e-3)
    brighter = parse_lighting(None, lights=(parse_light("0,0"),), ambient=0.5)
    np.testing.assert_allclose(brighter.white_sphere_rgb(64), expect + 0.5 * input_image.EXPOSURE, rtol=2e-2)


def test_two_lights_add():
    a, b = parse_light("-40,10"), parse_light("40,10,2")
    both = parse_lighting(None, lights=(a, b)).white_sphere_rgb(48)
    one = parse_lighting(None, lights=(a,)).white_sphere_rgb(48)
    two = parse_lighting(None, lights=(b,)).white_sphere_rgb(48)
    np.testing.assert_allclose(both, one + two, rtol=1e-9)
    assert parse_lighting(None, lights=(a, b)).scene(32).lights.__len__() == 2


def _equirect(path, w: int, h: int, value: float = 2.0) -> None:
    from specgen_addon.common.image_io import write_exr

    plane = np.full((h, w), value, np.float32)
    write_exr(path, {"R": plane, "G": plane, "B": plane})


def test_a_panorama_of_the_wrong_aspect_is_refused(tmp_path):
    _equirect(tmp_path / "square.exr", 32, 32)
    with pytest.raises(LightingError, match="twice as wide as it is high; this one is 32×32"):
        parse_lighting(str(tmp_path / "square.exr"))


def test_a_calibrated_panorama_keeps_its_power(tmp_path):
    _equirect(tmp_path / "room.exr", 64, 32, value=2.0)
    normalised = parse_lighting(str(tmp_path / "room.exr")).environment()
    calibrated = parse_lighting(str(tmp_path / "room.exr"), calibrated=True).environment()
    assert normalised.mean_luminance() == pytest.approx(1.0, rel=1e-3)
    assert calibrated.mean_luminance() == pytest.approx(2.0, rel=1e-3)
    assert "calibrated" in parse_lighting(str(tmp_path / "room.exr"), calibrated=True).label
    with pytest.raises(LightingError, match="only a panorama file can be calibrated"):
        InputLighting("forest", calibrated=True)


def test_lights_do_not_mix_with_the_canonical_studio():
    with pytest.raises(LightingError, match="canonical studio"):
        InputLighting("canonical", lights=(Light((0.0, 0.0, 1.0)),))
    with pytest.raises(LightingError, match="at least one light") as err:
        InputLighting("none")
    assert str(err.value) == "with no map, give at least one light or an ambient term to light the photo"
    assert math.isclose(Light.from_angles(0, 0).direction[2], 1.0)


@pytest.mark.parametrize("args,message", [
    (["--light", "5"], "a light needs a direction"),
    (["--light-vector", "0,0,0"], "a light needs a direction"),
    (["--circle", "1,2"], "--circle takes X,Y,R"),
])
def test_the_command_line_refuses_a_bad_light_or_circle_in_one_line(tmp_path, capsys, args, message):
    from conftest import REPO

    from specgen_addon.cli.app import main

    code = main(["infer", str(REPO / "examples" / "sphere.png"), "-o", str(tmp_path / "t.npz"), "--quiet", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "t.npz").exists()


def test_the_command_line_refuses_a_panorama_of_the_wrong_aspect(tmp_path, capsys):
    from conftest import REPO

    from specgen_addon.cli.app import main

    _equirect(tmp_path / "square.exr", 16, 16)
    code = main(["infer", str(REPO / "examples" / "sphere.png"), "-o", str(tmp_path / "t.npz"), "--quiet",
                 "--input-env", str(tmp_path / "square.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "twice as wide as it is high" in err[0], err


def test_a_light_value_with_a_minus_sign_is_attached_to_its_option():
    from specgen_addon.photo.photo_lighting import attach_signed_values

    argv = ["img.png", "--light", "-30,20", "--light-vector", "-.1,0.2,0.97", "--input-rotation", "-30",
            "--light=-5,5", "--light", "40,10", "--light"]
    assert attach_signed_values(argv) == ["img.png", "--light=-30,20", "--light-vector=-.1,0.2,0.97",
                                          "--input-rotation", "-30", "--light=-5,5", "--light", "40,10", "--light"]
    assert attach_signed_values(["--light", "--quiet"]) == ["--light", "--quiet"]   # argparse says what is missing
    argv = ["--white-patch", "-5,10,20,20", "--circle", "-10,20,30", "--probe-circle", "-.5,2,3"]
    assert attach_signed_values(argv) == ["--white-patch=-5,10,20,20", "--circle=-10,20,30",
                                          "--probe-circle=-.5,2,3"]


@pytest.mark.parametrize("args,message", [
    (["--white-patch", "-5,10,20,20"], "the white patch (-5.0, 10.0, 20.0, 20.0) does not lie in"),
    (["--circle", "-10,20,30"], "the circle (-10, 20, r 30) does not lie in"),
    (["--light-probe", "{photo}", "--probe-circle", "-10,20,30"],
     "chrome ball: {photo}: the circle (-10, 20, r 30) does not lie in"),
])
def test_a_negative_first_value_reaches_its_own_check_not_the_usage(tmp_path, capsys, args, message):
    from conftest import REPO

    from specgen_addon.cli.app import main

    photo = str(REPO / "examples" / "sphere.png")
    argv = [a.format(photo=photo) for a in args]
    code = main(["infer", photo, "-o", str(tmp_path / "t.npz"), "--quiet", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message.format(photo=photo) in err[0], err


def test_the_command_line_takes_a_light_from_the_left_written_with_a_space(tmp_path, capsys):
    # the first light parses (azimuth −30°); the second is refused by the light's own check, in one line
    from conftest import REPO

    from specgen_addon.cli.app import main

    code = main(["infer", str(REPO / "examples" / "sphere.png"), "-o", str(tmp_path / "t.npz"), "--quiet",
                 "--light", "-30,20", "--light-vector", "-0,0,0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "a light needs a direction" in err[0], err
