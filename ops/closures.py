"""Node building for the SpecGen material's native closure stack (Lambert + GGX lobes).

The numbers come from :mod:`specgen_addon.fit.closures`; this module only builds and sets nodes.
A SpecGen material holds two surfaces: the exact OSL shader (used by the exact render mode) and
this stack, which is what the Output node shows: F12 and the viewport render the stack with the
fit's RGB colours (an RGB stand-in), and the full-scene spectral render sets it per band group.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..specgen_addon.errors import SpecGenError
from ..specgen_addon.fit import ClosureFit, rgb_standin

FIT_PROP = "specgen_closures"
DIFFUSE_NODE = "SpecGen Diffuse"
LOBE_NODE = "SpecGen Lobe {}"
STACK_OUTPUT = "SpecGen Stack"  # the last Add Shader (or the diffuse node alone)


def build_closure_stack(mat: bpy.types.Material, fit: ClosureFit, output: bpy.types.Node) -> None:
    """Add Diffuse + Glossy (GGX) nodes summed by Add Shaders, link them to ``output``'s Surface,
    set the RGB stand-in colours, and keep the fit on the material (JSON custom property)."""
    tree = mat.node_tree
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.name = diffuse.label = DIFFUSE_NODE
    diffuse.location = (-200, -300)
    last = diffuse.outputs["BSDF"]
    for i, r in enumerate(fit.roughness):
        lobe = tree.nodes.new("ShaderNodeBsdfGlossy")
        lobe.name = lobe.label = LOBE_NODE.format(i + 1)
        lobe.distribution = "GGX"  # the fit's model: plain GGX, height-correlated Smith G
        lobe.inputs["Roughness"].default_value = float(r)
        lobe.location = (-200, -450 - 150 * i)
        add = tree.nodes.new("ShaderNodeAddShader")
        add.location = (0, -300 - 150 * i)
        tree.links.new(last, add.inputs[0])
        tree.links.new(lobe.outputs["BSDF"], add.inputs[1])
        last = add.outputs["Shader"]
    if last.node != diffuse:
        last.node.name = STACK_OUTPUT
    tree.links.new(last, output.inputs["Surface"])
    mat[FIT_PROP] = fit.to_json()
    mat["specgen_fit_error"] = fit.max_error  # shown in the panel
    d_rgb, s_rgb = rgb_standin(fit)
    set_stack_colours(mat, d_rgb, s_rgb)


def material_fit(mat: bpy.types.Material) -> ClosureFit:
    """The closure fit stored on a SpecGen material (SpecGenError when it has none)."""
    text = mat.get(FIT_PROP)
    if not text or DIFFUSE_NODE not in mat.node_tree.nodes:
        raise SpecGenError(f"material {mat.name!r} has no native closure fit; Apply the BRDF again")
    return ClosureFit.from_json(text)


def set_stack_colours(mat: bpy.types.Material, diffuse: np.ndarray, specular: np.ndarray) -> None:
    """Colours (3 values each: RGB, or three bands) of the diffuse node and of each lobe."""
    nodes = mat.node_tree.nodes
    nodes[DIFFUSE_NODE].inputs["Color"].default_value = (*(float(c) for c in diffuse[:3]), 1.0)
    for i, s in enumerate(specular):
        nodes[LOBE_NODE.format(i + 1)].inputs["Color"].default_value = (*(float(c) for c in s[:3]), 1.0)


def stack_socket(mat: bpy.types.Material) -> bpy.types.NodeSocket:
    """Output socket of the closure stack."""
    nodes = mat.node_tree.nodes
    return (nodes.get(STACK_OUTPUT) or nodes[DIFFUSE_NODE]).outputs[0]
