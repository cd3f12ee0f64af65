"""Node building for the SpecGen material's native closure stack (Lambert + GGX lobes, each
optionally weighted by the view-dependent dielectric Fresnel of a Fresnel node).

The numbers and the layout come from :mod:`specgen_addon.bake.closure_fit.closures`; this module only builds
and sets nodes. A SpecGen material holds two surfaces: the exact OSL shader (used by the exact
render mode) and this stack, which is what the Output node shows: F12 and the viewport render the
stack with the fit's RGB colours (an RGB stand-in), and the full-scene spectral render sets it per
band group. A lobe whose roughness varies with wavelength is three Glossy nodes, one per RGB
channel of a band group (``SpecGen Lobe 1 (R)`` …), summed before its Fresnel mix.
"""

from __future__ import annotations

import bpy

from specgen_addon.common.errors import SpecGenError
from specgen_addon.bake.closure_fit import ClosureFit, StackClosure, stack_layout, standin_closures

FIT_PROP = "specgen_closures"
PREFIX = "SpecGen "
STACK_OUTPUT = "SpecGen Stack"  # the node whose first output is the whole stack


def _sum(tree: bpy.types.NodeTree, outputs: list, y: float) -> bpy.types.NodeSocket:
    """Add Shader chain of ``outputs`` (one output stays as it is)."""
    last = outputs[0]
    for i, nxt in enumerate(outputs[1:]):
        add = tree.nodes.new("ShaderNodeAddShader")
        add.location = (-150 + 150 * i, y)
        tree.links.new(last, add.inputs[0])
        tree.links.new(nxt, add.inputs[1])
        last = add.outputs["Shader"]
    return last


def build_closure_stack(mat: bpy.types.Material, fit: ClosureFit, output: bpy.types.Node) -> None:
    """One Diffuse/Glossy (GGX) node per closure of :func:`stack_layout` (``SpecGen <name>``);
    a term's closures are added, Fresnel-weighted terms go through a Mix Shader whose factor is a
    Fresnel node (``(1 − F)`` for the diffuse, ``F`` for a lobe); all summed into ``output``'s
    Surface. Sets the RGB stand-in and keeps the fit on the material (JSON custom property)."""
    tree = mat.node_tree
    fresnel = None
    terms: dict[str, tuple[StackClosure, list]] = {}
    for i, c in enumerate(stack_layout(fit)):
        node = tree.nodes.new("ShaderNodeBsdfGlossy" if c.glossy else "ShaderNodeBsdfDiffuse")
        if c.glossy:
            node.distribution = "GGX"  # the fit's model: plain GGX, height-correlated Smith G
        node.name = node.label = PREFIX + c.name
        node.location = (-600, -300 - 150 * i)
        terms.setdefault(c.term, (c, []))[1].append(node.outputs["BSDF"])
    shaders = []
    for i, (c, outputs) in enumerate(terms.values()):
        out = _sum(tree, outputs, -300 - 150 * i)
        if c.fresnel:
            if fresnel is None:
                fresnel = tree.nodes.new("ShaderNodeFresnel")
                fresnel.name = fresnel.label = PREFIX + "Fresnel"
                fresnel.inputs["IOR"].default_value = float(fit.ior)
                fresnel.location = (-800, -300)
            mix = tree.nodes.new("ShaderNodeMixShader")  # (1 − fac)·A + fac·B, one side empty
            mix.location = (-200, -300 - 150 * i)
            tree.links.new(fresnel.outputs["Fac"], mix.inputs["Fac"])
            tree.links.new(out, mix.inputs[2 if c.glossy else 1])
            out = mix.outputs["Shader"]
        shaders.append(out)
    if not shaders:  # a black BRDF
        node = tree.nodes.new("ShaderNodeBsdfDiffuse")
        node.name = node.label = PREFIX + "Diffuse"
        node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        shaders.append(node.outputs["BSDF"])
    stack = tree.nodes.new("NodeReroute")
    stack.name = stack.label = STACK_OUTPUT
    stack.location = (150, -300)
    tree.links.new(_sum(tree, shaders, -100), stack.inputs[0])
    tree.links.new(stack.outputs[0], output.inputs["Surface"])
    mat[FIT_PROP] = fit.to_json()
    mat["specgen_fit_error"] = fit.max_error
    if fit.rendered_error is not None:  # shown in the panel
        mat["specgen_fit_delta_e"] = float(fit.rendered_error)
    elif "specgen_fit_delta_e" in mat:
        del mat["specgen_fit_delta_e"]
    set_stack(mat, standin_closures(fit, stack_layout(fit)))


def material_fit(mat: bpy.types.Material) -> ClosureFit:
    """The closure fit stored on a SpecGen material (SpecGenError when it has none)."""
    text = mat.get(FIT_PROP)
    if not text or STACK_OUTPUT not in mat.node_tree.nodes:
        raise SpecGenError(f"material {mat.name!r} has no native closure fit; Apply the BRDF again")
    return ClosureFit.from_json(text)


def set_stack(mat: bpy.types.Material, values: dict[str, tuple]) -> None:
    """Colour (three values: RGB, or a render's three bands) and roughness (None for a diffuse
    closure) of each closure by name, as :func:`~specgen_addon.bake.closure_fit.group_closures` gives them."""
    nodes = mat.node_tree.nodes
    for name, (colour, roughness) in values.items():
        node = nodes.get(PREFIX + name)
        if node is None:
            continue
        node.inputs["Color"].default_value = (*(float(v) for v in colour[:3]), 1.0)
        if roughness is not None:
            node.inputs["Roughness"].default_value = float(roughness)
