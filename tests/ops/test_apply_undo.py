"""Undo after Apply, headless with the bpy module.

The bpy module has a window manager with one window, so Blender's memfile undo runs as in the UI:
an operator called with ``undo=True`` (as a button click is) pushes an undo step when it has
``bl_options`` ``{'UNDO'}``, and ``bpy.ops.ed.undo()`` restores the file. Python references to
datablocks die with an undo (the file is reloaded from memory), so everything is looked up by name.
"""

from __future__ import annotations


import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module  # noqa: E402  (after the bpy skip)
bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")

from specgen_addon.bake.closure_fit import ggx_lobe  # noqa: E402
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402

WL = np.array([450.0, 550.0, 650.0])


@pytest.fixture(scope="module")
def lookup_json(tmp_path_factory):
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.array([0.2, 0.5, 0.7]) / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * 0.1
    d = tmp_path_factory.mktemp("undo")
    info = bake.bake_atlas(BRDFTable.tabulate(fn, WL), d / "brdf_lookup.exr")
    bake.save_atlas_info(info, d / "brdf_lookup.json")
    return d / "brdf_lookup.json"


def _state(obj_name: str) -> tuple:
    """What Apply may change: the object's materials, the file's materials, images and texts."""
    obj = bpy.data.objects[obj_name]
    return (tuple(s.material.name if s.material else None for s in obj.material_slots),
            sorted(m.name for m in bpy.data.materials), sorted(i.name for i in bpy.data.images),
            sorted(t.name for t in bpy.data.texts))


def test_undo_after_apply_restores_the_previous_material(blank_scene, lookup_json):
    PKG.register()
    try:
        sc = bpy.context.scene
        obj = scene_mod.add_mesh(sc, "sphere")
        old = bpy.data.materials.new("Old paint")
        old.diffuse_color = (0.1, 0.6, 0.2, 1.0)
        obj.data.materials.append(old)
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        sc.specgen.atlas_json = str(lookup_json)
        name = obj.name
        bpy.ops.ed.undo_push(message="before Apply")
        before = _state(name)

        assert bpy.ops.specgen.apply("EXEC_DEFAULT", True) == {"FINISHED"}   # as from a button
        after = _state(name)
        assert after != before and render.is_specgen_material(bpy.data.objects[name].active_material)

        assert bpy.ops.ed.undo() == {"FINISHED"}
        assert _state(name) == before                  # the SpecGen material is gone again
        assert tuple(bpy.data.materials["Old paint"].diffuse_color) == pytest.approx((0.1, 0.6, 0.2, 1.0))
        assert bpy.ops.ed.redo() == {"FINISHED"}
        assert _state(name) == after
        mat = bpy.data.objects[name].active_material
        assert render.is_specgen_material(mat) and mat.node_tree.nodes.get("SpecGen Stack") is not None
    finally:
        PKG.unregister()
