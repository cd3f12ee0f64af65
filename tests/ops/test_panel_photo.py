"""The panel's photo options, headless with the bpy module: the same core objects as the command
line's options (one validator), "lit like this scene" read from the scene's world and lights,
errors in one sentence, and Generate reporting the lighting and the circle it used."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module

from specgen_addon.cli.photo_args import add_photo_arguments, input_lighting_from_args, photo_source_from_args

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "sphere.png"
photo_inputs = addon_module("ops.photo_inputs")
pytestmark = pytest.mark.blender


def _cli(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_photo_arguments(parser)
    return parser.parse_args(list(argv))


@pytest.fixture
def panel(blank_scene, tmp_path):
    """The add-on registered on an empty scene; its photo settings and an output folder."""
    PKG.register()
    try:
        s = blank_scene.specgen
        s.output_dir = str(tmp_path / "out")
        yield blank_scene, s, s.photo
    finally:
        PKG.unregister()


def _lighting(scene, photo, tmp_path, image=None):
    job = photo_inputs.lighting_job(photo, scene, str(tmp_path), "ball", True)
    return job(image)


TILTED = (math.radians(70), 0.0, math.radians(20))   #: a camera looking down a little, turned


def _camera(scene, rotation=TILTED):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = (3.0, -8.0, 2.0)
    cam.rotation_euler = rotation
    scene.camera = cam
    bpy.context.view_layer.update()
    return cam


def _light(scene, kind: str, name: str, energy: float, direction=None, location=(0.0, 0.0, 0.0)):
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    obj.location = location
    if direction is not None:   # the light's +Z towards ``direction`` (it shines along −Z)
        from mathutils import Vector

        obj.rotation_euler = Vector(direction).to_track_quat("Z", "Y").to_euler()
    bpy.context.view_layer.update()
    return obj


def test_the_panels_light_list_is_the_clis_light(panel, tmp_path):
    scene, _s, photo = panel
    photo.lighting = "LIGHTS"
    for az, el, power, colour in ((30, 20, 2.0, "D65"), (-60, 45, 0.5, "3200K")):
        light = photo.lights.add()
        light.azimuth, light.elevation, light.power, light.colour = math.radians(az), math.radians(el), power, colour
    photo.ambient = 0.1
    lighting, notes = _lighting(scene, photo, tmp_path)
    cli = input_lighting_from_args(_cli("--light", "30,20,2", "--light=-60,45,0.5,3200K", "--ambient", "0.1"))
    assert lighting.label == cli.label and lighting.env == cli.env and notes == []
    for a, b in zip(lighting.lights, cli.lights):
        np.testing.assert_allclose(a.direction, b.direction, atol=1e-6)


def test_the_panels_photo_source_is_the_clis(panel):
    _, _s, photo = panel
    photo.encoding, photo.white_level = "linear", 0.5
    ball = photo.sphere
    ball.mode, ball.x, ball.y, ball.radius = "CIRCLE", 64.0, 60.0, 50.0
    ours = photo_inputs.photo_source(photo, str(EXAMPLE))
    cli = photo_source_from_args(_cli("--linear", "--white-level", "0.5", "--circle", "64,60,50"), EXAMPLE)
    assert ours == cli


def test_the_panels_white_patch_is_the_clis_balanced_to_the_same_light(panel, tmp_path):
    scene, _s, photo = panel
    photo.use_white_patch, photo.white_patch = True, (10.0, 12.0, 20.0, 16.0)
    photo.lighting = "LIGHTS"
    light = photo.lights.add()
    light.azimuth, light.elevation, light.power, light.colour = math.radians(30), math.radians(20), 2.0, "3200K"
    ours = photo_inputs.photo_source(photo, str(EXAMPLE))
    args = _cli("--white-patch", "10,12,20,16", "--light", "30,20,2,3200K")
    assert ours == photo_source_from_args(args, EXAMPLE)          # as read, before the light is known
    lighting, _ = _lighting(scene, photo, tmp_path, ours)
    assert photo_inputs.balances_to_the_light(photo)
    cli_lighting = input_lighting_from_args(args)
    balanced = photo_inputs.balanced_to_the_light(ours, lighting)
    cli = photo_source_from_args(args, EXAMPLE, cli_lighting.white_sphere_rgb())
    assert np.allclose(balanced.white_target, cli.white_target, rtol=1e-6)   # degrees ↔ radians
    assert not np.allclose(balanced.white_target, balanced.white_target[1])    # a warm light: not grey
    photo.lighting = "ESTIMATE"                                   # photographed alike: kept neutral
    assert not photo_inputs.balances_to_the_light(photo)


def test_lit_like_this_scene_with_a_sun_is_the_clis_light(panel, tmp_path):
    """A sun of strength π·P seen from the camera at azimuth A, elevation E is ``--light A,E,P``."""
    scene, _s, photo = panel
    cam = _camera(scene)
    az, el, power = 25.0, 35.0, 1.5
    cli = input_lighting_from_args(_cli("--light", f"{az},{el},{power}"))
    towards = np.array(cam.matrix_world.to_3x3().normalized()) @ np.asarray(cli.lights[0].direction)
    _light(scene, "SUN", "Sun", power * math.pi, direction=towards)
    photo.lighting = "SCENE"
    lighting, notes = _lighting(scene, photo, tmp_path)
    assert lighting.label == cli.label and lighting.env == cli.env
    np.testing.assert_allclose(lighting.lights[0].direction, cli.lights[0].direction, atol=1e-5)
    assert lighting.lights[0].power == pytest.approx(power, rel=1e-5)
    assert not [n for n in notes if n.startswith("warning")]


def test_lit_like_this_scene_takes_the_worlds_panorama_its_rotation_and_strength(panel, tmp_path):
    """A front camera (the photo lighting's own frame) and a Mapping node turned θ about Z light
    the ball as the panorama file with rotation θ and the Background strength as exposure."""
    from specgen_addon.photo.photo_lighting import InputLighting
    from specgen_addon.render.environment_maps import env_path

    hdri = env_path("forest")
    scene, _s, photo = panel
    _camera(scene, rotation=(math.pi / 2, 0.0, 0.0))
    world = bpy.data.worlds.new("World")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(str(hdri))
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(40.0))
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(nodes.new("ShaderNodeTexCoord").outputs["Generated"], mapping.inputs["Vector"])
    background = nodes["Background"]
    background.inputs["Strength"].default_value = 2.0
    links.new(tex.outputs["Color"], background.inputs["Color"])
    photo.lighting = "SCENE"
    lighting, _notes = _lighting(scene, photo, tmp_path)
    assert lighting.calibrated and lighting.exposure == 2.0 and Path(lighting.env).is_file()
    want = InputLighting(str(hdri), rotation_deg=40.0, exposure=2.0, calibrated=True)
    np.testing.assert_allclose(lighting.white_sphere_rgb(), want.white_sphere_rgb(), rtol=0.03)
    other = InputLighting(str(hdri), rotation_deg=220.0, exposure=2.0, calibrated=True)
    assert np.abs(other.white_sphere_rgb() - want.white_sphere_rgb()).max() > \
        3 * np.abs(lighting.white_sphere_rgb() - want.white_sphere_rgb()).max()   # the check can fail


def test_what_the_scene_cannot_give_is_named_in_the_warning(panel, tmp_path):
    scene, _s, photo = panel
    _camera(scene)
    _light(scene, "SUN", "Sun", 3.0, direction=(0.3, -1.0, 1.0))
    _light(scene, "AREA", "Softbox", 100.0, location=(2.0, -2.0, 3.0))
    spot = _light(scene, "SPOT", "Spot", 500.0, direction=(0.0, 0.0, 1.0), location=(0.0, 0.0, 10.0))
    spot.data.spot_size = math.radians(30)
    world = bpy.data.worlds.new("World")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    sky = world.node_tree.nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    photo.lighting = "SCENE"
    lighting, notes = _lighting(scene, photo, tmp_path)
    warning = " ".join(n for n in notes if n.startswith("warning"))
    assert "area light 'Softbox'" in warning and "procedural 'Sky Texture'" in warning
    assert "cone of spot light 'Spot'" in warning
    assert len(lighting.lights) == 2 and not lighting.has_map   # the sun and the spot taken as a point


def test_lit_like_this_scene_takes_only_lights_that_render(panel, tmp_path):
    """A light disabled in renders, in a collection disabled in renders or excluded from the view
    layer, lights nothing in the render, so it lights nothing in the photo's lighting either."""
    scene, _s, photo = panel
    _camera(scene)
    _light(scene, "SUN", "Key", 3.0, direction=(0.3, -1.0, 1.0))
    _light(scene, "SUN", "Off", 3.0, direction=(-1.0, -1.0, 0.2)).hide_render = True
    for name, how in (("Render off", "hide_render"), ("Excluded", "exclude")):
        coll = bpy.data.collections.new(name)
        scene.collection.children.link(coll)
        sun = _light(scene, "SUN", f"Sun in {name}", 3.0, direction=(-1.0, 0.5, 0.5))
        scene.collection.objects.unlink(sun)
        coll.objects.link(sun)
        if how == "hide_render":
            coll.hide_render = True
        else:
            bpy.context.view_layer.layer_collection.children[name].exclude = True
    photo.lighting = "SCENE"
    lighting, _notes = _lighting(scene, photo, tmp_path)
    assert len(lighting.lights) == 1                              # the key light alone


def _world_image(scene, path: Path) -> None:
    """A world whose Background colour is the image file ``path`` (an Environment Texture)."""
    world = bpy.data.worlds.new("World")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    tex = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(str(path))
    world.node_tree.links.new(tex.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])


def test_lit_like_this_scene_names_a_world_image_that_is_not_a_panorama(panel, tmp_path):
    from specgen_addon.common.image_io import write_exr

    scene, _s, photo = panel
    _camera(scene)
    _light(scene, "SUN", "Sun", 3.0, direction=(0.3, -1.0, 1.0))
    _world_image(scene, write_exr(tmp_path / "square.exr", {c: np.ones((16, 16), np.float32) for c in "RGB"}))
    photo.lighting = "SCENE"
    lighting, notes = _lighting(scene, photo, tmp_path)
    warning = " ".join(n for n in notes if n.startswith("warning"))
    assert "square.exr' (16×16" in warning and "twice as wide" in warning, warning
    assert not lighting.has_map and len(lighting.lights) == 1


def test_a_note_on_the_worlds_pixels_is_in_the_runs_report_not_a_python_warning(panel, tmp_path, recwarn):
    from specgen_addon.common.image_io import write_exr

    scene, _s, photo = panel
    _camera(scene)
    pano = np.full((16, 32), 0.5, np.float32)
    pano[3, 4] = -1.0                                             # a negative texel: clamped, with a note
    _world_image(scene, write_exr(tmp_path / "pano.exr", {c: pano for c in "RGB"}))
    photo.lighting = "SCENE"
    _taken, notes = _lighting(scene, photo, tmp_path)
    assert any(n.startswith("world: ") and "negative" in n for n in notes), notes
    assert not [w for w in recwarn if "negative" in str(w.message)]


BAD = {
    "a light list left empty": (lambda p: setattr(p, "lighting", "LIGHTS"), "at least one light"),
    "a light of power 0": (lambda p: (setattr(p, "lighting", "LIGHTS"), setattr(p.lights.add(), "power", 0.0)),
                           "power must be a positive number"),
    "an unknown light colour": (lambda p: (setattr(p, "lighting", "LIGHTS"), setattr(p.lights.add(), "colour", "pink")),
                                "unknown illuminant"),
    "no chrome ball photo": (lambda p: setattr(p, "lighting", "PROBE"), "choose a chrome ball photo"),
    "no panorama file": (lambda p: (setattr(p, "lighting", "PANORAMA"), setattr(p, "input_env", "FILE")),
                         "choose a panorama file"),
    "a scene without a camera": (lambda p: setattr(p, "lighting", "SCENE"), "needs an active camera"),
    "a circle of radius 0": (lambda p: setattr(p.sphere, "mode", "CIRCLE"), "radius above 0"),
    "a chrome ball not found": (lambda p: (setattr(p, "lighting", "PROBE"), setattr(p, "probe_path", str(EXAMPLE.with_name("missing.png")))),
                                "not found"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_wrong_photo_setting_is_refused_in_one_sentence_before_any_work(panel, case, tmp_path):
    _scene, s, photo = panel
    s.image_path = str(EXAMPLE)
    setup, needle = BAD[case]
    setup(photo)
    with pytest.raises(RuntimeError) as info:
        bpy.ops.specgen.generate_brdf()
    text = str(info.value)
    assert needle in text and "Traceback" not in text, text
    assert len([line for line in text.splitlines() if line.strip()]) == 1, text
    assert not (tmp_path / "out").exists()


def test_a_panorama_of_the_wrong_aspect_is_refused_in_one_sentence(panel, tmp_path):
    from specgen_addon.common.image_io import write_exr

    _scene, s, photo = panel
    square = tmp_path / "square.exr"
    write_exr(square, {c: np.ones((16, 16), np.float32) for c in "RGB"})
    s.image_path = str(EXAMPLE)
    photo.lighting, photo.input_env, photo.input_env_file = "PANORAMA", "FILE", str(square)
    with pytest.raises(RuntimeError, match="twice as wide"):
        bpy.ops.specgen.generate_brdf()


def test_a_calibrated_tick_left_from_a_file_does_not_block_a_bundled_panorama(panel, tmp_path):
    """Calibrated is drawn for a panorama file only; ticked there, then a bundled map chosen (the
    tick now hidden), the map is used as a bundled map is, not refused for the hidden tick."""
    scene, _s, photo = panel
    photo.lighting, photo.input_env, photo.calibrated = "PANORAMA", "FILE", True
    photo.input_env = "forest"
    lighting, _notes = _lighting(scene, photo, tmp_path)
    assert lighting.env == "forest" and not lighting.calibrated


@pytest.mark.slow
def test_generate_under_a_given_light_reports_the_lighting_and_the_circle(panel, tmp_path):
    from specgen_addon.model import DEFAULT_WEIGHTS

    if not Path(DEFAULT_WEIGHTS).is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    _scene, s, photo = panel
    s.image_path, s.bands, s.refine = str(EXAMPLE), 4, False
    photo.lighting = "LIGHTS"
    light = photo.lights.add()
    light.azimuth, light.elevation, light.power = math.radians(30), math.radians(20), 2.0
    photo.circle_preview = True
    assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
    mat = s.material
    want = input_lighting_from_args(_cli("--light", "30,20,2")).label
    assert mat is not None and mat["specgen_lighting"] == want
    assert photo.report.splitlines()[0] == f"photo lighting: {want}"
    assert "sphere: centre" in photo.report and "sphere: centre" in mat["specgen_sphere"]
    assert (tmp_path / "out" / f"{mat['specgen_stem']}_circle.png").is_file()


@pytest.mark.slow
def test_generate_lit_like_this_scene_uses_the_scenes_sun(panel, tmp_path):
    from specgen_addon.model import DEFAULT_WEIGHTS

    if not Path(DEFAULT_WEIGHTS).is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    scene, s, photo = panel
    cam = _camera(scene)
    cli = input_lighting_from_args(_cli("--light", "30,40,1"))
    towards = np.array(cam.matrix_world.to_3x3().normalized()) @ np.asarray(cli.lights[0].direction)
    _light(scene, "SUN", "Sun", math.pi, direction=towards)
    s.image_path, s.bands, s.refine = str(EXAMPLE), 4, False
    photo.lighting = "SCENE"
    assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
    assert s.material["specgen_lighting"] == cli.label


def test_the_photo_section_draws_for_every_lighting_source(panel):
    """Each source's settings exist under the names the Photo section draws (no UI needed)."""
    _scene, _s, photo = panel
    panel_mod = addon_module("ops.photo_panel")

    class Recorder:
        """A stand-in layout that records every property drawn."""

        def __init__(self):
            self.props = []

        def __getattr__(self, name):
            return lambda *a, **k: self

        def prop(self, data, name, **kw):
            assert hasattr(data, name), name
            self.props.append(name)

        def panel(self, *a, **k):
            return self, self

    for kind in ("CANONICAL", "LIGHTS", "PROBE", "PANORAMA", "ESTIMATE", "SCENE"):
        photo.lighting = kind
        layout = Recorder()
        panel_mod.draw_photo(layout, photo)
        assert "lighting" in layout.props


def _ball_exr(path: Path, rgb_of_normal) -> Path:
    """A ball filling a 96² EXR (black around), each pixel ``rgb_of_normal(n)`` (n: camera frame)."""
    from specgen_addon.common.image_io import write_exr
    from specgen_addon.photo.light_probe import ball_normals

    n, inside = ball_normals(96)
    img = np.zeros((96, 96, 3), np.float32)
    img[inside] = rgb_of_normal(n[inside])
    write_exr(path, {c: img[..., i] for i, c in enumerate("RGB")})
    return path


def test_estimate_and_chrome_ball_give_the_clis_lighting(panel, tmp_path):
    from specgen_addon.cli.photo_args import estimated_lighting, probe_lighting_from_args

    scene, _s, photo = panel
    light = np.array([0.4, 0.5, 0.77]) / np.linalg.norm([0.4, 0.5, 0.77])
    ball = _ball_exr(tmp_path / "ball.exr", lambda n: (0.05 + 0.5 * np.maximum(n @ light, 0))[:, None] * [1, 1, 1])
    chrome = _ball_exr(tmp_path / "chrome.exr", lambda n: np.full((len(n), 3), 0.3))
    source = photo_inputs.photo_source(photo, str(ball))

    photo.lighting = "ESTIMATE"
    ours, notes = _lighting(scene, photo, tmp_path, source)
    assert ours == estimated_lighting(source)
    assert notes[0].startswith("lighting estimated from the ball")

    photo.lighting, photo.probe_path = "PROBE", str(chrome)
    ours, notes = _lighting(scene, photo, tmp_path, source)
    args = _cli("--light-probe", str(chrome))
    args.overwrite = False                                   # an option of infer itself
    cli = probe_lighting_from_args(args, source, tmp_path / "cli_probe.exr")
    assert Path(ours.env).name == "ball_probe.exr" and ours.calibrated
    np.testing.assert_allclose(ours.white_sphere_rgb(), cli.white_sphere_rgb(), rtol=1e-6)
    assert any(n.startswith("chrome ball: chrome ball sphere: centre") for n in notes)


@pytest.mark.parametrize("encoding", ["auto", "linear"])
def test_an_edited_image_is_decoded_by_the_encoding_as_its_file_is(panel, encoding):
    """One rule for an image datablock: its pixels, edited or not, decode as the panel's Encoding
    says, whatever Color Space the image is set to in Blender."""
    from specgen_addon.photo.read import read_photo

    _scene, s, photo = panel
    operators = addon_module("ops.operators")
    img = bpy.data.images.load(str(EXAMPLE))
    img.colorspace_settings.name = "Non-Color"
    s.image, photo.encoding = img, encoding
    assert operators._image_input(s) == str(EXAMPLE)           # untouched: the file, decoded by the core
    img.pixels[0] = img.pixels[0]                                # edited: read from Blender's pixels
    assert img.is_dirty
    edited = operators._image_input(s)
    np.testing.assert_allclose(edited, read_photo(EXAMPLE, encoding=encoding).rgb[..., :3], atol=1e-5)


def test_an_image_not_saved_to_a_file_asks_to_be_saved_for_the_file_options(panel, tmp_path):
    _scene, s, photo = panel
    s.image = bpy.data.images.new("painted", 64, 64)
    photo.sphere.mode, photo.sphere.radius = "CIRCLE", 20.0
    with pytest.raises(RuntimeError, match="the sphere's circle or mask needs the photo as a file: save"):
        bpy.ops.specgen.generate_brdf()
    assert not (tmp_path / "out").exists()
