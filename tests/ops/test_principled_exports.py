"""A SpecGen material's Principled stand-in drives EEVEE and Blender's exporters: glTF, USD (its
preview surface) and MaterialX (an OpenPBR network in the USD file) carry the stand-in's colour,
metalness and roughness, read back from the exported files; Cycles keeps the closure stack."""

from __future__ import annotations

import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")
principled = addon_module("ops.principled")

from specgen_addon.bake.closure_fit import ClosureFit, ggx_lobe
from specgen_addon.bake.closure_fit.principled import principled_from_closures
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.linspace(400.0, 700.0, 8)


def test_a_coloured_lobe_without_diffuse_is_a_metal_and_a_white_one_over_a_diffuse_is_not():
    metal = ClosureFit(WL, np.zeros(8), np.array([0.3]), np.linspace(0.3, 0.9, 8)[None], np.zeros(8))
    p = principled_from_closures(metal)
    assert p.metallic == pytest.approx(1.0) and p.roughness == pytest.approx(0.3, rel=1e-6)
    assert p.base_color[0] > p.base_color[2]                     # reddish: more reflectance at long λ
    plastic = ClosureFit(WL, np.full(8, 0.5), np.array([0.2]), np.full((1, 8), 0.04), np.zeros(8))
    p = principled_from_closures(plastic)
    assert p.metallic == pytest.approx(0.0) and np.allclose(p.base_color, p.base_color[0], atol=0.02)
    assert p.specular_ior_level == pytest.approx(0.5, abs=0.05) and p.coat_weight == 0.0


@pytest.fixture(scope="module")
def atlas(tmp_path_factory):
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.linspace(0.1, 0.6, 8) / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * 0.05
    d = tmp_path_factory.mktemp("principled")
    return bake.bake_atlas(BRDFTable.tabulate(fn, WL), d / "ball_lookup.exr")


@pytest.mark.slow
@pytest.mark.blender
def test_gltf_usd_and_materialx_exports_carry_the_principled_stand_in(atlas, tmp_path, registered_addon):
    obj = scene_mod.add_mesh(bpy.context.scene, "sphere")
    mat = render.make_material("SpecGen ball", atlas)
    obj.data.materials.append(mat)
    p = dict(mat["specgen_principled"])
    base = list(p["base_color"])
    tree = mat.node_tree
    assert tree.get_output_node("EEVEE").inputs["Surface"].links[0].from_node.name == principled.PRINCIPLED_NODE
    assert render.material_output(mat).inputs["Surface"].links[0].from_node.name != principled.PRINCIPLED_NODE
    bpy.ops.export_scene.gltf(filepath=str(tmp_path / "ball.gltf"), export_format="GLTF_SEPARATE")
    bpy.ops.wm.usd_export(filepath=str(tmp_path / "ball.usda"), export_materials=True,
                          generate_materialx_network=True)
    gltf = json.loads((tmp_path / "ball.gltf").read_text())
    pbr = next(m for m in gltf["materials"] if m["name"] == "SpecGen ball")["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"][:3] == pytest.approx(base, abs=1e-4)
    assert pbr.get("metallicFactor", 1.0) == pytest.approx(p["metallic"], abs=1e-4)
    assert pbr["roughnessFactor"] == pytest.approx(p["roughness"], abs=1e-4)

    from pxr import Usd, UsdShade  # bundled with Blender; importable once its exporter has run

    stage = Usd.Stage.Open(str(tmp_path / "ball.usda"))
    shaders = {}
    for prim in stage.Traverse():
        if prim.GetTypeName() == "Shader" and "SpecGen_ball" in str(prim.GetPath()):
            sh = UsdShade.Shader(prim)
            shaders[sh.GetIdAttr().Get()] = {i.GetBaseName(): i.Get() for i in sh.GetInputs()}
    preview = shaders["UsdPreviewSurface"]
    assert list(preview["diffuseColor"]) == pytest.approx(base, abs=1e-4)
    assert preview["roughness"] == pytest.approx(p["roughness"], abs=1e-4)
    assert preview.get("metallic", 0.0) == pytest.approx(p["metallic"], abs=1e-4)
    openpbr = shaders["ND_open_pbr_surface_surfaceshader"]             # the MaterialX network
    assert list(openpbr["base_color"]) == pytest.approx(base, abs=1e-4)
    assert openpbr["specular_roughness"] == pytest.approx(p["roughness"], abs=1e-4)
