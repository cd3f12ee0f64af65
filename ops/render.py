"""Exact mode's Cycles driver: render a scene's SpecGen materials into a spectral stack.

The exact mode evaluates the tabulated BRDF itself (direct light, SpecGen objects only; the
full-scene mode is :mod:`.render_fullscene`). This module also builds the SpecGen material.

Cycles (CPU, OSL) renders images of spectral-basis coefficients, not bands (see :mod:`specgen_addon.bake.lookup`):
each render carries four coefficient slots × RGB lighting, which the shader
(``ops/osl/specgen_brdf.osl``) writes as closure weights and Cycles stores in the Emission,
Diffuse Color, Glossy Color and Transmission Color passes; one compositor File Output node per pass
writes them (a single multi-input File Output node wrote only its first input in Blender 5.0, and
view-layer AOVs stay empty under OSL). With no Cycles lights, a black world and zero bounces those
passes cost nothing beyond the shader, which does the lighting itself. The slot images are then
combined with the basis into any number of bands (usually one render for 21 bands) and written as
a spectral OpenEXR (Fichet et al. 2021) plus an RGB preview, atomically.

The scene is modified only for the duration of a render and restored afterwards
(:class:`_SceneState`). :class:`SpectralRenderJob` is a generator of progress steps so that a modal
operator can run it one Cycles render per timer tick and cancel between renders.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import bpy
import numpy as np

from specgen_addon.common.errors import Cancelled, OutputExistsError, SpecGenError
from specgen_addon.bake import lookup as bake
from specgen_addon.common.interrupts import private_tempdir

SHADER_PATH = Path(__file__).resolve().parent / "osl" / "specgen_brdf.osl"
#: The Script node's custom property naming the OSL source its bytecode was compiled from.
SHADER_DIGEST_KEY = "specgen_osl_sha256"
SHADER_TEXT_NAME = "specgen_brdf.osl"
MATERIAL_TAG = "specgen"
PASSES = (("Emission", "emit"), ("Diffuse Color", "diffuse_color"),
          ("Glossy Color", "glossy_color"), ("Transmission Color", "transmission_color"))
#: The material's node whose "BSDF" output is the exact shader: a Group node using the material's
#: own node group (``SpecGen <stem>``, see :mod:`.naming`), which holds the OSL Script node.
BRDF_NODE_NAME = "SpecGen BRDF"
#: The OSL Script node inside that group (the exact-mode driver sets its inputs per render).
SCRIPT_NODE_NAME = "SpecGen OSL"


def ensure_oslquery() -> None:
    """Make Cycles' script-node compiler work in the bpy *module* (facts §4).

    The module ships ``oslquery`` (and the OpenImageIO build it links against) under
    ``bpy/<ver>/python/lib/python3.x/site-packages`` without putting it on ``sys.path``; without it
    script nodes compile to no sockets. ``oslquery`` returns OpenImageIO ``TypeDesc`` objects, which
    only convert if *that* OpenImageIO extension is loaded, so it is loaded privately (a pip
    OpenImageIO imported earlier keeps its place in ``sys.modules``). A real Blender needs none of it.
    """
    import glob
    import importlib.machinery
    import importlib.util

    site = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib",
                        f"python{sys.version_info.major}.{sys.version_info.minor}", "site-packages")
    if not os.path.isdir(os.path.join(site, "oslquery")):
        return
    if site not in sys.path:
        sys.path.append(site)
    global _BPY_OIIO
    if _BPY_OIIO is not None:
        return
    current = sys.modules.get("OpenImageIO")
    if current is not None and os.path.dirname(getattr(current, "__file__", "")).startswith(site):
        _BPY_OIIO = current
        return
    so = sorted(glob.glob(os.path.join(site, "OpenImageIO", "OpenImageIO.cpython-*.so")))
    if not so:
        return
    loader = importlib.machinery.ExtensionFileLoader("OpenImageIO", so[0])
    spec = importlib.util.spec_from_file_location("OpenImageIO", so[0], loader=loader)
    _BPY_OIIO = importlib.util.module_from_spec(spec)
    if current is not None:
        sys.modules["OpenImageIO"] = current
    else:
        sys.modules.pop("OpenImageIO", None)


_BPY_OIIO = None


def shader_text() -> bpy.types.Text:
    """The OSL source as a text datablock (internal script: the .blend stays self-contained)."""
    text = bpy.data.texts.get(SHADER_TEXT_NAME)
    source = SHADER_PATH.read_text()
    if text is None:
        text = bpy.data.texts.new(SHADER_TEXT_NAME)
    if text.as_string() != source:
        text.clear()
        text.write(source)
    return text


def compile_script_node(node: bpy.types.Node) -> None:
    """Compile the SpecGen OSL into ``node`` (internal script) and create its sockets.

    Assigning the script runs Cycles' ``osl.update_script_node``; raises SpecGenError when the
    shader did not compile (no OSL in this Cycles build, or a broken source).
    """
    ensure_oslquery()
    scene = bpy.context.scene
    engine = scene.render.engine
    scene.render.engine = "CYCLES"  # the script-node update runs through the scene's engine
    try:
        node.mode = "INTERNAL"
        text = shader_text()
        if node.script == text:
            node.script = None
        with private_tempdir("specgen_osl_"):  # Cycles leaves its .oso build files behind
            node.script = text
    finally:
        scene.render.engine = engine
    if "Atlas" not in node.inputs or "BSDF" not in node.outputs:
        raise SpecGenError("the SpecGen OSL shader did not compile (is Cycles built with OSL?)")
    node[SHADER_DIGEST_KEY] = _shader_digest()


def _shader_digest() -> str:
    return hashlib.sha256(SHADER_PATH.read_bytes()).hexdigest()[:16]


def refresh_shader(mats: list[bpy.types.Material]) -> None:
    """Recompile the Script nodes of ``mats`` not compiled from this version's OSL (a .blend saved
    by an older SpecGen keeps its shader's bytecode in the node); their socket values are kept."""
    digest = _shader_digest()
    for mat in mats:
        node = script_node(mat)
        if node is not None and node.get(SHADER_DIGEST_KEY) != digest:
            compile_script_node(node)


def _brdf_group(name: str) -> bpy.types.NodeTree:
    """The node group ``name`` (a SpecGen one is rebuilt in place, so a material reusing it keeps
    its link); a foreign group of that name is left alone and a new one is numbered by Blender."""
    group = bpy.data.node_groups.get(name)
    if group is None or group.bl_idname != "ShaderNodeTree" or not group.get(MATERIAL_TAG) \
            or group.library is not None:
        group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group.nodes.clear()
    sockets = [(i.in_out, i.name, i.socket_type) for i in group.interface.items_tree if i.item_type == "SOCKET"]
    if sockets != [("OUTPUT", "BSDF", "NodeSocketShader")]:  # kept if right: users' links survive
        group.interface.clear()
        group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    group[MATERIAL_TAG] = True
    return group


def make_material(name: str, atlas: bake.AtlasInfo) -> bpy.types.Material:
    """A material whose surface is the SpecGen OSL shader reading ``atlas``.

    The material owns a node group of its own name (``SpecGen <stem>``) holding the Script node
    with the lookups' paths and layout; the material's Group node ``SpecGen BRDF`` uses it. With a
    closure fit the material's output shows the native stand-in stack instead (:mod:`.closures`)
    and the exact mode links the group in for its renders. Rebuilding a material of the same
    name (Overwrite) reuses its group; a new name makes a new group, so sets never share nodes.
    """
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    tree = mat.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    group = _brdf_group(mat.name)
    script = group.nodes.new("ShaderNodeScript")
    script.name = script.label = SCRIPT_NODE_NAME
    compile_script_node(script)
    script.inputs["Atlas"].default_value = str(atlas.group_paths[0])
    script.inputs["PhiD"].default_value = int(atlas.n_phi_d)
    script.inputs["TilesX"].default_value = int(atlas.tiles_x)
    script.inputs["TilesY"].default_value = int(atlas.tiles_y)
    group_out = group.nodes.new("NodeGroupOutput")
    group_out.location = (300, 0)
    group.links.new(script.outputs["BSDF"], group_out.inputs["BSDF"])
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.name = node.label = BRDF_NODE_NAME
    tree.links.new(node.outputs["BSDF"], out.inputs["Surface"])
    if atlas.closures is not None:  # F12/viewport and the full-scene mode use the native stack
        from .closures import build_closure_stack

        from .principled import build_principled  # EEVEE, viewport and exporters

        build_principled(mat, atlas.closures, out)  # first: USD's preview surface takes the first BSDF node
        build_closure_stack(mat, atlas.closures, out)
    mat.cycles.emission_sampling = "NONE"  # the emission is reflected light, not a light source
    mat[MATERIAL_TAG] = True
    mat.use_fake_user = True   # a generated result is kept on save before it is applied to anything
    mat["specgen_wavelengths_nm"] = [float(w) for w in atlas.wavelengths_nm]
    mat["specgen_atlas"] = str(atlas.path)
    mat["specgen_atlas_groups"] = [str(p) for p in atlas.group_paths]
    mat["specgen_basis"] = [float(x) for x in atlas.basis.ravel()]
    mat["specgen_offsets"] = [float(x) for x in atlas.offsets]
    mat["specgen_atlas_version"] = bake.ATLAS_VERSION
    mat["specgen_basis_error"] = float(atlas.rel_error)
    return mat


def material_output(mat: bpy.types.Material) -> bpy.types.Node:
    """The material's active Cycles output node."""
    tree = mat.node_tree
    return tree.get_output_node("CYCLES") or next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL")


def brdf_node(mat: bpy.types.Material) -> bpy.types.Node | None:
    """The material's node whose "BSDF" output is the exact SpecGen shader."""
    return mat.node_tree.nodes.get(BRDF_NODE_NAME) if mat.node_tree is not None else None


def script_node(mat: bpy.types.Material) -> bpy.types.Node | None:
    """The OSL Script node of a SpecGen material: inside its node group (or, in a material built
    before node groups, the ``SpecGen BRDF`` node itself)."""
    node = brdf_node(mat)
    if node is None or node.type == "SCRIPT":
        return node
    group = node.node_tree if node.type == "GROUP" else None
    return None if group is None else group.nodes.get(SCRIPT_NODE_NAME)


def touch(mat: bpy.types.Material) -> None:
    """Make Cycles re-sync ``mat`` after a Script-node input edit (a string-socket edit alone,
    inside a group even less, does not)."""
    node = brdf_node(mat)
    if node is not None and node.type == "GROUP" and node.node_tree is not None:
        node.node_tree.update_tag()
    mat.node_tree.update_tag()
    mat.update_tag()


def is_specgen_material(mat: bpy.types.Material | None) -> bool:
    return mat is not None and bool(mat.get(MATERIAL_TAG)) and script_node(mat) is not None


def specgen_materials(scene: bpy.types.Scene) -> list[bpy.types.Material]:
    """SpecGen materials used by render-visible objects of ``scene``."""
    mats: dict[str, bpy.types.Material] = {}
    for obj in scene.objects:
        if obj.hide_render:
            continue
        for slot in getattr(obj, "material_slots", ()):
            if is_specgen_material(slot.material):
                mats[slot.material.name] = slot.material
    return list(mats.values())


# ------------------------------------------------------------------------------ scene lighting
def _uplift(wavelengths_nm: np.ndarray) -> np.ndarray:
    from specgen_addon.render.environment import uplift_basis

    return uplift_basis(wavelengths_nm)


def _mapping_rotation_z(world_name: str, node) -> float:
    """Z rotation (radians) applied by the Mapping node driving an Environment Texture's Vector,
    as a shift of the map; SpecGenError for anything the exact mode cannot reproduce."""
    vec = node.inputs["Vector"]
    if not vec.is_linked:
        return 0.0
    src = vec.links[0].from_node
    if src.type == "TEX_COORD":
        return 0.0
    if src.type != "MAPPING" or src.vector_type not in ("POINT", "TEXTURE", "VECTOR"):
        raise SpecGenError(f"world {world_name!r}: the environment texture's vector comes from a "
                           f"{src.type} node; the exact mode supports a Mapping rotation about Z "
                           "only (use the Full Scene mode)")
    feed = src.inputs["Vector"].links[0].from_socket if src.inputs["Vector"].is_linked else None
    if feed is None or feed.node.type != "TEX_COORD" or feed.name not in ("Generated", "Object"):
        raise SpecGenError(f"world {world_name!r}: Mapping node {src.name!r} does not map the view "
                           "direction (Texture Coordinate: Generated); the exact mode cannot honour it")
    rot = src.inputs["Rotation"].default_value
    loc = src.inputs["Location"].default_value if "Location" in src.inputs else (0.0, 0.0, 0.0)
    scale = src.inputs["Scale"].default_value
    linked = any(src.inputs[k].is_linked for k in ("Rotation", "Location", "Scale") if k in src.inputs)
    if (linked or abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6 or any(abs(c) > 1e-6 for c in loc)
            or any(abs(c - scale[0]) > 1e-6 for c in scale) or scale[0] <= 0):
        raise SpecGenError(f"world {world_name!r}: Mapping node {src.name!r} does more than rotate "
                           "about Z; the exact mode cannot honour it (use the Full Scene mode)")
    return float(-rot[2] if src.vector_type == "TEXTURE" else rot[2])


def rotate_equirect(rgb: np.ndarray, angle_z: float) -> np.ndarray:
    """Equirect map as seen through a Mapping rotation ``angle_z`` about Z (radians).

    Blender looks up the texture at ``R_z(θ) d``, whose azimuth is larger by θ, i.e. ``u`` smaller
    by ``θ/2π`` (``u = −atan2(y, x)/2π + ½``): the image moves right by ``θ/2π`` of its width
    (periodic, linear between columns).
    """
    w = rgb.shape[1]
    shift = (angle_z / (2 * np.pi) * w) % w
    k = int(np.floor(shift))
    t = shift - k
    return (1 - t) * np.roll(rgb, k, axis=1) + t * np.roll(rgb, k + 1, axis=1)


def world_environment(scene: bpy.types.Scene, max_width: int = 512) -> np.ndarray | None:
    """Linear-sRGB radiance (H, W, 3), row 0 at the zenith, of the world's environment texture
    (through a Mapping rotation about Z) times its Background strength; a constant map for a plain
    Background colour; None if black. Several Background nodes are refused."""
    world = scene.world
    if world is None or world.node_tree is None:
        return None
    out = world.node_tree.get_output_node("CYCLES")
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    background = out.inputs["Surface"].links[0].from_node
    used = [n for n in world.node_tree.nodes if n.type == "BACKGROUND" and n.outputs[0].is_linked]
    if background.type != "BACKGROUND" or len(used) > 1:
        raise SpecGenError(f"world {world.name!r} combines several shaders (e.g. Background nodes); "
                           "the exact mode supports one Background node (use the Full Scene mode)")
    strength = float(background.inputs["Strength"].default_value)
    color_in = background.inputs["Color"]
    if color_in.is_linked:
        src = color_in.links[0].from_node
        if src.type != "TEX_ENVIRONMENT" or src.image is None:
            raise SpecGenError(f"world background is driven by a {src.type} node; only an "
                               "Environment Texture (equirectangular) or a plain colour is supported")
        img = src.image
        w, h = img.size
        if w == 0 or h == 0:
            raise SpecGenError(f"environment image {img.name!r} could not be loaded")
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        rgb = px.reshape(h, w, 4)[::-1, :, :3].copy()
        while rgb.shape[1] > max_width and rgb.shape[0] % 2 == 0 and rgb.shape[1] % 2 == 0:
            rgb = rgb.reshape(rgb.shape[0] // 2, 2, rgb.shape[1] // 2, 2, 3).mean(axis=(1, 3))
        rgb = rotate_equirect(rgb, _mapping_rotation_z(world.name, src))
    else:
        rgb = np.broadcast_to(np.asarray(color_in.default_value[:3], np.float32), (8, 16, 3)).copy()
    rgb = np.clip(rgb * strength, 0.0, None)
    return None if not np.any(rgb > 0) else rgb


def render_visible(obj: bpy.types.Object, view_layer: bpy.types.ViewLayer) -> bool:
    """Whether ``obj`` renders in ``view_layer``: not hidden for render, and in at least one
    collection that is neither excluded from the layer nor hidden for render (up to the root)."""
    if obj.hide_render:
        return False

    def walk(layer_coll) -> bool:
        if layer_coll.exclude or layer_coll.collection.hide_render:
            return False
        if obj.name in layer_coll.collection.objects:
            return True
        return any(walk(child) for child in layer_coll.children)

    root = view_layer.layer_collection
    return obj.name in root.collection.objects or any(walk(c) for c in root.children)


def _view_layer(scene: bpy.types.Scene) -> bpy.types.ViewLayer:
    vl = bpy.context.view_layer
    return vl if vl is not None and vl.id_data == scene else scene.view_layers[0]


def _light_strength(light: bake.Light, targets: list) -> float:
    """Luminance of the light's irradiance on the SpecGen objects (sun: E; point: I/d²)."""
    y = float(np.dot(light.rgb, (0.2126, 0.7152, 0.0722)))
    if light.kind == "sun":
        return y
    d2 = min(float(np.sum((np.asarray(light.vector) - np.asarray(t)) ** 2)) for t in targets)
    return y / max(d2, 1e-6)


def scene_lights(scene: bpy.types.Scene, warn: Callable[[str], None] = print,
                 world: bool = True) -> bake.SceneLights:
    """Sun and point lights plus the world environment of ``scene``, in linear sRGB, for the exact mode.

    Spectra follow from the RGB with the environment's uplift basis (Mallett & Yuksel 2019 × D65),
    so a white sun of strength E is D65 irradiance E, as in the reference renderer. A point light
    of power P (W) has radiant intensity P/4π. Light exposure (× 2^exposure) and blackbody
    temperature (its RGB colour) are honoured; lights in excluded or render-hidden collections
    are skipped. Everything the mode cannot do is warned about by name: area and spot lights,
    sun angle, lights without cast shadows, emissive meshes, and lights beyond
    :data:`bake.MAX_LIGHTS`, of which the weakest (irradiance on the SpecGen objects) are dropped.
    """
    from mathutils import Vector

    lights: list[bake.Light] = []
    names: list[str] = []
    layer = _view_layer(scene)
    depsgraph = bpy.context.evaluated_depsgraph_get()  # fresh matrix_world of just-moved objects
    for obj in scene.objects:
        if obj.type != "LIGHT" or not render_visible(obj, layer):
            continue
        data = obj.data
        matrix = obj.evaluated_get(depsgraph).matrix_world if scene == bpy.context.scene else obj.matrix_world
        rgb = np.asarray(data.color[:3], dtype=np.float64) * 2.0 ** float(getattr(data, "exposure", 0.0))
        if getattr(data, "use_temperature", False):
            rgb = rgb * np.asarray(data.temperature_color[:3], np.float64)
        if data.type in ("SUN", "POINT") and not getattr(data, "use_shadow", True):
            warn(f"SpecGen: light {obj.name!r} casts no shadow in Blender; the exact mode shadows "
                 "every light")
        if data.type == "SUN":
            if data.angle > 1e-4:
                warn(f"SpecGen: sun {obj.name!r} has an angle of {np.degrees(data.angle):.1f}°; the "
                     "exact mode renders it as a point-like sun (hard shadows)")
            d = (matrix.to_3x3() @ Vector((0.0, 0.0, 1.0))).normalized()
            lights.append(bake.Light("sun", tuple(d), tuple(float(data.energy) * rgb)))
        elif data.type == "POINT":
            lights.append(bake.Light("point", tuple(matrix.translation),
                                     tuple(float(data.energy) / (4 * math.pi) * rgb)))
        else:
            warn(f"SpecGen: {data.type.lower()} light {obj.name!r} is ignored by the exact mode "
                 "(sun and point lights only; the Full Scene mode renders it)")
            continue
        names.append(obj.name)
    targets = []
    emissive = []
    for obj in scene.objects:
        if obj.type not in ("MESH", "CURVE", "SURFACE", "META", "FONT") or not render_visible(obj, layer):
            continue
        mats = [s.material for s in obj.material_slots if s.material is not None]
        if any(is_specgen_material(m) for m in mats):
            targets.append(tuple(obj.matrix_world.translation))
        elif any(_emits(m) for m in mats):
            emissive.append(obj.name)
    targets = targets or [(0.0, 0.0, 0.0)]
    for name in emissive:
        warn(f"SpecGen: emissive object {name!r} does not light the exact mode's SpecGen objects")
    if len(lights) > bake.MAX_LIGHTS:
        order = sorted(range(len(lights)), key=lambda i: -_light_strength(lights[i], targets))
        keep = sorted(order[:bake.MAX_LIGHTS])
        dropped = [names[i] for i in order[bake.MAX_LIGHTS:]]
        warn(f"SpecGen: the exact mode takes {bake.MAX_LIGHTS} lights; dropped the weakest: "
             + ", ".join(repr(n) for n in dropped))
        lights = [lights[i] for i in keep]
    env_rgb = world_environment(scene) if world else None   # world=False: suns and points only
    return bake.SceneLights(lights, None if env_rgb is None else bake.EnvironmentLight(env_rgb))


def _emits(mat: bpy.types.Material) -> bool:
    """Whether a (non-SpecGen) material emits light: an Emission node or a Principled emission."""
    if mat.node_tree is None:
        return False
    for node in mat.node_tree.nodes:
        if node.type == "EMISSION" and node.inputs["Strength"].default_value > 0:
            return True
        if (node.type == "BSDF_PRINCIPLED" and node.inputs["Emission Strength"].default_value > 0
                and (node.inputs["Emission Color"].is_linked
                     or any(c > 0 for c in node.inputs["Emission Color"].default_value[:3]))):
            return True
    return False


# ------------------------------------------------------------------------------ scene state
class SavedAttributes:
    """Set Blender properties for a render and put every one back afterwards, newest first
    (a datablock deleted meanwhile is skipped). Subclasses keep ``self.saved``."""

    saved: list[tuple[object, str, object]]

    def _set(self, owner, attr: str, value) -> None:
        self.saved.append((owner, attr, getattr(owner, attr)))
        setattr(owner, attr, value)

    def _restore_attributes(self) -> None:
        for owner, attr, value in reversed(self.saved):
            try:
                setattr(owner, attr, value)
            except (ReferenceError, AttributeError, TypeError):
                pass


class _SceneState(SavedAttributes):
    """Temporarily switch a scene to the spectral set-up; restore everything on exit."""

    def __init__(self, scene: bpy.types.Scene, samples: int, resolution: tuple[int, int],
                 out_dir: Path, holdout_others: bool = False):
        self.scene = scene
        self.holdout_others = holdout_others
        self.samples = samples
        self.resolution = resolution
        self.out_dir = out_dir
        self.saved: list[tuple[object, str, object]] = []
        self.created: list[tuple[object, object]] = []
        self.relinked: list[tuple[object, object, object]] = []

    def __enter__(self) -> "_SceneState":
        sc = self.scene
        cy = sc.cycles
        self._set(sc.render, "engine", "CYCLES")
        for attr, value in (("device", "CPU"), ("shading_system", True), ("samples", self.samples),
                            ("max_bounces", 0), ("diffuse_bounces", 0), ("glossy_bounces", 0),
                            ("transmission_bounces", 0), ("transparent_max_bounces", 0),
                            ("use_denoising", False),
                            # every pass gets every sample (adaptive stopping looks at Combined only)
                            ("use_adaptive_sampling", False)):
            self._set(cy, attr, value)
        self._set(sc.render, "resolution_x", self.resolution[0])
        self._set(sc.render, "resolution_y", self.resolution[1])
        self._set(sc.render, "resolution_percentage", 100)
        self._set(sc.render, "use_compositing", True)
        self._set(sc.render, "film_transparent", False)
        vl = bpy.context.view_layer if bpy.context.view_layer.id_data == sc else sc.view_layers[0]
        for _, flag in PASSES:
            self._set(vl, f"use_pass_{flag}", True)
        world = bpy.data.worlds.new("SpecGen black")
        world.use_nodes = True if hasattr(world, "use_nodes") else None
        bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
        bg.inputs["Strength"].default_value = 0.0
        self.created.append((bpy.data.worlds, world))
        self._set(sc, "world", world)
        for obj in sc.objects:
            if obj.type == "LIGHT" and not obj.hide_render:
                self._set(obj, "hide_render", True)  # lighting happens in the shader
            elif obj.type in ("MESH", "CURVE", "SURFACE", "META", "FONT") and not any(
                    is_specgen_material(s.material) for s in obj.material_slots):
                if self.holdout_others:  # occludes the camera too, draws black (Full Scene)
                    if not obj.is_holdout:
                        self._set(obj, "is_holdout", True)
                else:
                    self._set(obj, "visible_camera", False)  # still occludes (shadow rays)
        tree = bpy.data.node_groups.new("SpecGen passes", "CompositorNodeTree")
        self.created.append((bpy.data.node_groups, tree))
        layers = tree.nodes.new("CompositorNodeRLayers")
        layers.scene = sc
        layers.layer = vl.name
        for i, (pass_name, _) in enumerate(PASSES):
            # One File Output node per pass: Blender 5.0 wrote only the first input of one node.
            fo = tree.nodes.new("CompositorNodeOutputFile")
            fo.format.media_type = "MULTI_LAYER_IMAGE"
            fo.format.file_format = "OPEN_EXR_MULTILAYER"
            fo.format.color_depth = "32"
            fo.format.exr_codec = "NONE"
            fo.save_as_render = False
            fo.directory = str(self.out_dir)
            fo.file_name = f"pass{i}"
            fo.file_output_items.new("RGBA", "P")
            tree.links.new(layers.outputs[pass_name], fo.inputs["P"])
        self._set(sc, "compositing_node_group", tree)
        for mat in specgen_materials(sc):  # the exact shader, not the native stand-in stack
            surface = material_output(mat).inputs["Surface"]
            self.relinked.append((mat.node_tree, surface,
                                  surface.links[0].from_socket if surface.is_linked else None))
            mat.node_tree.links.new(brdf_node(mat).outputs["BSDF"], surface)
        return self

    def __exit__(self, *exc) -> None:
        for tree, surface, source in reversed(self.relinked):
            for link in list(surface.links):
                tree.links.remove(link)
            if source is not None:
                tree.links.new(source, surface)
        self._restore_attributes()
        for collection, block in reversed(self.created):
            try:
                collection.remove(block)
            except (ReferenceError, RuntimeError):
                pass


def _read_pass(path: Path) -> np.ndarray:
    from specgen_addon.common.image_io import read_exr

    ch, _ = read_exr(path)
    names = sorted(ch)
    pick = {c: next(n for n in names if n.endswith("." + c) or n == c) for c in "RGB"}
    return np.stack([ch[pick[c]] for c in "RGB"], axis=-1)


def _find_output(out_dir: Path, index: int) -> Path:
    hits = sorted(out_dir.glob(f"pass{index}*.exr"))
    if not hits:
        raise SpecGenError(f"Cycles wrote no pass file pass{index}*.exr into {out_dir}")
    return hits[-1]


# ------------------------------------------------------------------------------ the job
class RenderJobOutputs:
    """Cancel flag and output paths shared by the render jobs (``output``: the EXR or None)."""

    output: object
    overwrite: bool
    preview_png: bool
    _cancelled: bool

    def cancel(self) -> None:
        self._cancelled = True

    def _check(self) -> None:
        if self._cancelled:
            raise Cancelled("spectral render cancelled; nothing was written")

    def _outputs(self) -> tuple[Path, Path] | None:
        if self.output is None:
            return None
        exr = Path(self.output)
        return exr, exr.with_name(exr.stem + "_preview.png")

    def _check_outputs(self) -> None:
        """Before any work: the EXR (and preview) may be written — not there unless ``overwrite``,
        and the folder exists and is writable."""
        outs = self._outputs()
        if outs is not None:
            for p in outs if self.preview_png else outs[:1]:
                if p.exists() and not self.overwrite:
                    raise OutputExistsError(f"{p}: already exists (pass overwrite to replace it)")
            parent = outs[0].parent
            if not parent.is_dir() or not os.access(parent, os.W_OK):
                raise SpecGenError(f"{parent}: output folder does not exist or is not writable")


@dataclass
class SpectralRenderJob(RenderJobOutputs):
    """Render ``scene`` band group by band group, then write a spectral EXR and a PNG preview.

    Iterate :meth:`steps` (each step is at most one Cycles render; yields progress in [0, 1]) or
    call :meth:`run`. :meth:`cancel` stops before the next render and nothing is written.
    """

    scene: bpy.types.Scene
    output: Path | None
    samples: int = 16
    resolution: tuple[int, int] = (256, 256)
    overwrite: bool = False
    env_samples: int = 2
    env_lobe: float = 64.0
    shadows: bool = True
    preview_png: bool = True
    attributes: dict = field(default_factory=dict)
    warn: Callable[[str], None] = print
    #: other objects as holdouts (hide what they cover) rather than invisible to the camera: the
    #: full-scene mode's exact direct light (:mod:`.exact_direct`)
    holdout_others: bool = False
    #: light from the world too (False: only suns and point lights, see :mod:`.exact_direct`)
    world: bool = True
    #: one Cycles render of the scene as set up, as a generator (None: a blocking render); the
    #: Full Scene job passes a render job that Esc stops inside the render (:mod:`.exact_direct`)
    render_call: Callable[[], Iterator[None]] | None = None
    spectral: np.ndarray | None = field(default=None, init=False)
    wavelengths_nm: np.ndarray | None = field(default=None, init=False)
    basis: np.ndarray | None = field(default=None, init=False)
    offsets: np.ndarray | None = field(default=None, init=False)
    coefficient_images: np.ndarray | None = field(default=None, init=False)
    timings: dict = field(default_factory=dict, init=False)
    _cancelled: bool = field(default=False, init=False)

    def _preflight(self) -> list[bpy.types.Material]:
        self._check_outputs()
        mats = specgen_materials(self.scene)
        if not mats:
            raise SpecGenError("no render-visible object uses a SpecGen material (Apply one first)")
        stale = [m.name for m in mats if m.get("specgen_atlas_version") != bake.ATLAS_VERSION]
        if stale:
            raise SpecGenError(f"SpecGen material {stale[0]!r} was baked by an older SpecGen; "
                               "generate it again")
        from .travel import check_lookups

        check_lookups(mats, self.warn)
        bands = {tuple(m["specgen_wavelengths_nm"]) for m in mats}
        if len(bands) != 1:
            raise SpecGenError("SpecGen materials in the scene have different wavelength bands; "
                               "generate them with the same From, To and Bands")
        self.wavelengths_nm = np.asarray(next(iter(bands)), dtype=np.float64)
        # One group per spectral basis: a render's passes hold coefficients of one basis, so each
        # group renders with the others' shaders muted (their images add up, see steps()).
        groups: dict[tuple, list] = {}
        for m in mats:
            groups.setdefault((tuple(m["specgen_basis"]), tuple(m["specgen_offsets"])), []).append(m)
        self.groups = [(np.asarray(b, np.float64).reshape(-1, self.wavelengths_nm.size),
                        np.asarray(o, np.float64), ms) for (b, o), ms in groups.items()]
        self.basis, self.offsets = self.groups[0][0], self.groups[0][1]
        refresh_shader(mats)
        return mats

    def steps(self) -> Iterator[float]:
        """Generator: bake lighting, one Cycles render per four coefficient slots, assemble, write."""
        from .travel import atlas_groups

        t0 = time.perf_counter()
        mats = self._preflight()
        wl = self.wavelengths_nm
        ensure_oslquery()
        work = Path(tempfile.mkdtemp(prefix="specgen_render_"))
        try:
            lights = scene_lights(self.scene, self.warn, world=self.world)
            if not lights.lights and lights.environment is None:
                raise SpecGenError("the scene has no sun, point light or world lighting")
            slots = (lights.lights + [None] * bake.MAX_LIGHTS)[:bake.MAX_LIGHTS]
            env_map = env_list = ""
            if lights.environment is not None:
                m, l = bake.bake_environment(lights.environment, work / "env.exr", work / "env_list.exr")
                env_map, env_list = str(m), str(l)
            for mat in mats:
                node = script_node(mat)
                for i, light in enumerate(slots):
                    for key, value in bake.light_socket_values(light).items():
                        node.inputs[f"Light{i}{key}"].default_value = value
                node.inputs["EnvMap"].default_value = env_map
                node.inputs["EnvList"].default_value = env_list
                node.inputs["EnvSamples"].default_value = self.env_samples if env_map else 0
                node.inputs["EnvLobe"].default_value = self.env_lobe
                node.inputs["Shadows"].default_value = int(self.shadows)
            self.timings["bake_s"] = time.perf_counter() - t0
            yield 0.02
            h, w = self.resolution[1], self.resolution[0]
            uplift = _uplift(wl)
            plan = [(g, r) for g, (basis, _, _) in enumerate(self.groups)
                    for r in range(-(-basis.shape[0] // bake.COEFFS_PER_RENDER))]
            images = [np.zeros((h, w, len([p for p in plan if p[0] == g]) * bake.COEFFS_PER_RENDER, 3),
                               np.float32) for g in range(len(self.groups))]
            t_render = 0.0
            for i, (g, r) in enumerate(plan):
                self._check()
                out_dir = work / f"g{g}r{r}"
                out_dir.mkdir()
                for other, (_, _, group_mats) in enumerate(self.groups):
                    for mat in group_mats:
                        # other bases' materials are muted (an empty Atlas shades black)
                        script_node(mat).inputs["Atlas"].default_value = \
                            atlas_groups(mat)[r] if other == g else ""
                        touch(mat)
                t = time.perf_counter()
                with _SceneState(self.scene, self.samples, self.resolution, out_dir, self.holdout_others):
                    if self.render_call is None:
                        bpy.ops.render.render(write_still=False, scene=self.scene.name)
                    else:
                        yield from self.render_call()   # None while a render job runs
                t_render += time.perf_counter() - t
                for j in range(len(PASSES)):
                    images[g][:, :, r * bake.COEFFS_PER_RENDER + j] = _read_pass(_find_output(out_dir, j))
                yield 0.02 + 0.93 * (i + 1) / len(plan)
            self._check()
            self.timings["cycles_s"] = t_render
            self.coefficient_images = images[0]
            # rendering is linear: the groups' spectra add up
            self.spectral = sum(bake.assemble_spectrum(images[g], basis, offsets, uplift)
                                for g, (basis, offsets, _) in enumerate(self.groups))
            outs = self._outputs()
            if outs is not None:
                from specgen_addon.render.spectral_exr import (linear_srgb_preview, write_preview_png,
                                                          write_spectral_exr)

                rgb = linear_srgb_preview(self.spectral, wl)
                attrs = {"specgenRenderer": "SpecGen OSL/Cycles", "specgenSamples": str(self.samples),
                         "specgenBasisCoefficients": str(self.basis.shape[0]),
                         **{k: str(v) for k, v in self.attributes.items()}}
                write_spectral_exr(outs[0], self.spectral, wl, overwrite=self.overwrite, rgb=rgb,
                                   attributes=attrs)
                if self.preview_png:
                    from .result_view import preview_transform, show_result

                    write_preview_png(outs[1], rgb, overwrite=self.overwrite,
                                      view=preview_transform(self.scene, self.warn))
                    show_result(rgb)            # the result in Blender, as the Full Scene mode
            self.timings["total_s"] = time.perf_counter() - t0
            yield 1.0
        finally:
            for mat in mats:  # no dangling paths to the deleted temporary lighting files
                node = script_node(mat)
                if node is not None:
                    node.inputs["EnvMap"].default_value = ""
                    node.inputs["EnvList"].default_value = ""
            shutil.rmtree(work, ignore_errors=True)
            for mat in mats:  # unmute: every material shows its own first lookup again
                script_node(mat).inputs["Atlas"].default_value = atlas_groups(mat)[0]
                touch(mat)

    def run(self, progress: Callable[[float], None] | None = None) -> np.ndarray:
        """Run all steps; returns the spectral stack (H, W, Λ)."""
        for fraction in self.steps():
            if progress is not None and fraction is not None:   # None: a render job runs
                progress(fraction)
        return self.spectral
