"""Undo after Generate, headless with the bpy module (as in tests/ops/test_apply_undo.py): one Ctrl-Z
removes what Generate made (its material, node group and preview image) and nothing the user did
before it; redo brings them back."""

from __future__ import annotations


import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

scene_mod = addon_module("ops.scene")



def _state() -> tuple:
    return (sorted(o.name for o in bpy.data.objects), sorted(m.name for m in bpy.data.materials),
            sorted(g.name for g in bpy.data.node_groups), sorted(i.name for i in bpy.data.images))


@pytest.mark.slow
@pytest.mark.blender
def test_one_undo_after_generate_removes_only_what_generate_made(tmp_path, registered_addon, sphere_photo,
                                                                  default_weights):
    s = bpy.context.scene.specgen
    s.image_path = str(sphere_photo)
    s.output_dir = str(tmp_path / "out")
    s.bands = 4
    s.refine = False
    bpy.ops.ed.undo_push(message="settings")
    scene_mod.add_mesh(bpy.context.scene, "sphere")                 # the user's own step
    bpy.ops.ed.undo_push(message="add the sphere")
    before = _state()

    assert bpy.ops.specgen.generate_brdf("EXEC_DEFAULT", True) == {"FINISHED"}   # as from a button
    after = _state()
    made = [n for a, b in zip(after, before) for n in set(a) - set(b)]
    assert any(n.startswith("SpecGen ") for n in made) and after[0] == before[0]

    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert _state() == before                 # Generate's datablocks gone, the sphere kept
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert _state() == after
    previews = [i.name for i in bpy.data.images if i.name.startswith("SpecGen ")]
    assert previews
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "saved.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "saved.blend"))
    assert all(name in bpy.data.images for name in previews)   # the thumbnail survives the save
