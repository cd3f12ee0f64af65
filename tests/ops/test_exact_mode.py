"""Exact mode (tabulated BRDF in OSL, direct light, SpecGen objects): what it honours, what it
warns about by name, which lights it drops. Headless bpy; only the last test renders."""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module  # noqa: E402  (after the bpy skip)
bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")
core_errors = addon_module("specgen_addon.common.errors")


def _light(sc, name, kind, energy, location=(0.0, 0.0, 5.0), collection=None, **props):
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    for k, v in props.items():
        setattr(data, k, v)
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    (collection or sc.collection).objects.link(obj)
    return obj


def _scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def test_unsupported_lights_and_emitters_are_named_in_warnings():
    sc = _scene()
    _light(sc, "Key area", "AREA", 100.0)
    _light(sc, "Rim spot", "SPOT", 100.0)
    _light(sc, "Soft sun", "SUN", 2.0, angle=math.radians(5))
    _light(sc, "No shadow", "POINT", 50.0, use_shadow=False)
    bpy.ops.mesh.primitive_cube_add()
    lamp = bpy.context.active_object
    lamp.name = "Lamp shade"
    mat = bpy.data.materials.new("glow")
    mat.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 3.0
    mat.node_tree.nodes["Principled BSDF"].inputs["Emission Color"].default_value = (1, 1, 1, 1)
    lamp.data.materials.append(mat)
    warnings: list[str] = []
    lights = render.scene_lights(sc, warnings.append)
    text = "\n".join(warnings)
    for name in ("Key area", "Rim spot", "Soft sun", "No shadow", "Lamp shade"):
        assert repr(name) in text, (name, text)
    assert [lt.kind for lt in lights.lights] == ["sun", "point"]


def test_the_weakest_lights_are_dropped_never_the_key_light():
    sc = _scene()
    for i in range(4):
        _light(sc, f"fill{i}", "POINT", 10.0 + i, location=(5.0, 0.0, 5.0))
    _light(sc, "far", "POINT", 500.0, location=(0.0, 0.0, 80.0))     # strong but far: weak here
    _light(sc, "key", "POINT", 1000.0, location=(0.0, -3.0, 3.0))    # created last
    warnings: list[str] = []
    lights = render.scene_lights(sc, warnings.append)
    assert len(lights.lights) == bake.MAX_LIGHTS
    kept = {tuple(round(c, 3) for c in lt.vector) for lt in lights.lights}
    assert (0.0, -3.0, 3.0) in kept
    assert "'far'" in warnings[-1] and "'fill0'" in warnings[-1] and "'key'" not in warnings[-1]


def test_lights_in_disabled_collections_are_skipped_and_exposure_and_temperature_honoured():
    sc = _scene()
    hidden = bpy.data.collections.new("hidden")
    excluded = bpy.data.collections.new("excluded")
    sc.collection.children.link(hidden)
    sc.collection.children.link(excluded)
    hidden.hide_render = True
    bpy.context.view_layer.layer_collection.children["excluded"].exclude = True
    _light(sc, "h", "SUN", 1.0, collection=hidden)
    _light(sc, "x", "SUN", 1.0, collection=excluded)
    _light(sc, "warm", "SUN", 2.0, exposure=1.0, use_temperature=True, temperature=3000.0)
    lights = render.scene_lights(sc, lambda m: None)
    assert len(lights.lights) == 1
    bb = np.asarray(bpy.data.lights["warm"].temperature_color[:3])
    np.testing.assert_allclose(lights.lights[0].rgb, 2.0 * 2.0 * bb, rtol=1e-6)


def _env_world(sc, rotation_z=0.0, scale=1.0, second_background=False):
    world = scene_mod.set_world_environment(sc, None)
    t = world.node_tree
    img = bpy.data.images.new("env", 16, 8, float_buffer=True)
    px = np.zeros((8, 16, 4), np.float32)
    px[..., 3] = 1
    px[:, 3, :3] = 5.0                                  # one bright column
    img.pixels.foreach_set(px.ravel())
    img.pack()                                          # Cycles reads the pixels from the file data
    env = t.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    mapping = t.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
    mapping.inputs["Scale"].default_value = (1.0, scale, 1.0)
    coords = t.nodes.new("ShaderNodeTexCoord")
    t.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    t.links.new(mapping.outputs[0], env.inputs["Vector"])
    bg = next(n for n in t.nodes if n.type == "BACKGROUND")
    t.links.new(env.outputs["Color"], bg.inputs["Color"])
    if second_background:
        bg2 = t.nodes.new("ShaderNodeBackground")
        add = t.nodes.new("ShaderNodeAddShader")
        t.links.new(bg.outputs[0], add.inputs[0])
        t.links.new(bg2.outputs[0], add.inputs[1])
        t.links.new(add.outputs[0], t.get_output_node("CYCLES").inputs["Surface"])
    return world


def test_world_mapping_rotation_is_honoured_and_unsupported_worlds_refused():
    sc = _scene()
    _env_world(sc, 0.0)
    base = render.world_environment(sc)
    assert base.shape == (8, 16, 3) and np.argmax(base[4, :, 0]) == 3
    _env_world(sc, math.pi / 2)                          # +90° about Z: a quarter turn, u − ¼
    turned = render.world_environment(sc)
    np.testing.assert_allclose(turned, np.roll(base, 4, axis=1), atol=1e-6)
    _env_world(sc, 0.3, scale=2.0)                       # stretched: not a rotation
    with pytest.raises(core_errors.SpecGenError, match="does more than rotate"):
        render.world_environment(sc)
    _env_world(sc, 0.0, second_background=True)
    with pytest.raises(core_errors.SpecGenError, match="several shaders"):
        render.world_environment(sc)


def test_rotated_map_agrees_with_what_cycles_shows_of_the_world(tmp_path):
    # Independent truth for the direction of the shift: Cycles' own background, seen by a
    # narrow camera looking along the azimuth where our rotated map has its bright column.
    sc = _scene()
    sc.render.engine = "CYCLES"
    sc.render.resolution_x = sc.render.resolution_y = 4
    sc.cycles.samples = 1
    _env_world(sc, math.pi / 2)
    turned = render.world_environment(sc)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.lens = 400.0
    sc.collection.objects.link(cam)
    sc.camera = cam

    def seen(phi: float) -> float:
        cam.rotation_euler = (math.pi / 2, 0.0, phi - math.pi / 2)   # looks along (cos φ, sin φ, 0)
        bpy.ops.render.render(write_still=False)
        path = tmp_path / "w.exr"
        sc.render.image_settings.file_format = "OPEN_EXR"
        bpy.data.images["Render Result"].save_render(str(path), scene=sc)
        import OpenEXR

        with OpenEXR.File(str(path)) as f:
            return float(np.asarray(next(iter(f.channels().values())).pixels)[..., 0].mean())

    col = int(np.argmax(turned[4, :, 0]))
    phi_bright = (0.5 - (col + 0.5) / turned.shape[1]) * 2 * np.pi      # u = −φ/2π + ½
    assert seen(phi_bright) > 4.0
    assert seen(phi_bright + np.pi / 2) < 0.5                            # the unrotated place
