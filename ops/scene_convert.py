"""Convert a Blender scene to one band group of a spectral render, and restore it exactly.

The full-scene render (:mod:`.render_fullscene`) path-traces the user's scene with Cycles, three
bands per render in R, G, B. Before each render every RGB quantity is replaced by its values at
the group's three wavelengths (maths in :mod:`specgen_addon.bake.scene_uplift`):

* unlinked colour inputs of shader nodes (BSDFs, Emission, Background, volumes) in every material,
  the world and light node trees: set to ``M @ rgb`` (reflectance basis) or ``U @ rgb`` (emission
  basis for Emission/Background colours and Principled emission);
* linked colour inputs (image and environment textures, colour ramps, mixes ...): one
  ``SpecGen uplift`` node group is inserted on the link: ``band_j = dot(basis_row_j, rgb)``, three
  dot products, so textures stay textures and Mapping, several Background nodes etc. work as
  Cycles does them; a Blackbody node feeding an emission colour directly gives Planck's spectrum;
* lights: colour (and blackbody temperature) per band; strength, exposure, shape, angle and
  shadows untouched (Cycles honours them);
* SpecGen materials: their native closure stack gets the fitted per-band albedo, lobe colours and
  (for a lobe built per channel) roughnesses.

:class:`SceneConversion` records every value, link and node it touches and :meth:`restore`
puts them back; :func:`fingerprint` lets tests check that nothing changed.
"""

from __future__ import annotations

from typing import Callable

import bpy
import numpy as np

from specgen_addon.bake import scene_uplift as uplift
from specgen_addon.bake.closure_fit import group_closures, stack_layout
from .closures import material_fit, set_stack
from .render import is_specgen_material

REFLECTANCE, EMISSION = "reflectance", "emission"
GROUP_NAME = {REFLECTANCE: "SpecGen uplift (reflectance)", EMISSION: "SpecGen uplift (emission)"}
#: (node bl_idname, input name) pairs whose colour is emitted light.
EMITTER_INPUTS = {("ShaderNodeEmission", "Color"), ("ShaderNodeBackground", "Color"),
                  ("ShaderNodeBsdfPrincipled", "Emission Color"),
                  ("ShaderNodeVolumePrincipled", "Emission Color")}


def _is_shader_node(node: bpy.types.Node) -> bool:
    return any(o.type == "SHADER" for o in node.outputs)


def _make_uplift_group(kind: str) -> bpy.types.NodeTree:
    """Node group Color → Color whose output channel j is ``dot(row_j, colour)``."""
    group = bpy.data.node_groups.new(GROUP_NAME[kind], "ShaderNodeTree")
    group.interface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    combine = group.nodes.new("ShaderNodeCombineColor")
    for j, channel in enumerate("RGB"):
        dot = group.nodes.new("ShaderNodeVectorMath")
        dot.operation = "DOT_PRODUCT"
        dot.name = f"band{j}"
        group.links.new(gin.outputs[0], dot.inputs[0])
        group.links.new(dot.outputs["Value"], combine.inputs[j])
    group.links.new(combine.outputs[0], gout.inputs[0])
    return group


class SceneConversion:
    """Per-band-group edits of a scene's materials, world and lights, with exact restore."""

    def __init__(self, scene: bpy.types.Scene, wavelengths_nm: np.ndarray,
                 warn: Callable[[str], None] = print):
        self.scene = scene
        self.wavelengths_nm = np.asarray(wavelengths_nm, np.float64)
        self.warn = warn
        self.basis = {REFLECTANCE: uplift.reflectance_basis(self.wavelengths_nm),
                      EMISSION: uplift.emission_basis(self.wavelengths_nm)}
        self._values: list[tuple[object, str, object]] = []   # (owner, attribute, original)
        self._sockets: list[tuple[object, str, tuple]] = []   # (socket, kind, original RGBA)
        self._blackbody: list[tuple[object, float, tuple]] = []  # (socket, kelvin, original RGBA)
        self._lights: list[tuple[object, np.ndarray, float | None]] = []  # (light, rgb, kelvin)
        self._links: list[tuple[object, object, object]] = []  # removed (tree, from, to)
        self._nodes: list[tuple[object, object]] = []          # added (tree, node)
        self._groups: dict[str, bpy.types.NodeTree] = {}
        self._specgen: list[tuple[object, object, list]] = []  # (material, fit at our bands, layout)
        self._done_trees: set[int] = set()
        self.prepared = False

    # ---------------------------------------------------------------- preparation
    def _group(self, kind: str) -> bpy.types.NodeTree:
        if kind not in self._groups:
            self._groups[kind] = _make_uplift_group(kind)
        return self._groups[kind]

    def _insert_uplift(self, tree, link, kind: str) -> None:
        src, dst = link.from_socket, link.to_socket
        node = tree.nodes.new("ShaderNodeGroup")
        node.node_tree = self._group(kind)
        node.name = node.label = "SpecGen uplift"
        node.location = (dst.node.location.x - 150, dst.node.location.y)
        self._nodes.append((tree, node))
        tree.links.remove(link)
        self._links.append((tree, src, dst))
        tree.links.new(src, node.inputs[0])
        tree.links.new(node.outputs[0], dst)

    def _convert_tree(self, tree, owner: str, light_tree: bool = False) -> None:
        if tree is None or tree.as_pointer() in self._done_trees:
            return
        self._done_trees.add(tree.as_pointer())
        if tree.library is not None:
            self.warn(f"SpecGen: node group {tree.name!r} in {owner} is linked from a library and "
                      "cannot be converted per band; its colours render as RGB")
            return
        for node in list(tree.nodes):
            if node.type == "GROUP" and node.node_tree is not None:
                self._convert_tree(node.node_tree, owner, light_tree)
                continue
            if not _is_shader_node(node) or node.mute:
                continue
            if node.type == "SCRIPT":
                self.warn(f"SpecGen: OSL script node {node.name!r} in {owner}: its colour inputs "
                          "are converted as reflectances")
            for sock in node.inputs:
                if sock.type != "RGBA" or not sock.enabled:
                    continue
                kind = EMISSION if ((node.bl_idname, sock.name) in EMITTER_INPUTS
                                    and not light_tree) else REFLECTANCE
                links = [lk for lk in sock.links if not lk.is_muted]
                if not links:
                    self._sockets.append((sock, kind, tuple(sock.default_value)))
                    continue
                src = links[0].from_node
                if (kind == EMISSION and src.type == "BLACKBODY"
                        and not src.inputs["Temperature"].is_linked):
                    tree.links.remove(links[0])
                    self._links.append((tree, src.outputs[0], sock))
                    self._blackbody.append((sock, float(src.inputs["Temperature"].default_value),
                                            tuple(sock.default_value)))
                    continue
                if src.type == "BLACKBODY":
                    self.warn(f"SpecGen: Blackbody node {src.name!r} in {owner} is not wired "
                              "straight into an emission colour; its RGB is uplifted instead")
                self._insert_uplift(tree, links[0], kind)

    def prepare(self) -> "SceneConversion":
        """Insert the uplift nodes (values follow in :meth:`set_group`)."""
        sc = self.scene
        for mat in bpy.data.materials:
            if mat.library is not None or mat.node_tree is None:
                continue
            if is_specgen_material(mat):
                fit = material_fit(mat)  # the nodes follow the stored fit's layout
                self._specgen.append((mat, fit.at(self.wavelengths_nm), stack_layout(fit)))
                continue
            self._convert_tree(mat.node_tree, f"material {mat.name!r}")
        if sc.world is not None and sc.world.node_tree is not None:
            self._convert_tree(sc.world.node_tree, f"world {sc.world.name!r}")
        lights = {o.data for o in sc.objects if o.type == "LIGHT"}
        for light in lights:
            kelvin = float(light.temperature) if getattr(light, "use_temperature", False) else None
            self._lights.append((light, np.asarray(light.color[:], np.float64), kelvin))
            self._values.append((light, "color", tuple(light.color)))
            if kelvin is not None:
                self._values.append((light, "use_temperature", True))
                light.use_temperature = False
            if light.node_tree is not None:
                self._convert_tree(light.node_tree, f"light {light.name!r}", light_tree=True)
        for mat, _, _ in self._specgen:
            nodes = mat.node_tree.nodes
            for node in nodes:
                if node.name.startswith("SpecGen ") and node.type in ("BSDF_DIFFUSE", "BSDF_GLOSSY"):
                    self._values.append((node.inputs["Color"], "default_value",
                                         tuple(node.inputs["Color"].default_value)))
                    if node.type == "BSDF_GLOSSY":
                        self._values.append((node.inputs["Roughness"], "default_value",
                                             float(node.inputs["Roughness"].default_value)))
        self.prepared = True
        return self

    def specgen_fits(self) -> list[tuple[bpy.types.Material, object]]:
        """(material, :class:`~specgen_addon.bake.closure_fit.ClosureFit` at the render's bands) per SpecGen material."""
        return [(mat, fit) for mat, fit, _ in self._specgen]

    # ---------------------------------------------------------------- per group
    def set_group(self, group: np.ndarray) -> None:
        """Write band group ``group`` (three band indices) into the scene."""
        group = np.asarray(group)
        mats = {k: uplift.group_matrix(b, group) for k, b in self.basis.items()}
        for kind, tree in self._groups.items():
            for j in range(3):
                tree.nodes[f"band{j}"].inputs[1].default_value = tuple(mats[kind][j])
        for sock, kind, rgba in self._sockets:
            sock.default_value = (*(mats[kind] @ np.asarray(rgba[:3])), rgba[3])
        for sock, kelvin, rgba in self._blackbody:
            bb = uplift.blackbody_spectrum(kelvin, self.wavelengths_nm)
            sock.default_value = (*uplift.group_values(bb, group), rgba[3])
        for light, rgb, kelvin in self._lights:
            if kelvin is None:
                light.color = tuple(mats[EMISSION] @ rgb)
            else:  # the colour filters the blackbody: reflectance × Planck (unit luminance)
                bb = np.asarray(uplift.group_values(
                    uplift.blackbody_spectrum(kelvin, self.wavelengths_nm), group))
                light.color = tuple((mats[REFLECTANCE] @ rgb) * bb)
        for mat, fit, layout in self._specgen:
            set_stack(mat, group_closures(fit, group, layout))

    # ---------------------------------------------------------------- restore
    def restore(self) -> None:
        """Undo everything :meth:`prepare` and :meth:`set_group` did (idempotent)."""
        for tree, node in reversed(self._nodes):
            try:
                tree.nodes.remove(node)
            except (ReferenceError, RuntimeError):
                pass
        for tree, src, dst in reversed(self._links):
            try:
                tree.links.new(src, dst)
            except (ReferenceError, RuntimeError):
                pass
        for sock, _, rgba in self._sockets:
            sock.default_value = rgba
        for sock, _, rgba in self._blackbody:
            sock.default_value = rgba
        for owner, attr, value in reversed(self._values):
            setattr(owner, attr, value)
        for group in self._groups.values():
            bpy.data.node_groups.remove(group)
        self._nodes, self._links, self._sockets, self._blackbody = [], [], [], []
        self._values, self._groups, self._lights, self._specgen = [], {}, [], []
        self.prepared = False


def fingerprint() -> dict:
    """Every material, world, light and node group as plain data (names, node types, input
    values, links, light settings), to check that a render left the file unchanged."""
    def value(v):
        if isinstance(v, (int, float, str, bool, type(None))):
            return round(v, 7) if isinstance(v, float) else v
        try:
            return tuple(round(float(x), 7) for x in v)
        except (TypeError, ValueError):
            return str(v)

    def tree_data(tree):
        if tree is None:
            return None
        nodes = {n.name: (n.bl_idname, getattr(n.node_tree, "name", None) if n.type == "GROUP" else None,
                          tuple((s.identifier, value(getattr(s, "default_value", None)))
                                for s in n.inputs))
                 for n in tree.nodes}
        links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name,
                        lk.to_socket.identifier, lk.is_muted) for lk in tree.links)
        return nodes, links

    light_attrs = ("type", "color", "energy", "use_temperature", "temperature", "exposure",
                   "use_shadow", "angle", "shadow_soft_size")
    return {
        "materials": {m.name: tree_data(m.node_tree) for m in bpy.data.materials},
        "worlds": {w.name: tree_data(w.node_tree) for w in bpy.data.worlds},
        "node_groups": {g.name: tree_data(g) for g in bpy.data.node_groups},
        "lights": {lt.name: tuple(value(getattr(lt, a, None)) for a in light_attrs)
                   for lt in bpy.data.lights},
        "images": sorted(i.name for i in bpy.data.images if i.name not in ("Render Result",)),
        "texts": sorted(t.name for t in bpy.data.texts),
    }
