""""Lit like this scene": the open scene's lights and world read for the photo's lighting.

Reads what Blender holds (the active camera, sun / point / spot / area lights, the world's node
tree) and hands the values to :mod:`specgen_addon.photo.scene_lighting`, which does the frames,
units and resampling. What cannot be taken is named in the run's warning: area lights, a spot's
cone, a procedural world, a world texture that is not equirectangular.
"""

from __future__ import annotations

import os
import warnings

import bpy
import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.image_checks import check_pixel_count
from specgen_addon.photo.scene_lighting import (
    PANORAMA_WIDTH,
    SceneLighting,
    emitted_rgb,
    inside_cone,
    light_colour,
    mapping_matrix,
    point_light,
    rotation_part,
    sun_light,
    world_in_camera_frame,
)


def read_scene_lighting(scene, target=None) -> SceneLighting:
    """The scene's lighting as seen from its active camera; ``target`` is the ball's world position
    (default: the world origin), from which far point lights are seen."""
    if scene.camera is None:
        raise SpecGenError("lit like this scene needs an active camera (the photo's viewpoint)")
    cam = rotation_part(scene.camera.matrix_world)
    target = np.zeros(3) if target is None else np.asarray(target, np.float64)
    taken = SceneLighting()
    for obj in _rendered_objects(scene):
        if obj.type == "LIGHT":
            _add_light(taken, obj, cam, target)
    with warnings.catch_warnings(record=True) as said:   # a note on the world's pixels: the run's report says it
        warnings.simplefilter("always")
        _add_world(taken, scene.world, cam)
    taken.notes += [f"world: {w.message}" for w in said]
    return taken


def _rendered_objects(scene) -> list:
    """The scene's objects a render of its view layer shows: in a collection the view layer does
    not exclude and that (with its parents) is not disabled in renders, and not disabled in
    renders themselves. Read from the layer's collection tree, which is always current (the view
    layer's object list is updated lazily)."""
    layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    found: dict[str, object] = {}

    def walk(layer_collection) -> None:
        if layer_collection.exclude or layer_collection.collection.hide_render:
            return
        for obj in layer_collection.collection.objects:
            if not obj.hide_render:
                found.setdefault(obj.name, obj)
        for child in layer_collection.children:
            walk(child)

    walk(layer.layer_collection)
    return list(found.values())


def _add_light(taken: SceneLighting, obj, cam: np.ndarray, target: np.ndarray) -> None:
    light = obj.data
    if light.energy <= 0:
        return
    temperature = light.temperature if getattr(light, "use_temperature", False) else None
    rgb = emitted_rgb(light.color, getattr(light, "exposure", 0.0), temperature)
    if not float(np.max(rgb)) > 0:
        return
    colour = light_colour(rgb)
    if colour.changed:
        taken.not_taken.append(f"the exact colour of {light.type.lower()} light '{obj.name}' "
                               f"(taken as {colour.name})")
    matrix = np.array(obj.matrix_world)
    if light.type == "SUN":
        taken.lights.append(sun_light(cam, rotation_part(matrix), light.energy, rgb))
    elif light.type in ("POINT", "SPOT"):
        position = matrix[:3, 3]
        if light.type == "SPOT":
            if not inside_cone(rotation_part(matrix), position, target, light.spot_size):
                taken.not_taken.append(f"spot light '{obj.name}' (the ball lies outside its cone)")
                return
            taken.not_taken.append(f"the cone of spot light '{obj.name}' (taken as a point light)")
        taken.lights.append(point_light(cam, position, target, light.energy, rgb))
    else:
        taken.not_taken.append(f"{light.type.lower()} light '{obj.name}'")


def _add_world(taken: SceneLighting, world, cam: np.ndarray) -> None:
    if world is None:
        return
    tree = world.node_tree   # Blender 5 worlds always use their nodes; older ones may not
    if bpy.app.version < (5, 0, 0) and not world.use_nodes:
        tree = None
    if tree is None:
        _constant(taken, world.color, 1.0)
        return
    out = next((n for n in tree.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output), None) or \
        next((n for n in tree.nodes if n.type == "OUTPUT_WORLD"), None)
    surface = out.inputs["Surface"] if out is not None else None
    if surface is None or not surface.is_linked:
        return
    node = surface.links[0].from_node
    if node.type != "BACKGROUND":
        taken.not_taken.append(f"the world's '{node.name}' node (only a Background is read)")
        return
    colour_in, strength_in = node.inputs["Color"], node.inputs["Strength"]
    if strength_in.is_linked:
        taken.not_taken.append("the world's Background strength texture (its value taken)")
    strength = float(strength_in.default_value)
    if strength <= 0:
        return
    if not colour_in.is_linked:
        _constant(taken, colour_in.default_value, strength)
        return
    tex = colour_in.links[0].from_node
    if tex.type != "TEX_ENVIRONMENT" or tex.image is None:
        taken.not_taken.append(f"the world's procedural '{tex.name}'")
        return
    if tex.projection != "EQUIRECTANGULAR":
        taken.not_taken.append(f"the world's '{tex.name}' ({tex.projection.lower().replace('_', ' ')} "
                               "projection; only equirectangular is read)")
        return
    rgb = _image_rgb(tex.image)
    h, w = rgb.shape[:2]
    if w != 2 * h:
        taken.not_taken.append(f"the world's image '{tex.image.name}' ({w}×{h}; an equirectangular "
                               "panorama is twice as wide as it is high)")
        return
    taken.panorama = world_in_camera_frame(rgb, cam, _mapping(taken, tex))
    taken.strength = strength
    taken.notes.append(f"world: {tex.image.name} × {strength:g}, seen from the camera")


def _constant(taken: SceneLighting, colour, strength: float) -> None:
    rgb = np.asarray(colour[:3], np.float32) * np.float32(strength)
    if float(rgb.max()) > 0:
        taken.panorama = np.broadcast_to(rgb, (PANORAMA_WIDTH // 2, PANORAMA_WIDTH, 3)).copy()
        taken.notes.append(f"world: a uniform colour ({', '.join(f'{c:.3g}' for c in rgb)})")


def _mapping(taken: SceneLighting, tex) -> np.ndarray | None:
    """The matrix of a Mapping node feeding the environment texture's Vector, if any."""
    vector = tex.inputs["Vector"]
    if not vector.is_linked:
        return None
    node = vector.links[0].from_node
    if node.type == "TEX_COORD":
        return None
    if node.type != "MAPPING":
        taken.not_taken.append(f"the world's '{node.name}' before its environment texture")
        return None
    if any(node.inputs[k].is_linked for k in ("Rotation", "Scale")):
        taken.not_taken.append("a texture driving the world's Mapping node")
    kind = node.vector_type
    rotation = node.inputs["Rotation"].default_value
    scale = node.inputs["Scale"].default_value
    if kind in ("POINT", "TEXTURE") and any(abs(v) > 0 for v in node.inputs["Location"].default_value):
        taken.not_taken.append("the world's Mapping location")
    return mapping_matrix(kind, tuple(rotation), tuple(scale))


def _image_rgb(image) -> np.ndarray:
    """An image datablock's linear RGB (H, W, 3), row 0 on top: its file read in strips when it
    is a saved file (large panoramas never exist in full), else its pixels."""
    path = bpy.path.abspath(image.filepath) if image.filepath else ""
    if image.source == "FILE" and not image.packed_file and not image.is_dirty and os.path.isfile(path) \
            and path.lower().endswith((".exr", ".hdr")):
        from specgen_addon.photo.photo_lighting import read_map_bounded

        rgb = read_map_bounded(path, 2 * PANORAMA_WIDTH)
        if rgb is not None:
            return rgb
    w, h = image.size
    if w < 2 or h < 2:
        raise SpecGenError(f"the world's image {image.name!r} has no pixels (missing file?)")
    check_pixel_count(w, h, f"image {image.name!r}")
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    rgb = px.reshape(h, w, image.channels)[::-1, :, :3].astype(np.float64)
    if not image.is_float and image.colorspace_settings.name.lower().startswith("srgb"):
        from specgen_addon.spectral.spectra import srgb_decode

        rgb = srgb_decode(rgb)
    return rgb


def ball_position(context) -> np.ndarray | None:
    """Where the ball stands for the scene's point lights: the active object's origin when it is
    a surface (a mesh, curve …; not a light or the camera just clicked), else None."""
    obj = getattr(context, "active_object", None)
    if obj is None or obj.type not in {"MESH", "CURVE", "SURFACE", "META", "FONT"}:
        return None
    return np.array(obj.matrix_world.translation)

