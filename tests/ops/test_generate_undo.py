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


@pytest.mark.slow
@pytest.mark.blender
def test_replace_materials_removes_the_old_runs_files_and_an_undone_material_says_its_files_changed(
        tmp_path, registered_addon, sphere_photo, default_weights):
    """Generate again with Replace Materials and Export Table off: the first run's table goes
    with the rest of its set (it would be exported, packed and baked from as this material's).
    Undo then brings the first run's material back, but not its files: the spectral render
    refuses with one sentence naming the material instead of rendering the other run's lookups."""
    render = addon_module("ops.render")
    s = bpy.context.scene.specgen
    s.image_path, s.output_dir = str(sphere_photo), str(tmp_path / "out")
    s.bands, s.refine, s.overwrite, s.export_table = 4, False, True, True
    scene_mod.add_camera(bpy.context.scene)
    ball = scene_mod.add_mesh(bpy.context.scene, "sphere")
    assert bpy.ops.specgen.generate_brdf("EXEC_DEFAULT", True) == {"FINISHED"}
    stem = s.material["specgen_stem"]
    table = tmp_path / "out" / f"{stem}.npz"
    assert table.is_file()
    ball.data.materials.append(s.material)
    bpy.ops.ed.undo_push(message="apply")
    s.export_table, s.refine = False, True                  # another material: the refined one
    assert bpy.ops.specgen.generate_brdf("EXEC_DEFAULT", True) == {"FINISHED"}
    assert not table.exists()                              # not this material's table any more
    render.SpectralRenderJob(bpy.context.scene, None, samples=1, resolution=(8, 8))._preflight()
    assert bpy.ops.ed.undo() == {"FINISHED"}
    with pytest.raises(Exception, match="replaced by a later Generate") as info:
        render.SpectralRenderJob(bpy.context.scene, None, samples=1, resolution=(8, 8))._preflight()
    assert len(str(info.value).splitlines()) == 1
