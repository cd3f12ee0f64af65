"""The SpecGen material's Principled BSDF stand-in (numbers from :mod:`specgen_addon.bake.closure_fit.principled`).

A SpecGen material then has two outputs: the Cycles output shows the native closure stack (F12,
the full-scene render, the exact mode's group), and an EEVEE output, the active one, shows a
Principled BSDF: EEVEE, the viewport, and Blender's glTF, USD and MaterialX exporters (which read
the Principled node linked to the active output) see it.
"""

from __future__ import annotations

import bpy

from specgen_addon.bake.closure_fit import ClosureFit
from specgen_addon.bake.closure_fit.principled import principled_from_closures

PRINCIPLED_NODE = "SpecGen Principled"
EEVEE_OUTPUT = "SpecGen EEVEE Output"


def build_principled(mat: bpy.types.Material, fit: ClosureFit, cycles_output: bpy.types.Node) -> None:
    """Add (or update) the Principled stand-in of ``fit`` and its EEVEE output; ``cycles_output``
    (the closure stack's) is kept for Cycles only."""
    tree = mat.node_tree
    p = principled_from_closures(fit)
    node = tree.nodes.get(PRINCIPLED_NODE) or tree.nodes.new("ShaderNodeBsdfPrincipled")
    node.name = node.label = PRINCIPLED_NODE
    node.location = (0, 400)
    node.inputs["Base Color"].default_value = (*p.base_color, 1.0)
    node.inputs["Metallic"].default_value = p.metallic
    node.inputs["Roughness"].default_value = p.roughness
    node.inputs["Specular IOR Level"].default_value = p.specular_ior_level
    node.inputs["Specular Tint"].default_value = (*p.specular_tint, 1.0)
    node.inputs["Coat Weight"].default_value = p.coat_weight
    node.inputs["Coat Roughness"].default_value = p.coat_roughness
    node.inputs["Sheen Weight"].default_value = p.sheen_weight
    node.inputs["Sheen Tint"].default_value = (*p.sheen_tint, 1.0)
    node.inputs["Sheen Roughness"].default_value = p.sheen_roughness
    out = tree.nodes.get(EEVEE_OUTPUT) or tree.nodes.new("ShaderNodeOutputMaterial")
    out.name = out.label = EEVEE_OUTPUT
    out.location = (300, 400)
    out.target = "ALL"         # EEVEE and the exporters; Cycles prefers its own output
    tree.links.new(node.outputs["BSDF"], out.inputs["Surface"])
    cycles_output.target = "CYCLES"
    out.is_active_output = True
    mat.diffuse_color = (*p.base_color, 1.0)    # the Solid view's colour
    mat.metallic, mat.roughness = p.metallic, p.roughness
    mat["specgen_principled"] = p.to_dict()
