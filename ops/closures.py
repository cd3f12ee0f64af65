"""Node building for the SpecGen material's native closure stack (Lambert + GGX lobes, each
optionally weighted by the view-dependent dielectric Fresnel of a Fresnel node).

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
PREFIX = "SpecGen "
STACK_OUTPUT = "SpecGen Stack"  # the node whose first output is the whole stack


def build_closure_stack(mat: bpy.types.Material, fit: ClosureFit, output: bpy.types.Node) -> None:
    """One Diffuse/Glossy (GGX) node per fitted closure (``SpecGen <term>``); Fresnel-weighted
    ones go through a Mix Shader whose factor is a Fresnel node (``(1 − F)`` for the diffuse,
    ``F`` for a lobe); all summed by Add Shaders into ``output``'s Surface. Sets the RGB stand-in
    colours and keeps the fit on the material (JSON custom property)."""
    tree = mat.node_tree
    fresnel = None
    shaders = []
    for i, (name, roughness, weighted, _) in enumerate(fit.terms()):
        if roughness is None:
            node = tree.nodes.new("ShaderNodeBsdfDiffuse")
        else:
            node = tree.nodes.new("ShaderNodeBsdfGlossy")
            node.distribution = "GGX"  # the fit's model: plain GGX, height-correlated Smith G
            node.inputs["Roughness"].default_value = roughness
        node.name = node.label = PREFIX + name
        node.location = (-400, -300 - 150 * i)
        out = node.outputs["BSDF"]
        if weighted:
            if fresnel is None:
                fresnel = tree.nodes.new("ShaderNodeFresnel")
                fresnel.name = fresnel.label = PREFIX + "Fresnel"
                fresnel.inputs["IOR"].default_value = float(fit.ior)
                fresnel.location = (-600, -300)
            mix = tree.nodes.new("ShaderNodeMixShader")  # (1 − fac)·A + fac·B, one side empty
            mix.location = (-200, -300 - 150 * i)
            tree.links.new(fresnel.outputs["Fac"], mix.inputs["Fac"])
            tree.links.new(out, mix.inputs[1 if roughness is None else 2])
            out = mix.outputs["Shader"]
        shaders.append(out)
    if not shaders:  # a black BRDF
        node = tree.nodes.new("ShaderNodeBsdfDiffuse")
        node.name = node.label = PREFIX + "Diffuse"
        node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        shaders.append(node.outputs["BSDF"])
    last = shaders[0]
    for i, nxt in enumerate(shaders[1:]):
        add = tree.nodes.new("ShaderNodeAddShader")
        add.location = (0, -300 - 150 * i)
        tree.links.new(last, add.inputs[0])
        tree.links.new(nxt, add.inputs[1])
        last = add.outputs["Shader"]
    stack = tree.nodes.new("NodeReroute")
    stack.name = stack.label = STACK_OUTPUT
    stack.location = (150, -300)
    tree.links.new(last, stack.inputs[0])
    tree.links.new(stack.outputs[0], output.inputs["Surface"])
    mat[FIT_PROP] = fit.to_json()
    mat["specgen_fit_error"] = fit.max_error  # shown in the panel
    set_stack_colours(mat, rgb_standin(fit))


def material_fit(mat: bpy.types.Material) -> ClosureFit:
    """The closure fit stored on a SpecGen material (SpecGenError when it has none)."""
    text = mat.get(FIT_PROP)
    if not text or STACK_OUTPUT not in mat.node_tree.nodes:
        raise SpecGenError(f"material {mat.name!r} has no native closure fit; Apply the BRDF again")
    return ClosureFit.from_json(text)


def set_stack_colours(mat: bpy.types.Material, colours: dict[str, np.ndarray]) -> None:
    """Colour of each closure by term name (three values: RGB, or a render's three bands)."""
    nodes = mat.node_tree.nodes
    for name, c in colours.items():
        node = nodes.get(PREFIX + name)
        if node is not None:
            node.inputs["Color"].default_value = (*(float(v) for v in c[:3]), 1.0)

