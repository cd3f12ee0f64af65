"""Build the example scene: one object in front of an orthographic camera, lit by a sun and/or an
environment, in the reference renderer's conventions.

The reference renderer (:mod:`specgen_addon.render`) works in a frame with +x right, +y up, +z
towards the camera; Blender's world is z-up, and the two map as ``(x, y, z) → (x, −z, y)``: the
camera sits on −Y looking along +Y (Blender's front view) and frames the unit sphere exactly
(orthographic, ``ortho_scale = 2``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

from specgen_addon.common.errors import SpecGenError

MESHES = ("sphere", "suzanne")


def reference_to_blender(v) -> Vector:
    """A vector of the reference renderer's frame in Blender's world frame."""
    x, y, z = (float(c) for c in v)
    return Vector((x, -z, y))


def clear_scene(scene: bpy.types.Scene) -> None:
    """Remove every object from ``scene`` (and orphaned meshes/lights/cameras it used)."""
    for obj in list(scene.objects):
        data = obj.data
        bpy.data.objects.remove(obj, do_unlink=True)
        if data is not None and data.users == 0:
            for coll in (bpy.data.meshes, bpy.data.lights, bpy.data.cameras):
                if data.name in coll and coll[data.name] == data:
                    coll.remove(data)
                    break


def add_camera(scene: bpy.types.Scene, scale: float = 2.0) -> bpy.types.Object:
    """Orthographic camera at −Y looking +Y (up +Z), framing a ``scale``-wide square."""
    cam = bpy.data.cameras.new("SpecGen camera")
    cam.type = "ORTHO"
    cam.ortho_scale = scale
    cam.clip_start = 0.01
    cam.clip_end = 100.0
    obj = bpy.data.objects.new("SpecGen camera", cam)
    obj.location = (0.0, -10.0, 0.0)
    obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def _mesh_object(name: str, verts: np.ndarray, faces: list) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    mesh.update()
    for poly in mesh.polygons:
        poly.use_smooth = True
    return bpy.data.objects.new(name, mesh)


def uv_sphere(name: str = "SpecGen sphere", segments: int = 256, rings: int = 128) -> bpy.types.Object:
    """Smooth-shaded unit UV sphere (fine enough that its silhouette and normals match the analytic
    sphere to ~1e-4 at 256² pixels)."""
    verts = [(0.0, 0.0, 1.0)]
    for r in range(1, rings):
        theta = math.pi * r / rings
        for s in range(segments):
            phi = 2 * math.pi * s / segments
            verts.append((math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)))
    verts.append((0.0, 0.0, -1.0))
    faces = []
    for s in range(segments):
        faces.append((0, 1 + s, 1 + (s + 1) % segments))
    for r in range(rings - 2):
        a, b = 1 + r * segments, 1 + (r + 1) * segments
        for s in range(segments):
            s1 = (s + 1) % segments
            faces.append((a + s, b + s, b + s1, a + s1))
    last = len(verts) - 1
    base = 1 + (rings - 2) * segments
    for s in range(segments):
        faces.append((base + s, last, base + (s + 1) % segments))
    return _mesh_object(name, np.asarray(verts), faces)


def suzanne(name: str = "SpecGen Suzanne") -> bpy.types.Object:
    """Blender's monkey, subdivided once, facing the camera."""
    mesh = bpy.data.meshes.new(name)
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_monkey(bm)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=1, use_grid_fill=True, smooth=1.0)
    bm.to_mesh(mesh)
    bm.free()
    for poly in mesh.polygons:
        poly.use_smooth = True
    obj = bpy.data.objects.new(name, mesh)
    obj.rotation_euler = (0.0, 0.0, 0.0)  # Suzanne faces −Y: towards the camera
    obj.scale = (0.72, 0.72, 0.72)  # ears (x ±1.36) inside the 2-unit frame
    return obj


def import_obj(path: Path) -> bpy.types.Object:
    """Import a Wavefront OBJ, join its parts, fit it into the unit sphere around the origin."""
    if not path.is_file():
        raise SpecGenError(f"{path}: mesh file not found")
    before = set(bpy.data.objects)
    bpy.ops.wm.obj_import(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if not new:
        raise SpecGenError(f"{path}: no mesh found in the OBJ file")
    obj = new[0]
    for other in new[1:]:
        obj.data.polygons  # noqa: B018 (touch to keep data loaded)
    for o in new:
        for poly in o.data.polygons:
            poly.use_smooth = True
    corners = np.array([list(obj.matrix_world @ Vector(c)) for c in obj.bound_box])
    centre = (corners.max(0) + corners.min(0)) / 2
    radius = float(np.max(np.linalg.norm(corners - centre, axis=1))) or 1.0
    obj.location = Vector(obj.location) - Vector(centre)
    obj.scale = tuple(s / radius for s in obj.scale)
    return obj


def add_mesh(scene: bpy.types.Scene, mesh: str) -> bpy.types.Object:
    """``sphere``, ``suzanne`` or a path to an ``.obj`` file, linked into ``scene``."""
    if mesh == "sphere":
        obj = uv_sphere()
    elif mesh == "suzanne":
        obj = suzanne()
    else:
        obj = import_obj(Path(mesh))
        for col in list(obj.users_collection):
            col.objects.unlink(obj)
    scene.collection.objects.link(obj)
    return obj


def add_sun(scene: bpy.types.Scene, direction_ref=(0.0, 0.0, 1.0), irradiance: float = math.pi,
            color=(1.0, 1.0, 1.0)) -> bpy.types.Object:
    """A sun shining *from* ``direction_ref`` (reference frame, towards the light) with irradiance E."""
    light = bpy.data.lights.new("SpecGen sun", "SUN")
    light.energy = float(irradiance)
    light.color = color
    light.angle = 0.0
    obj = bpy.data.objects.new("SpecGen sun", light)
    d = reference_to_blender(direction_ref).normalized()
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = d.to_track_quat("Z", "Y")
    scene.collection.objects.link(obj)
    return obj


def new_reference_sphere_scene(make_material: Callable[[], bpy.types.Material], sun_ref=(0.0, 0.0, 1.0),
                               irradiance: float = math.pi) -> tuple[bpy.types.Scene, bpy.types.Object]:
    """Reset Blender to an empty file and build the reference renderer's sphere scene: the
    orthographic camera, the unit sphere wearing the material ``make_material`` makes (after the
    reset, which would remove one made before), one sun from ``sun_ref`` of
    ``irradiance`` (W/m²), pixels sampled at their centres as the reference samples them; gives
    (scene, sphere). For headless checks against the reference renderer only: it discards the
    open file."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    add_camera(scene)
    sphere = add_mesh(scene, "sphere")
    sphere.data.materials.append(make_material())
    scene.cycles.filter_width = 0.01
    add_sun(scene, sun_ref, irradiance=irradiance)
    return scene, sphere


def set_world_environment(scene: bpy.types.Scene, image_path: Path | None, strength: float = 1.0,
                          color=(0.0, 0.0, 0.0)) -> bpy.types.World:
    """World = an equirect Environment Texture × strength (or a plain colour if no image)."""
    world = bpy.data.worlds.new("SpecGen world")
    tree = world.node_tree
    bg = next(n for n in tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Strength"].default_value = float(strength)
    if image_path is not None:
        tex = tree.nodes.new("ShaderNodeTexEnvironment")
        tex.image = bpy.data.images.load(str(image_path), check_existing=True)
        try:
            tex.image.colorspace_settings.name = "Linear Rec.709"
        except TypeError:
            pass
        tree.links.new(tex.outputs["Color"], bg.inputs["Color"])
    else:
        bg.inputs["Color"].default_value = (*color, 1.0)
    scene.world = world
    return world
