"""Example scenes for the full-scene spectral mode: an ordinary scene and a Cornell box.

Used by the figures (``scripts/make_fullscene_figures.py``), the benchmark (``bench/render.py``)
and the tests. A builder given a SpecGen material builds into the current (empty) file, as the
material must exist first; without one it starts from an empty file itself.
"""

from __future__ import annotations

import math
import os

import bpy

from .scene import add_sun


def _camera(sc, location, rotation, lens: float = 50.0) -> bpy.types.Object:
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    sc.collection.objects.link(cam)
    cam.location, cam.rotation_euler = location, rotation
    sc.camera = cam
    return cam


def principled(name: str, rgb, **inputs) -> bpy.types.Material:
    """A Principled BSDF material with base colour ``rgb`` and other inputs by name."""
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    for key, value in inputs.items():
        bsdf.inputs[key].default_value = value
    return mat


def studio_light(name: str) -> str:
    """Path of one of Blender's CC0 studio-light HDRIs (``courtyard``, ``forest`` ...)."""
    return os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), f"{name}.exr")


def _start(samples: int, size: tuple[int, int], reset: bool) -> bpy.types.Scene:
    if reset:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.render.resolution_x, sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.cycles.samples = samples
    sc.cycles.use_denoising = False
    sc.cycles.seed = 3
    return sc


def _sphere(name: str, radius: float, location, mat) -> bpy.types.Object:
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=48, ring_count=24)
    obj = bpy.context.active_object
    obj.name = name
    bpy.ops.object.shade_smooth()
    obj.data.materials.append(mat)
    return obj


def ordinary_scene(samples: int = 64, size: tuple[int, int] = (48, 32),
                   specgen_material: bpy.types.Material | None = None) -> bpy.types.Scene:
    """Floor (checker texture), three Principled spheres (red, metal, green with coat), an area
    light, a sun with an angle, an HDRI world through a rotated Mapping node plus a second
    Background node; with ``specgen_material``, a fourth sphere in front uses it."""
    sc = _start(samples, size, reset=specgen_material is None)
    bpy.ops.mesh.primitive_plane_add(size=12)
    floor = bpy.context.active_object
    floor.name = "Floor"
    checker = bpy.data.materials.new("Floor")
    t = checker.node_tree
    tex = t.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = 6.0
    tex.inputs["Color1"].default_value = (0.8, 0.75, 0.6, 1.0)
    tex.inputs["Color2"].default_value = (0.1, 0.2, 0.35, 1.0)
    t.links.new(tex.outputs["Color"], t.nodes["Principled BSDF"].inputs["Base Color"])
    floor.data.materials.append(checker)
    for x, name, rgb, extra in ((-1.6, "Red", (0.8, 0.1, 0.05), {"Roughness": 0.3}),
                                (0.0, "Metal", (0.9, 0.9, 0.9), {"Metallic": 1.0, "Roughness": 0.25}),
                                (1.6, "Green", (0.1, 0.5, 0.15), {"Coat Weight": 0.5})):
        _sphere(name, 0.7, (x, 0.0, 0.7), principled(name, rgb, **extra))
    if specgen_material is not None:
        _sphere("SpecGen", 0.55, (0.8, -1.6, 0.55), specgen_material)
    area = bpy.data.lights.new("Area", "AREA")
    area.energy, area.size, area.color = 150.0, 2.0, (1.0, 0.85, 0.7)
    area.exposure = 1.0                                   # × 2: exposure is honoured by Cycles
    obj = bpy.data.objects.new("Area", area)
    obj.location, obj.rotation_euler = (-3.0, -2.0, 4.0), (0.6, -0.5, 0.0)
    sc.collection.objects.link(obj)
    disabled = bpy.data.collections.new("Disabled lights")   # excluded: must not light anything
    sc.collection.children.link(disabled)
    off = bpy.data.objects.new("Disabled", bpy.data.lights.new("Disabled", "POINT"))
    off.data.energy, off.location = 5000.0, (0.0, -2.0, 2.0)
    disabled.objects.link(off)
    bpy.context.view_layer.layer_collection.children[disabled.name].exclude = True
    sun = add_sun(sc, (0.5, 0.7, 0.5), 2.0, color=(0.9, 0.95, 1.0))
    sun.data.angle = 0.1
    world = bpy.data.worlds.new("HDRI")
    sc.world = world
    world.cycles.sampling_method = "MANUAL"   # a small importance map: 'auto' costs ~5 s per sync
    world.cycles.sample_map_resolution = 128
    w = world.node_tree
    bg = w.nodes["Background"]
    env = w.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(studio_light("courtyard"), check_existing=True)
    mapping = w.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, 1.3)
    coords = w.nodes.new("ShaderNodeTexCoord")
    w.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    w.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    w.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 0.6
    bg2 = w.nodes.new("ShaderNodeBackground")              # a second Background, added
    bg2.inputs["Color"].default_value = (0.2, 0.3, 0.6, 1.0)
    bg2.inputs["Strength"].default_value = 0.3
    add = w.nodes.new("ShaderNodeAddShader")
    w.links.new(bg.outputs[0], add.inputs[0])
    w.links.new(bg2.outputs[0], add.inputs[1])
    w.links.new(add.outputs[0], w.nodes["World Output"].inputs["Surface"])
    _camera(sc, (0.0, -7.0, 3.0), (1.2, 0.0, 0.0))
    return sc


def cornell_box(specgen_material: bpy.types.Material, samples: int = 128,
                size: tuple[int, int] = (64, 64)) -> bpy.types.Scene:
    """A Cornell box (red left wall, green right wall, white floor, ceiling and back wall, an
    area light under the ceiling, black world) with a sphere of ``specgen_material`` in it."""
    sc = _start(samples, size, reset=False)
    white = principled("White wall", (0.75, 0.75, 0.75), Roughness=1.0)
    red = principled("Red wall", (0.65, 0.05, 0.05), Roughness=1.0)
    green = principled("Green wall", (0.12, 0.45, 0.10), Roughness=1.0)
    for name, loc, rot, mat in (("Floor", (0, 0, 0), (0, 0, 0), white),
                                ("Ceiling", (0, 0, 2), (math.pi, 0, 0), white),
                                ("Back", (0, 1, 1), (math.pi / 2, 0, 0), white),
                                ("Left", (-1, 0, 1), (0, math.pi / 2, 0), red),
                                ("Right", (1, 0, 1), (0, -math.pi / 2, 0), green)):
        bpy.ops.mesh.primitive_plane_add(size=2, location=loc, rotation=rot)
        bpy.context.active_object.name = name
        bpy.context.active_object.data.materials.append(mat)
    light = bpy.data.lights.new("Ceiling light", "AREA")
    light.energy, light.size = 25.0, 0.5
    obj = bpy.data.objects.new("Ceiling light", light)
    obj.location = (0, 0, 1.98)
    sc.collection.objects.link(obj)
    _sphere("SpecGen", 0.45, (0.0, 0.1, 0.45), specgen_material)
    world = bpy.data.worlds.new("Black")
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sc.world = world
    sc.cycles.max_bounces = 8
    _camera(sc, (0.0, -3.1, 1.0), (math.pi / 2, 0.0, 0.0), lens=35.0)
    return sc
